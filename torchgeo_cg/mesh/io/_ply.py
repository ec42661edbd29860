"""Stanford PLY (ASCII and binary): vertex positions and polygon faces of any size.

Convention:
    - The header is read line by line and must be exactly PLY's: ``ply``, one
      ``format ascii|binary_little_endian|binary_big_endian 1.0``, ``element``,
      ``property`` (scalar or ``list``), ``comment``/``obj_info`` lines, and a line
      reading ``end_header``. The header is ASCII, except that ``comment`` and
      ``obj_info`` lines with other bytes (UTF-8, latin-1, ...) are skipped with one
      :class:`~torchgeo_cg.mesh.io.MeshFileWarning` naming the first. Scalar
      types: ``char uchar short ushort int uint float double`` and their
      ``int8 .. float64`` aliases.
    - A ``vertex`` element with ``x, y, z`` is required; ``face`` needs one integer
      list named ``vertex_indices`` (or ``vertex_index``); other elements and
      properties are read, checked and dropped. An element may hold one list.
    - Header counts are checked against the bytes (binary) or lines (ASCII) that
      follow before anything is allocated. ASCII: one record per line, blank lines
      skipped; every value must match its declared type (integers integral and in
      range). Binary: the data must end exactly after the last element.
    - Errors name the file and the line (ASCII and header) or the element record (binary).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from torchgeo_cg.mesh.io._text import (
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

PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}


class PlyProperty(NamedTuple):
    """One property: ``dtype`` a numpy code (``"f4"``), ``count_dtype`` set for lists."""

    name: str
    dtype: str
    count_dtype: str | None


class PlyElement(NamedTuple):
    """One element: ``count`` records of ``props``, declared on header line ``line``."""

    name: str
    count: int
    props: list
    line: int


class PlyHeader(NamedTuple):
    """``format`` (``ascii``, ``binary_*``), the elements, the body's byte offset and first
    line, and the warning for the non-ASCII comments skipped (or ``None``)."""

    format: str
    elements: list
    body: int
    body_line: int
    skipped: str | None = None


def _header_property(name, line, words, elements):
    if not elements:
        raise file_error(name, line, "'property' before any 'element'")
    is_list = len(words) > 1 and words[1] == "list"
    if len(words) != (5 if is_list else 3):
        raise file_error(name, line, "expected 'property <type> <name>' or "
                         "'property list <count type> <item type> <name>'")
    types = words[2:4] if is_list else words[1:2]
    for t in types:
        if t not in PLY_TYPES:
            raise file_error(name, line, f"unknown property type {t!r}")
    if is_list and PLY_TYPES[types[0]][0] == "f":
        raise file_error(name, line, f"list count type must be an integer, got {types[0]!r}")
    prop = PlyProperty(words[-1], PLY_TYPES[types[-1]], PLY_TYPES[types[0]] if is_list else None)
    if prop.name in [p.name for p in elements[-1].props]:
        raise file_error(name, line, f"property {prop.name!r} declared twice")
    if is_list and any(p.count_dtype for p in elements[-1].props):
        raise file_error(name, line, "an element with two list properties is not supported")
    elements[-1].props.append(prop)


def _header_line(name, line, words, fmt, elements):
    """Apply one header line; returns the format (set by a ``format`` line)."""
    key = words[0] if words else ""
    if key in ("comment", "obj_info"):
        return fmt
    if key == "format":
        if fmt is not None or elements or len(words) != 3 or words[1] not in _FORMATS:
            raise file_error(name, line, "expected one 'format ascii|binary_little_endian|"
                             "binary_big_endian 1.0' line before the elements")
        if words[2] != "1.0":
            raise file_error(name, line, f"unsupported PLY version {words[2]!r}")
        return words[1]
    if key == "element":
        if len(words) != 3 or not words[2].isdigit():
            raise file_error(name, line, "expected 'element <name> <count>'")
        if words[1] in [e.name for e in elements]:
            raise file_error(name, line, f"element {words[1]!r} declared twice")
        elements.append(PlyElement(words[1], int(words[2]), [], line))
        return fmt
    if key == "property":
        _header_property(name, line, words, elements)
        return fmt
    raise file_error(name, line, f"unknown header line {' '.join(words)[:40]!r}")


def read_ply_header(data: bytes, name: str) -> PlyHeader:
    """Parse the header, line by line up to the line reading ``end_header``.

    Example:
        >>> h = read_ply_header(b"ply\\nformat ascii 1.0\\nelement vertex 0\\n"
        ...                     b"property float x\\nend_header\\n", "m.ply")
        >>> h.format, h.elements[0].name, h.elements[0].count, h.body
        ('ascii', 'vertex', 0, 66)
    """
    if not (data.startswith(b"ply\n") or data.startswith(b"ply\r\n")):
        raise file_error(name, 1, "not a PLY file (the first line must read 'ply')")
    fmt, elements, pos, line, skipped = None, [], data.index(b"\n") + 1, 1, []
    while True:  # loop over header lines
        end = data.find(b"\n", pos)
        if end < 0:
            raise file_error(name, None, "no 'end_header' line")
        raw, pos, line = data[pos:end], end + 1, line + 1
        if not raw.isascii():
            if raw.split(None, 1)[:1] not in ([b"comment"], [b"obj_info"]):
                raise file_error(name, line, "the header is not ASCII text")
            skipped.append(line)  # a comment cannot change positions or faces
            continue
        words = raw.decode("ascii").split()
        if words == ["end_header"]:
            break
        fmt = _header_line(name, line, words, fmt, elements)
    if fmt is None:
        raise file_error(name, line, "no 'format' line before 'end_header'")
    note = skipped_message(name, np.array(skipped, np.int64),
                           "a 'comment' or 'obj_info' line that is not ASCII")
    return PlyHeader(fmt, elements, pos, line + 1, note)


class _Records(NamedTuple):
    """One element's values: scalars by name ``(count,)`` and the list, padded."""

    scalars: dict
    lists: np.ndarray | None  # (count, K) padded with -1 (integer lists) or None
    degrees: np.ndarray | None  # (count,)
    where: object  # record index -> human location ("line 12" or "record 3")


