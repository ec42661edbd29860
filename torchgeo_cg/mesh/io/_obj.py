"""Wavefront OBJ: positions, polygon faces, texture coordinates and OpenSubdiv ``t`` tags.

Convention:
    - ``v x y z [w]`` or ``v x y z r g b`` (``w`` and colours are not kept);
      ``vt u [v [w]]`` (``v`` defaults to 0, ``w`` is not kept); ``vn`` lines are
      skipped; ``f`` corners are ``v``, ``v/vt``, ``v/vt/vn`` or ``v//vn``.
    - Indices are 1-based in the file, 0-based in memory; a negative index counts
      back from the last ``v`` (``vt``) read before its line, as the OBJ spec says.
    - Within a face, texture indices are on every corner or on none (``v`` and
      ``v//vn`` corners have none); faces may differ, as when one object has UVs
      and another has not. A face without them has ``-1`` on every corner of
      ``uv_faces``, where ``faces`` has its real indices; padding is where
      ``faces`` is ``-1``. ``uv_faces`` is ``None`` when no face has them.
    - ``t`` lines are OpenSubdiv's tags, see :mod:`torchgeo_cg.mesh.io._obj_tags`.
    - Known statements that do not describe polygons (``o g s usemtl mtllib l p``,
      free-form curves, ...) and comments are skipped silently.
    - What the format does not allow but cannot change positions or faces is
      skipped with one :class:`~torchgeo_cg.mesh.io.MeshFileWarning` per file,
      naming the first such line and how many there are: an unknown statement
      (``vx``, ``newmtl``, ``call`` and ``csh``, which are not run), and bytes that
      are not UTF-8 (latin-1, say) in a comment or in a name (``g``, ``o``,
      ``usemtl``, ...). Such bytes on a ``v vt vn f t`` line, and an unknown
      statement that is ``v vt f t`` glued to a number (``v1 2 3``: skipping it
      would lose a vertex), raise instead.
    - Comments start at ``#``; a line ending with ``\\`` continues on the next one.
"""

from __future__ import annotations

import io as _io
from typing import NamedTuple

import numpy as np

from torchgeo_cg.mesh.io._obj_tags import ObjTags, format_tags, parse_tags
from torchgeo_cg.mesh.io._text import (
    TextLines,
    blank_comments,
    chars_at,
    check_padding,
    file_error,
    first_chars,
    format_faces,
    format_rows,
    gather_lines,
    line_tokens,
    parse_numbers,
    read_text,
    skipped_message,
)

__all__: list[str] = []

OBJ_STATEMENTS = frozenset(
    b"v vt vn vp f l p t o g s mg usemtl mtllib cstype deg bmat step curv curv2 surf parm "
    b"trim hole scrv sp end con bevel c_interp d_interp lod shadow_obj trace_obj ctech stech "
    b"maplib usemap".split()
)
"""The OBJ statements read or knowingly skipped (``t``: OpenSubdiv's tags)."""

_KW = 16  # longest keyword we look at
_KNOWN = np.array(sorted(OBJ_STATEMENTS), dtype=f"S{_KW}")
_READ = ("v", "vt", "vn", "f", "t")  # the statements whose numbers are parsed


class ObjContent(NamedTuple):
    """What an OBJ file holds, as numpy arrays (indices 0-based).

    Attributes:
        verts_v3: ``(V, 3)`` float64.
        faces_fk: ``(F, K)`` int64 padded with ``-1``.
        uvs_t2: ``(T, 2)`` float64, or ``None`` without ``vt`` lines.
        uv_faces_fk: ``(F, K)`` int64 like ``faces_fk``, or ``None`` when faces have no ``vt``.
        tags: :class:`~torchgeo_cg.mesh.io._obj_tags.ObjTags`.
        skipped: the warning for what was skipped (see the module docstring), or ``None``.
    """

    verts_v3: np.ndarray
    faces_fk: np.ndarray
    uvs_t2: np.ndarray | None
    uv_faces_fk: np.ndarray | None
    tags: ObjTags
    skipped: str | None = None


