"""OpenSubdiv's ``t`` tag lines in OBJ files: creases, corners, holes and scheme options.

A tag line reads ``t <name> <ni>/<nf>/<ns> <ni ints> <nf floats> <ns strings>``
(OpenSubdiv ``regression/common/shape_utils.cpp``). Indices in tags are 0-based
(unlike OBJ face indices).

Convention:
    - ``t crease 2k/1/0 a0 b0 .. a(k-1) b(k-1) s``: ``k`` edges of sharpness ``s``
      (or ``2k/k/0`` with one sharpness per edge). Each edge must be an edge of
      the mesh. ``t corner n/1/0 v.. s`` (or ``n/n/0``): corner vertices.
      ``t hole n/0/0 f..``: hole faces. Sharpness is finite and ``>= 0``
      (OpenSubdiv's meaning, see :mod:`torchgeo_cg.mesh.subdivision.tags`).
    - Scheme options become keyword arguments named like the subdivision builders':
      ``interpolateboundary 1/0/0 n`` -> ``boundary`` (0 ``"none"``,
      1 ``"edge_and_corner"``, 2 ``"edge_only"``); ``creasemethod 0/0/1 normal|chaikin``
      -> ``crease_method`` (``"uniform"``/``"chaikin"``); ``smoothtriangles 0/0/1
      catmark|smooth`` -> ``triangle_rule``; ``facevaryinginterpolateboundary 1/0/0 n``
      -> ``fvar_interpolation`` (0 ``"none"``, 1 ``"corners_only"``, 2 ``"corners_plus1"``,
      3 ``"corners_plus2"``, 4 ``"boundaries"``, 5 ``"all"``);
      ``facevaryingpropagatecorners 1/0/0 n`` -> ``fvar_propagate_corners`` (bool).
    - An edge, corner, hole or option given twice, and any other tag name
      (e.g. hierarchical edits), is an error: nothing is silently dropped.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from torchgeo_cg.mesh.io._text import (  # read_text: doctests
    TextLines,
    file_error,
    gather_lines,
    line_tokens,
    read_text,  # noqa: F401
)

__all__: list[str] = []

OPTION_TAGS = {
    "interpolateboundary": ("boundary", ("none", "edge_and_corner", "edge_only")),
    "facevaryinginterpolateboundary": (
        "fvar_interpolation",
        ("none", "corners_only", "corners_plus1", "corners_plus2", "boundaries", "all"),
    ),
    "facevaryingpropagatecorners": ("fvar_propagate_corners", (False, True)),
    "creasemethod": ("crease_method", {"normal": "uniform", "chaikin": "chaikin"}),
    "smoothtriangles": ("triangle_rule", {"catmark": "catmark", "smooth": "smooth"}),
}
"""OpenSubdiv option tag -> (keyword, values by integer code or by string)."""


class ObjTags(NamedTuple):
    """Tags of an OBJ file as numpy arrays (see :class:`~torchgeo_cg.mesh.SubdivisionTags`).

    Attributes:
        creases: ``(E, 2)`` int64. crease_sharpness: ``(E,)`` float64.
        corners: ``(C,)`` int64. corner_sharpness: ``(C,)`` float64.
        holes: ``(H,)`` int64 face ids. options: ``dict`` of scheme options.
    """

    creases: np.ndarray
    crease_sharpness: np.ndarray
    corners: np.ndarray
    corner_sharpness: np.ndarray
    holes: np.ndarray
    options: dict

    @classmethod
    def empty(cls) -> ObjTags:
        """No tag."""
        i, f = np.zeros(0, np.int64), np.zeros(0, np.float64)
        return cls(i.reshape(0, 2), f, i, f, i, {})


class _Group(NamedTuple):
    name: str
    lines: np.ndarray  # (n,) line indices into the file
    ints: np.ndarray  # (n, ni)
    floats: np.ndarray  # (n, nf)
    strings: np.ndarray  # (n, ns) object


def _numbers(tokens, dtype, text, lines):
    flat = tokens.ravel()
    values = np.zeros(0, dtype)
    if flat.size:
        try:
            values = np.fromstring(b" ".join(flat.tolist()), dtype=dtype, sep=" ")
        except ValueError:
            values = np.zeros(0, dtype)
    if values.size != flat.size:
        for row, line in zip(tokens, lines):  # error path only
            try:
                ok = np.fromstring(b" ".join(row.tolist()), dtype=dtype, sep=" ").size == row.size
            except ValueError:
                ok = False
            if not ok:
                kind = "integers" if dtype == np.int64 else "numbers"
                raise file_error(text.name, text.numbers[line], f"tag arguments are not {kind}")
    return values.reshape(tokens.shape)


def _groups(text: TextLines, lines: np.ndarray) -> list[_Group]:
    """Tag lines grouped by ``name ni/nf/ns``; arguments parsed per group, vectorized."""
    blob, segs = gather_lines(text, lines, text.starts[lines])
    counts = line_tokens(blob, segs).counts
    short = counts < 2
    if short.any():
        raise file_error(text.name, text.numbers[lines[int(np.argmax(short))]],
                         "a tag needs a name and an 'ints/floats/strings' count")
    tokens = np.array(blob.tobytes().split(), dtype=object)
    first = np.cumsum(counts) - counts
    keys = tokens[first] + b" " + tokens[first + 1]
    uniq, where = np.unique(keys, return_index=True)
    groups = []
    for key in uniq[np.argsort(where)]:  # loop over distinct tag kinds, not tag lines
        rows = np.flatnonzero(keys == key)
        name, spec = key.decode(errors="replace").split(" ", 1)
        parts = spec.split("/")
        if len(parts) != 3 or not all(p.isdigit() for p in parts):
            raise file_error(text.name, text.numbers[lines[rows[0]]],
                             f"tag {name!r}: expected 'ints/floats/strings' counts, "
                             f"got {spec!r}")
        ni, nf, ns = (int(p) for p in parts)
        bad = counts[rows] != 2 + ni + nf + ns
        if bad.any():
            r = rows[int(np.argmax(bad))]
            raise file_error(text.name, text.numbers[lines[r]],
                             f"tag {name!r} {spec} needs {ni + nf + ns} values, "
                             f"got {counts[r] - 2}")
        args = tokens[first[rows][:, None] + 2 + np.arange(ni + nf + ns)].reshape(len(rows), -1)
        groups.append(_Group(
            name, lines[rows], _numbers(args[:, :ni], np.int64, text, lines[rows]),
            _numbers(args[:, ni:ni + nf], np.float64, text, lines[rows]), args[:, ni + nf:],
        ))
    return groups


def _per_item(text, g: _Group, per: int, what: str):
    """Flatten ``ints`` in items of ``per`` ints, with one shared or one per-item sharpness."""
    n_items = g.ints.shape[1] // per if g.ints.shape[1] % per == 0 else 0
    if n_items == 0 or g.floats.shape[1] not in (1, n_items) or g.strings.shape[1]:
        raise file_error(text.name, text.numbers[g.lines[0]],
                         f"tag {what!r}: expected {'2k' if per == 2 else 'k'} ints, 1 or k floats "
                         "and no strings, got "
                         f"{g.ints.shape[1]}/{g.floats.shape[1]}/{g.strings.shape[1]}")
    items = g.ints.reshape(-1, per)
    sharp = np.broadcast_to(g.floats, (len(g.lines), n_items)).reshape(-1)
    return items, sharp, np.repeat(g.lines, n_items)


def _check_items(error, items, limit, what, sharp=None):
    """Indices in ``[0, limit)``, sharpness finite and ``>= 0``, no item twice."""
    if len(items) == 0:
        return
    bad = ((items < 0) | (items >= limit)).reshape(len(items), -1).any(1)
    if bad.any():
        i = int(np.argmax(bad))
        raise error(i, f"{what} {items[i].tolist()} out of range [0, {limit})")
    if sharp is not None:
        bad = ~np.isfinite(sharp) | (sharp < 0)
        if bad.any():
            i = int(np.argmax(bad))
            raise error(i, f"{what} sharpness must be finite and >= 0, got {sharp[i]}")
    keys = np.sort(items.reshape(len(items), -1), axis=1)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    repeat = first[inverse.reshape(-1)] != np.arange(len(items))
    if repeat.any():
        i = int(np.argmax(repeat))
        raise error(i, f"{what} {items[i].tolist()} tagged twice")


def _check_edges(error, creases, faces_fk, num_vertices):
    """Every crease must be an edge of the mesh (undirected)."""
    if creases.size == 0:
        return
    valid = faces_fk >= 0
    nxt = np.where(np.roll(valid, -1, axis=1), np.roll(faces_fk, -1, axis=1), faces_fk[:, :1])
    a, b = faces_fk[valid], nxt[valid]
    edge_keys = np.minimum(a, b) * num_vertices + np.maximum(a, b)
    keys = creases.min(1) * num_vertices + creases.max(1)
    bad = ~np.isin(keys, edge_keys)
    if bad.any():
        i = int(np.argmax(bad))
        raise error(i, f"crease {creases[i].tolist()} is not an edge of the mesh")


def check_tags(tags: ObjTags, num_vertices: int, faces_fk: np.ndarray, error=None) -> None:
    """Check tags against a mesh as :func:`parse_tags` does (for writing what reads back).

    Args:
        tags: the tags.
        num_vertices: ``V``.
        faces_fk: ``(F, K)`` padded faces.
        error: ``error(kind, i, message) -> Exception``; default names ``tags.<kind>s``.

    Example:
        >>> t = ObjTags.empty()._replace(creases=np.array([[0, 2]]), crease_sharpness=np.ones(1))
        >>> check_tags(t, 4, np.array([[0, 1, 2, 3]]))
        Traceback (most recent call last):
        ...
        ValueError: tags.creases: item 0: crease [0, 2] is not an edge of the mesh
    """
    if error is None:
        def error(kind, i, msg):
            return ValueError(f"tags.{kind}s: item {i}: {msg}")
    for kind, items, sharp in (("crease", tags.creases.reshape(-1, 2), tags.crease_sharpness),
                               ("corner", tags.corners.reshape(-1, 1), tags.corner_sharpness),
                               ("hole", tags.holes.reshape(-1, 1), None)):
        def err(i, msg, kind=kind):
            return error(kind, i, msg)

        _check_items(err, items, len(faces_fk) if kind == "hole" else num_vertices, kind, sharp)
        if kind == "crease":
            _check_edges(err, items, faces_fk, num_vertices)


def _option(text, g: _Group, options: dict) -> None:
    key, values = OPTION_TAGS[g.name]
    line = text.numbers[g.lines[0]]
    if key in options or len(g.lines) > 1:
        raise file_error(text.name, text.numbers[g.lines[-1]], f"tag {g.name!r} given twice")
    if isinstance(values, dict):
        arg = g.strings[0, 0].decode(errors="replace") if g.strings.shape[1] == 1 else None
        ok = g.ints.shape[1] == 0 and g.floats.shape[1] == 0 and arg in values
        if not ok:
            raise file_error(text.name, line, f"tag {g.name!r}: expected 0/0/1 and one of "
                             f"{sorted(values)}")
        options[key] = values[arg]
        return
    code = int(g.ints[0, 0]) if g.ints.shape[1] == 1 else -1
    if g.floats.shape[1] or g.strings.shape[1] or not 0 <= code < len(values):
        raise file_error(text.name, line, f"tag {g.name!r}: expected 1/0/0 and an integer in "
                         f"[0, {len(values)})")
    options[key] = values[code]


def parse_tags(text: TextLines, lines: np.ndarray, num_vertices: int, faces_fk: np.ndarray
               ) -> ObjTags:
    r"""Tags of the ``t`` lines ``lines`` (their ``t`` already blanked), checked against the mesh.

    Example:
        >>> t = read_text(b"  crease 2/1/0 0 1 3\n  hole 1/0/0 0\n", "m.obj")
        >>> tags = parse_tags(t, np.arange(2), 3, np.array([[0, 1, 2]]))
        >>> tags.creases.tolist(), tags.crease_sharpness.tolist(), tags.holes.tolist()
        ([[0, 1]], [3.0], [0])
    """
    if lines.size == 0:
        return ObjTags.empty()
    parts = {"crease": [], "corner": [], "hole": []}
    options: dict = {}
    for g in _groups(text, lines):  # loop over tag kinds
        if g.name == "crease":
            parts["crease"].append(_per_item(text, g, 2, "crease"))
        elif g.name == "corner":
            parts["corner"].append(_per_item(text, g, 1, "corner"))
        elif g.name == "hole":
            if g.floats.shape[1] or g.strings.shape[1] or g.ints.shape[1] == 0:
                raise file_error(text.name, text.numbers[g.lines[0]],
                                 "tag 'hole': expected n/0/0 and n face ids")
            ids = g.ints.reshape(-1, 1)
            parts["hole"].append((ids, np.zeros(len(ids)), np.repeat(g.lines, g.ints.shape[1])))
        elif g.name in OPTION_TAGS:
            _option(text, g, options)
        else:
            raise file_error(text.name, text.numbers[g.lines[0]], f"unsupported tag {g.name!r}")
    out = {}
    for kind, width in (("crease", 2), ("corner", 1), ("hole", 1)):
        got = parts[kind]
        items = np.concatenate([p[0] for p in got]) if got else np.zeros((0, width), np.int64)
        sharp = np.concatenate([p[1] for p in got]) if got else np.zeros(0)
        where = np.concatenate([p[2] for p in got]) if got else np.zeros(0, np.int64)
        order = np.argsort(where, kind="stable")  # file order
        items, sharp, where = items[order], sharp[order], where[order]
        out[kind] = (items, sharp, where)
    tags = ObjTags(out["crease"][0].reshape(-1, 2), out["crease"][1],
                   out["corner"][0].reshape(-1), out["corner"][1],
                   out["hole"][0].reshape(-1), options)

    def error(kind, i, msg):
        return file_error(text.name, text.numbers[out[kind][2][i]], msg)

    check_tags(tags, num_vertices, faces_fk, error)
    return tags


def _lines(prefix: str, items: np.ndarray, sharp: np.ndarray | None, precision: int) -> str:
    cols = [items.astype(str)]
    if sharp is not None:
        cols.append(np.char.mod(f"%.{precision}g", sharp))
    rows = np.full(len(items), prefix, dtype=object)
    for col in np.column_stack(cols).T if len(items) else ():  # loop over columns
        rows = rows + " " + col.astype(object)
    return "\n".join(rows.tolist()) + "\n" if len(rows) else ""


def format_tags(tags: ObjTags, precision: int) -> str:
    """``t`` lines for ``tags`` (one crease, corner or hole per line, then the options).

    Example:
        >>> t = ObjTags.empty()._replace(creases=np.array([[0, 1]]),
        ...                              crease_sharpness=np.array([2.5]),
        ...                              options={"boundary": "edge_only"})
        >>> print(format_tags(t, 17), end="")
        t crease 2/1/0 0 1 2.5
        t interpolateboundary 1/0/0 2
    """
    out = _lines("t crease 2/1/0", tags.creases.reshape(-1, 2), tags.crease_sharpness, precision)
    out += _lines("t corner 1/1/0", tags.corners.reshape(-1, 1), tags.corner_sharpness, precision)
    out += _lines("t hole 1/0/0", tags.holes.reshape(-1, 1), None, precision)
    for tag, (key, values) in OPTION_TAGS.items():  # loop over the few option kinds
        if key not in tags.options:
            continue
        value = tags.options[key]
        if isinstance(values, dict):
            word = {v: k for k, v in values.items()}.get(value)
            if word is None:
                raise ValueError(
                    f"options: {key}={value!r} is not one of {sorted(values.values())}")
            out += f"t {tag} 0/0/1 {word}\n"
        else:
            if value not in values:
                raise ValueError(f"options: {key}={value!r} is not one of {list(values)}")
            out += f"t {tag} 1/0/0 {list(values).index(value)}\n"
    unknown = set(tags.options) - {key for key, _ in OPTION_TAGS.values()}
    if unknown:
        raise ValueError(f"options: unknown keys {sorted(unknown)}")
    return out