def _check_typed(name, where, values, dtype, what):
    """Integer-typed values must be integral and inside their type's range."""
    if dtype[0] == "f" or values.size == 0:
        return
    info = np.iinfo(dtype)
    bad = (values != np.floor(values)) | (values < info.min) | (values > info.max)
    if bad.any():
        i = int(np.argmax(bad.reshape(len(bad), -1).any(1)) if bad.ndim > 1 else np.argmax(bad))
        got = values[i] if values.ndim == 1 else values[i][bad[i]][0]
        raise where(i, f"{what}: expected a {np.dtype(dtype).name}, got {float(got)!r}")


def _ascii_element(text, lines, el: PlyElement) -> _Records:
    def where(i, msg):
        return file_error(text.name, text.numbers[lines[i]], msg)

    blob, segs = gather_lines(text, lines, text.starts[lines])
    tokens = line_tokens(blob, segs)
    li = next((k for k, p in enumerate(el.props) if p.count_dtype), None)
    n_scalar = len(el.props) - (li is not None)
    short = tokens.counts < n_scalar + (li is not None)
    if li is None:
        short = tokens.counts != n_scalar
    if short.any():
        i = int(np.argmax(short))
        raise where(i, f"element {el.name!r}: expected {n_scalar} values, got {tokens.counts[i]}")
    values = parse_numbers(text, lines, blob, segs, tokens, np.float64)
    first = np.cumsum(tokens.counts) - tokens.counts
    degrees = None
    if li is not None:
        degrees_f = values[first + li]
        _check_typed(text.name, where, degrees_f, el.props[li].count_dtype, "list count")
        degrees = degrees_f.astype(np.int64)
        bad = tokens.counts != n_scalar + 1 + degrees
        if bad.any():
            i = int(np.argmax(bad))
            raise where(i, f"element {el.name!r}: the list holds {degrees[i]} values, so the "
                           f"line needs {n_scalar + 1 + degrees[i]} values, got {tokens.counts[i]}")
    scalars, lists, col = {}, None, first.copy()
    for p in el.props:  # loop over properties
        if p.count_dtype is None:
            scalars[p.name] = values[col]
            _check_typed(text.name, where, scalars[p.name], p.dtype, p.name)
            col = col + 1
            continue
        longest = text.numbers[lines[int(np.argmax(degrees))]] if degrees.size else None
        width = check_padding(text.name, longest, degrees, len(text.buf))
        valid = np.arange(width) < degrees[:, None]
        items = values[np.where(valid, col[:, None] + 1 + np.arange(width), 0)]
        _check_typed(text.name, where, np.where(valid, items, 0), p.dtype, p.name)
        lists = np.where(valid, items, -1)
        col = col + 1 + degrees
    return _Records(scalars, lists, degrees, where)