def _classify(text: TextLines) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray]:
    """Line indices of each statement kind, then ``(pos, unknown lines, their keywords)``."""
    pos = first_chars(text)
    last = len(text.buf) - 1
    c0, c1, c2 = (text.buf[np.minimum(pos + k, last)] for k in range(3))
    v, end1, end2 = c0 == 118, c1 <= 32, c2 <= 32
    kinds = {
        "v": v & end1, "vt": v & (c1 == 116) & end2, "vn": v & (c1 == 110) & end2,
        "f": (c0 == 102) & end1, "t": (c0 == 116) & end1,
    }
    known = c0 == 10
    for mask in kinds.values():
        known |= mask
    other = np.flatnonzero(~known)
    word = chars_at(text, pos[other], _KW).view(f"S{_KW}").ravel()
    unknown = ~np.isin(word, _KNOWN)
    _refuse_glued(text, other[unknown], word[unknown])
    return {k: np.flatnonzero(m) for k, m in kinds.items()}, pos, other[unknown], word[unknown]


def _refuse_glued(text: TextLines, lines: np.ndarray, words: np.ndarray) -> None:
    """Raise for ``v``, ``vt``, ``f`` or ``t`` glued to a number (``v1 2 3``), a lost record."""
    if lines.size == 0:
        return
    w = words.view(np.uint8).reshape(len(words), _KW)
    numeric = (((w >= 48) & (w <= 57)) | (w == 43) | (w == 45) | (w == 46))
    one = ((w[:, 0] == 118) | (w[:, 0] == 102) | (w[:, 0] == 116)) & numeric[:, 1]
    glued = one | ((w[:, 0] == 118) & (w[:, 1] == 116) & numeric[:, 2])
    if glued.any():
        i = int(np.argmax(glued))
        shown = words[i].decode("utf-8", errors="replace")
        kw = shown[:2] if one[i] == 0 else shown[:1]
        raise file_error(text.name, text.numbers[lines[i]],
                         f"unknown OBJ statement {shown!r} (a {kw!r} glued to its first number; "
                         "skipping it would lose a record)")


def _skipped(text: TextLines, kinds: dict, unknown: np.ndarray, words: np.ndarray
             ) -> str | None:
    """The warning for unknown statements and non-UTF-8 bytes where nothing is read.

    Call after the comments are blanked: a non-UTF-8 byte still standing on a line
    whose numbers are read raises, naming the line.
    """
    bad = text.invalid
    lines = unknown
    if bad is not None and bad.size:
        line = np.searchsorted(text.ends, bad)
        read = np.zeros(len(text.ends), dtype=bool)
        for kind in _READ:  # loop over the five statement kinds
            read[kinds[kind]] = True
        hit = read[line] & (text.buf[bad] != 32)  # not blanked as a comment
        if hit.any():
            at = int(np.argmax(hit))
            raise file_error(text.name, text.numbers[line[at]],
                             f"not valid UTF-8 text (byte 0x{int(text.buf[bad[at]]):02x})")
        lines = np.union1d(unknown, line)
    if lines.size == 0:
        return None
    if unknown.size and unknown[0] == lines[0]:
        first = f"unknown OBJ statement {words[0].decode('utf-8', errors='replace')!r}"
    else:
        first = "bytes that are not UTF-8 in a comment or a name"
    return skipped_message(text.name, text.numbers[lines], first)


def _numbers_block(text, lines, pos, skip, allowed, what):
    """Numbers of ``lines`` after their ``skip``-byte keyword; count per line in ``allowed``."""
    for k in range(skip):
        text.buf[pos[lines] + k] = 32
    blob, segs = gather_lines(text, lines, text.starts[lines])
    tokens = line_tokens(blob, segs)
    bad = ~np.isin(tokens.counts, allowed)
    if bad.any():
        i = int(np.argmax(bad))
        raise file_error(
            text.name, text.numbers[lines[i]],
            f"{what} needs {', '.join(map(str, allowed[:-1]))} or {allowed[-1]} values, "
            f"got {tokens.counts[i]}",
        )
    values = parse_numbers(text, lines, blob, segs, tokens, np.float64)
    return values, tokens.counts


def _columns(values, counts, width, fill=0.0):
    """``(M, width)`` from per-line runs of ``counts`` values (missing ones ``fill``)."""
    if (counts == width).all():
        return values.reshape(-1, width)
    first = np.cumsum(counts) - counts
    col = np.arange(width)
    idx = first[:, None] + col
    return np.where(col < counts[:, None], values[np.minimum(idx, len(values) - 1)], fill)