def _read_ascii(data, name, header: PlyHeader) -> dict:
    text = read_text(data, name, offset=header.body, first_line=header.body_line)
    pos = first_chars(text)
    records = np.flatnonzero(text.buf[pos] != 10)  # non-blank lines
    row = 0
    for el in header.elements:  # check every count before reading anything
        if el.count > len(records) - row:
            raise file_error(name, el.line, f"element {el.name!r} declares {el.count} records, "
                             f"but only {len(records) - row} non-blank lines are left for it")
        row += el.count
    if len(records) > row:
        raise file_error(name, text.numbers[records[row]],
                         f"extra line after the {row} declared records")
    out, row = {}, 0
    for el in header.elements:  # loop over element kinds
        out[el.name] = _ascii_element(text, records[row:row + el.count], el)
        row += el.count
    return out


def _struct(props, end) -> np.dtype:
    return np.dtype([(p.name, end + p.dtype) for p in props])


def _list_starts(data, pos, el, end, pre, post):
    """Byte offsets of each record of an element with one list, vectorized."""
    lp = next(p for p in el.props if p.count_dtype)
    cdt, idt = np.dtype(end + lp.count_dtype), np.dtype(end + lp.dtype)
    body = np.frombuffer(data, np.uint8, offset=pos)
    size = len(body) + 1  # the last slot is a sink for records running past the end
    first = np.frombuffer(data, cdt, 1, pos + pre)[0] if len(body) >= pre + cdt.itemsize else 0
    rec = pre + cdt.itemsize + idt.itemsize * int(first) + post
    if int(first) >= 0 and el.count * rec <= len(body):  # uniform sizes: one strided view
        counts = np.ndarray((el.count,), cdt, data, pos + pre, (rec,))
        if (counts == first).all():
            return np.arange(el.count, dtype=np.int64) * rec, rec * el.count
    windows = np.lib.stride_tricks.sliding_window_view(
        np.concatenate([body, np.zeros(pre + cdt.itemsize, np.uint8)]), cdt.itemsize)
    count_at = windows[pre : pre + len(body)].copy().view(cdt).reshape(-1).astype(np.int64)
    if (count_at < 0).any():  # signed counts: negative ones are only an error where read
        count_at = np.maximum(count_at, -1)
    step = pre + cdt.itemsize + post + idt.itemsize * np.maximum(count_at, 0)
    jump = np.minimum(np.arange(len(body)) + step, size - 1)
    jump = np.concatenate([jump, [size - 1]])
    starts = np.zeros(1, np.int64)
    while len(starts) < el.count:  # pointer doubling: loop over log2(count) levels
        starts = np.concatenate([starts, jump[starts]])
        jump = jump[jump]
    starts = starts[: el.count]
    return starts, None


def _binary_list_element(data, pos, el, end, where, name) -> tuple[_Records, int]:
    li = next(k for k, p in enumerate(el.props) if p.count_dtype)
    lp = el.props[li]
    pre_dt, post_dt = _struct(el.props[:li], end), _struct(el.props[li + 1:], end)
    cdt, idt = np.dtype(end + lp.count_dtype), np.dtype(end + lp.dtype)
    if el.count == 0:
        names = (pre_dt.names or ()) + (post_dt.names or ())
        empty = np.zeros(0, np.int64)
        return _Records({n: np.zeros(0) for n in names}, empty.reshape(0, 3), empty, where), 0
    starts, total = _list_starts(data, pos, el, end, pre_dt.itemsize, post_dt.itemsize)
    if total is not None:  # every record has the same size: one structured view
        k = (total // max(el.count, 1) - pre_dt.itemsize - cdt.itemsize - post_dt.itemsize)
        k //= idt.itemsize
        fields = [(p.name, end + p.dtype) for p in el.props if p is not lp]
        fields.insert(li, (lp.name, idt, (k,)))
        fields.insert(li, (lp.name + " count", cdt))
        raw = np.frombuffer(data, np.dtype(fields), el.count, pos)
        items = raw[lp.name].astype(np.float64 if idt.kind == "f" else np.int64)
        scalars = {n: raw[n] for n, *_ in fields if n not in (lp.name, lp.name + " count")}
        degrees = np.full(el.count, k, dtype=np.int64)
        return _Records(scalars, items.reshape(el.count, k), degrees, where), total
    body = np.frombuffer(data, np.uint8, offset=pos)
    past = starts + pre_dt.itemsize + cdt.itemsize > len(body)
    if past.any():
        raise where(int(np.argmax(past)), "truncated: the record runs past the end of the file")
    head = starts[:, None] + pre_dt.itemsize + np.arange(cdt.itemsize)
    degrees = body[head].copy().view(cdt).reshape(-1).astype(np.int64)
    if (degrees < 0).any():
        i = int(np.argmax(degrees < 0))
        raise where(i, f"negative list count {degrees[i]}")
    ends = starts + pre_dt.itemsize + cdt.itemsize + idt.itemsize * degrees + post_dt.itemsize
    if el.count and ends[-1] > len(body) or (ends[:-1] != starts[1:]).any():
        i = int(np.argmax(np.append(ends[:-1] != starts[1:], True)))
        raise where(i, "truncated: the record runs past the end of the file")
    width = check_padding(name, None, degrees, len(data))
    valid = np.arange(width) < degrees[:, None]
    at = starts[:, None] + pre_dt.itemsize + cdt.itemsize + idt.itemsize * np.arange(width)
    at = np.where(valid, at, 0)[..., None] + np.arange(idt.itemsize)
    items = body[np.minimum(at, len(body) - 1)].copy().view(idt)[..., 0]
    lists = np.where(valid, items.astype(np.float64 if idt.kind == "f" else np.int64), -1)
    scalars = {}
    for dt, off in ((pre_dt, 0), (post_dt, None)):  # the scalars before and after the list
        if not dt.names:
            continue
        base = starts if off == 0 else ends - dt.itemsize
        raw = body[base[:, None] + np.arange(dt.itemsize)].copy().view(dt).reshape(-1)
        scalars.update({n: raw[n].astype(np.float64) for n in dt.names})
    return _Records(scalars, lists, degrees, where), int(ends[-1]) if el.count else 0


def _min_record_bytes(el, end) -> int:
    """Fewest bytes one record can take (its lists empty)."""
    return sum(np.dtype(end + (p.count_dtype or p.dtype)).itemsize for p in el.props)


def _read_binary(data, name, header: PlyHeader) -> dict:
    end = _FORMATS[header.format]
    pos, out = header.body, {}
    for el in header.elements:  # loop over element kinds
        need = el.count * _min_record_bytes(el, end)
        if need > len(data) - pos:
            raise file_error(name, el.line, f"element {el.name!r} declares {el.count} records "
                             f"needing at least {need} bytes, but only {len(data) - pos} "
                             "bytes follow")

        def where(i, msg, el=el):
            return file_error(name, None, f"element {el.name!r} record {i}: {msg}")

        if any(p.count_dtype for p in el.props):
            out[el.name], used = _binary_list_element(data, pos, el, end, where, name)
        else:
            dt = _struct(el.props, end)
            raw = np.frombuffer(data, dt, el.count, pos)
            out[el.name] = _Records({n: raw[n] for n in dt.names or ()}, None, None, where)
            used = el.count * dt.itemsize
        pos += used
    if pos != len(data):
        raise file_error(name, None, f"{len(data) - pos} bytes after the last element")
    return out


def _mesh_of(name, header, records) -> tuple[np.ndarray, np.ndarray]:
    elements = {e.name: e for e in header.elements}
    if "vertex" not in elements:
        raise file_error(name, None, "no 'vertex' element")
    vert = records["vertex"]
    missing = [a for a in "xyz" if a not in vert.scalars]
    if missing:
        raise file_error(name, elements["vertex"].line, f"'vertex' lacks properties {missing}")
    verts = np.empty((len(vert.scalars["x"]), 3))
    for k, axis in enumerate("xyz"):  # loop over the 3 coordinates
        verts[:, k] = vert.scalars[axis]
    if "face" not in elements:
        return verts, np.zeros((0, 3), np.int64)
    face_el, face = elements["face"], records["face"]
    lp = next((p for p in face_el.props if p.count_dtype), None)
    if lp is None or lp.name not in ("vertex_indices", "vertex_index") or lp.dtype[0] == "f":
        raise file_error(name, face_el.line, "'face' needs an integer list property "
                         "'vertex_indices'")
    small = face.degrees < 3
    if small.any():
        i = int(np.argmax(small))
        raise face.where(i, f"face {i} has {face.degrees[i]} vertices; a face needs at least 3")
    faces = np.asarray(face.lists, dtype=np.int64)
    full = faces.size == 0 or (face.degrees == faces.shape[1]).all()
    if full and (faces.size == 0 or (faces.min() >= 0 and faces.max() < len(verts))):
        return verts, faces
    used = np.arange(faces.shape[1]) < face.degrees[:, None]
    bad = (faces >= len(verts)) | ((faces < 0) & used)
    if bad.any():
        i = int(np.argmax(bad.any(1)))
        raise face.where(i, f"face {i} has vertex index {int(faces[i][bad[i]][0])}, "
                            f"out of range [0, {len(verts)})")
    return verts, faces


def read_ply(data: bytes, name: str) -> tuple[np.ndarray, np.ndarray, str | None]:
    """``(verts (V, 3) float64, faces (F, K) int64 padded with -1, warning or None)`` of a
    PLY file (the warning: :attr:`PlyHeader.skipped`).

    Example:
        >>> v, f, _ = read_ply(b"ply\\nformat ascii 1.0\\nelement vertex 3\\nproperty float x\\n"
        ...                 b"property float y\\nproperty float z\\nelement face 1\\n"
        ...                 b"property list uchar int vertex_indices\\nend_header\\n"
        ...                 b"0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n", "m.ply")
        >>> v.shape, f.tolist()
        ((3, 3), [[0, 1, 2]])
    """
    header = read_ply_header(data, name)
    if header.format == "ascii":
        records = _read_ascii(data, name, header)
    else:
        records = _read_binary(data, name, header)
    return (*_mesh_of(name, header, records), header.skipped)


def format_ply(verts_v3: np.ndarray, faces_fk: np.ndarray, binary: bool, precision: int) -> bytes:
    """PLY bytes: ``float``/``double`` ``x y z`` (by ``verts_v3.dtype``) and
    ``list uchar int vertex_indices``; binary little-endian or ASCII.

    Example:
        >>> b = format_ply(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]]), False, 9)
        >>> print(b.decode().splitlines()[-2:])
        ['0 0 1', '3 0 1 2']
    """
    ftype, npf = ("double", "<f8") if verts_v3.dtype == np.float64 else ("float", "<f4")
    header = (
        f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\n"
        f"comment torchgeo_cg\nelement vertex {len(verts_v3)}\n"
        f"property {ftype} x\nproperty {ftype} y\nproperty {ftype} z\n"
        f"element face {len(faces_fk)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode("ascii")
    valid_fk = faces_fk >= 0
    sizes_f = valid_fk.sum(1)
    if binary:
        rec_f = 1 + 4 * sizes_f
        starts_f = np.cumsum(rec_f) - rec_f
        buf = np.zeros(int(rec_f.sum()), dtype=np.uint8)
        buf[starts_f] = sizes_f.astype(np.uint8)
        rows, cols = np.nonzero(valid_fk)
        at = (starts_f[rows] + 1 + 4 * cols)[:, None] + np.arange(4)
        buf[at] = faces_fk[valid_fk].astype("<i4").view(np.uint8).reshape(-1, 4)
        return header + np.ascontiguousarray(verts_v3, dtype=npf).tobytes() + buf.tobytes()
    body = format_rows("", verts_v3, precision) + format_faces("", faces_fk, 0, count=True)
    return header + body.encode("ascii")