def _per_token(positions: np.ndarray, token_starts: np.ndarray) -> np.ndarray:
    """How many of the sorted byte ``positions`` fall in each token (tokens hold no blank)."""
    before = np.searchsorted(positions, token_starts)
    return np.diff(np.append(before, len(positions)))


def _corner_forms(text, lines, blob, tokens):
    """Form of each corner: 0 ``v``, 1 ``v/vt``, 2 ``v/vt/vn``, 3 ``v//vn``."""
    slash = blob == 47
    if not slash.any():
        return np.zeros(len(tokens.starts), np.int64)
    n_slash = _per_token(np.flatnonzero(slash), tokens.starts)
    n_double = _per_token(np.flatnonzero(slash[:-1] & slash[1:]), tokens.starts)
    bad = (n_slash > 2) | (n_double > 1) | slash[tokens.starts]
    trailing = np.flatnonzero(slash[:-1] & (blob[1:] <= 32))  # "1/" ends a corner
    bad[np.searchsorted(tokens.starts, trailing, side="right") - 1] = True
    if bad.any():
        t = int(np.argmax(bad))
        start = tokens.starts[t]
        end = start + int(np.argmax(blob[start:] <= 32))
        corner = blob[start:end].tobytes().decode(errors="replace")
        raise file_error(text.name, text.numbers[lines[tokens.line()[t]]],
                         f"malformed face corner {corner!r}")
    blob[slash] = 32
    return np.where(n_slash == 0, 0, np.where(n_slash == 1, 1, np.where(n_double == 1, 3, 2)))


def _face_has_vt(text, lines, forms, starts_f):
    """``(F,)`` bool: the faces with texture indices, on every corner (else an error)."""
    vt_before = np.concatenate([[0], np.cumsum((forms == 1) | (forms == 2))])
    n_vt_f = np.diff(np.append(vt_before[starts_f], vt_before[-1]))
    has_vt = n_vt_f > 0
    mixed = has_vt & (n_vt_f < np.diff(np.append(starts_f, len(forms))))
    if mixed.any():
        i = int(np.argmax(mixed))
        raise file_error(text.name, text.numbers[lines[i]],
                         "face has texture indices on some corners only")
    return has_vt


def _resolve(text, lines, idx, corner_line, kind_lines, total, what, plural):
    """OBJ indices (1-based, negative relative) -> 0-based, range checked."""
    if idx.size == 0 or (idx.min() > 0 and idx.max() <= total):
        return idx - 1
    corner_line = corner_line()
    if (idx == 0).any():
        t = int(np.argmax(idx == 0))
        raise file_error(text.name, text.numbers[lines[corner_line[t]]],
                         f"{what} index 0 (OBJ indices start at 1)")
    out = idx - 1
    neg = idx < 0
    if neg.any():
        # number of `kind` lines before each corner's line
        before = np.searchsorted(kind_lines, lines[corner_line[neg]])
        out[neg] = before + idx[neg]
    bad = (out < 0) | (out >= total)
    if bad.any():
        t = int(np.argmax(bad))
        raise file_error(text.name, text.numbers[lines[corner_line[t]]],
                         f"{what} index {int(idx[t])} out of range, the file has {total} {plural}")
    return out


def _pad(values, degrees, k):
    if degrees.size == 0:
        return np.zeros((0, 3), np.int64)
    if (degrees == k).all():
        return values.reshape(-1, k)
    out = np.full((len(degrees), k), -1, np.int64)
    out[np.arange(k) < degrees[:, None]] = values
    return out


def _faces(text, kinds, pos, num_vertices, n_uvs):
    """``(faces_fk, uv_faces_fk or None)`` from the ``f`` lines."""
    lines = kinds["f"]
    text.buf[pos[lines]] = 32
    blob, segs = gather_lines(text, lines, text.starts[lines])
    corners = line_tokens(blob, segs)
    small = corners.counts < 3
    if small.any():
        i = int(np.argmax(small))
        raise file_error(text.name, text.numbers[lines[i]],
                         f"a face needs at least 3 vertices, got {corners.counts[i]}")
    if lines.size == 0:
        return np.zeros((0, 3), np.int64), None
    forms = _corner_forms(text, lines, blob, corners)
    starts_f = np.cumsum(corners.counts) - corners.counts
    has_vt = _face_has_vt(text, lines, forms, starts_f)
    numbers = line_tokens(blob, segs) if forms.any() else corners
    values = parse_numbers(text, lines, blob, segs, numbers, np.int64)
    if forms.any():
        n_numbers = np.array([1, 2, 3, 2])[forms]
        first = np.cumsum(n_numbers) - n_numbers
    else:
        first = slice(None)
    vi = _resolve(text, lines, values[first], corners.line, kinds["v"], num_vertices, "vertex",
                  "vertices")
    longest = int(np.argmax(corners.counts))
    width = check_padding(text.name, text.numbers[lines[longest]], corners.counts, len(text.buf))
    faces = _pad(vi, corners.counts, width)
    if not has_vt.any():
        return faces, None
    return faces, _uv_faces(text, lines, kinds, values, first, forms, corners, n_uvs, width)


def _uv_faces(text, lines, kinds, values, first, forms, corners, n_uvs, width):
    """``(F, K)`` texture indices: ``-1`` on the corners without them, and as padding."""
    with_vt = (forms == 1) | (forms == 2)
    if with_vt.all():
        ti = _resolve(text, lines, values[first + 1], corners.line, kinds["vt"], n_uvs,
                      "texture coordinate", "texture coordinates")
        return _pad(ti, corners.counts, width)
    ti = np.full(len(forms), -1, np.int64)
    ti[with_vt] = _resolve(text, lines, values[first[with_vt] + 1],
                           lambda: corners.line()[with_vt], kinds["vt"], n_uvs,
                           "texture coordinate", "texture coordinates")
    return _pad(ti, corners.counts, width)


def read_obj(data: bytes, name: str) -> ObjContent:
    """Parse the bytes of an OBJ file.

    Args:
        data: the file content.
        name: the file name for error messages.

    Returns:
        :class:`ObjContent`.

    Raises:
        ValueError: malformed content, naming the file and the line.

    Example:
        >>> c = read_obj(b"v 0 0 0\\nv 1 0 0\\nv 0 1 0\\nvt 0 0\\nf 1/1 2/1 -1/1\\n", "m.obj")
        >>> c.faces_fk.tolist(), c.uv_faces_fk.tolist(), c.uvs_t2.shape
        ([[0, 1, 2]], [[0, 0, 0]], (1, 2))
    """
    text = read_text(data, name, continuations=True, strict=False)
    if b"#" in data:
        blank_comments(text)
    kinds, pos, unknown, words = _classify(text)
    skipped = _skipped(text, kinds, unknown, words)
    values, counts = _numbers_block(text, kinds["v"], pos, 1, (3, 4, 6, 7), "'v'")
    verts = _columns(values, counts, 3)
    uvs = None
    if kinds["vt"].size:
        values, counts = _numbers_block(text, kinds["vt"], pos, 2, (1, 2, 3), "'vt'")
        uvs = _columns(values, counts, 2)
    faces, uv_faces = _faces(text, kinds, pos, len(verts), 0 if uvs is None else len(uvs))
    text.buf[pos[kinds["t"]]] = 32
    tags = parse_tags(text, kinds["t"], len(verts), faces)
    return ObjContent(verts, faces, uvs, uv_faces, tags, skipped)


def format_obj(content: ObjContent, precision: int, *, uv_precision: int | None = None,
               tag_precision: int | None = None) -> str:
    """OBJ text for ``content``: ``v``, ``vt``, ``f`` and ``t`` lines.

    Args:
        content: what to write (``tags`` may be empty).
        precision: significant digits of the vertices (17 round-trips float64).
        uv_precision, tag_precision: the same for the ``vt`` lines and the tag
            sharpness (default: ``precision``), so each keeps its own dtype's digits.

    Example:
        >>> from torchgeo_cg.mesh.io._obj_tags import ObjTags
        >>> c = ObjContent(np.eye(3), np.array([[0, 1, 2]]), None, None, ObjTags.empty())
        >>> print(format_obj(c, 9), end="")
        v 1 0 0
        v 0 1 0
        v 0 0 1
        f 1 2 3
    """
    out = _io.StringIO()
    out.write(format_rows("v", content.verts_v3, precision))
    if content.uvs_t2 is not None:
        out.write(format_rows("vt", content.uvs_t2, uv_precision or precision))
    out.write(format_faces("f", content.faces_fk, 1, content.uv_faces_fk))
    out.write(format_tags(content.tags, tag_precision or precision))
    return out.getvalue()
