"""Polygon mesh I/O (OBJ, PLY) and trimesh interop, keeping polygons of any size.

Convention:
    - A mesh is ``Mesh(verts, faces)``: ``verts`` ``(V, 3)`` float, ``faces``
      ``(F, K)`` long padded with ``-1`` (see :mod:`torchgeo_cg.mesh.faces`).
    - Indices are 0-based in memory; OBJ files are 1-based (negative OBJ indices,
      relative to the last vertex read, are resolved).
    - Faces keep their order and winding (counter-clockwise seen from outside);
      vertices keep their file order. Nothing is merged, removed or re-ordered.
    - trimesh holds triangles only: :func:`to_trimesh` fan-triangulates polygons.
"""

from __future__ import annotations

import io as _io
import os
import re
from typing import Any, NamedTuple

import numpy as np
import torch

from torchgeo_cg.core.check import check_float, check_shape, check_tensor
from torchgeo_cg.mesh.faces import check_faces, pad_faces, triangulate_faces

__all__ = ["Mesh", "load_mesh", "save_mesh", "from_trimesh", "to_trimesh"]


class Mesh(NamedTuple):
    """A polygon mesh.

    Attributes:
        verts: ``(V, 3)`` float vertex positions.
        faces: ``(F, K)`` long vertex indices, padded with ``-1``.

    Example:
        >>> m = Mesh(torch.zeros(4, 3), torch.tensor([[0, 1, 2, 3]]))
        >>> m.verts.shape, m.faces.shape
        (torch.Size([4, 3]), torch.Size([1, 4]))
    """

    verts: torch.Tensor
    faces: torch.Tensor


def _resolve_dtype(dtype: torch.dtype | None) -> torch.dtype:
    return torch.get_default_dtype() if dtype is None else dtype


_OBJ_V = re.compile(r"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", re.MULTILINE)
_OBJ_F = re.compile(r"^[ \t]*f[ \t]+([^\r\n#]*)", re.MULTILINE)
_OBJ_VF = re.compile(r"^[ \t]*(v|f)[ \t]", re.MULTILINE)
_SLASH_TAIL = re.compile(r"/\S*")


def _parse_obj(text: str) -> tuple[np.ndarray, np.ndarray]:
    """OBJ text -> ``(V, 3)`` float64 and ``(F, K)`` int64 padded faces (0-based)."""
    verts_v3 = np.array(_OBJ_V.findall(text), dtype=np.float64).reshape(-1, 3)
    bodies = _OBJ_F.findall(text)
    if not bodies:
        return verts_v3, np.zeros((0, 3), dtype=np.int64)
    # Keep only the vertex index of "v/vt/vn" tokens, separate faces with a 0
    # (never a valid OBJ index), and split the flat integer stream vectorized.
    stream = _SLASH_TAIL.sub("", " 0 ".join(bodies) + " 0")
    flat = np.array(stream.split(), dtype=np.int64)
    sep = flat == 0
    face_of_token = np.cumsum(sep) - sep  # face index of each token
    idx = flat[~sep]
    face_of_idx = face_of_token[~sep]
    if (idx < 0).any():  # relative indices: count the vertices read before each face
        kinds = np.array(_OBJ_VF.findall(text))
        verts_before_face = np.cumsum(kinds == "v")[kinds == "f"]
        rel = idx < 0
        idx[rel] = verts_before_face[face_of_idx[rel]] + idx[rel] + 1
    idx = idx - 1
    sizes_f = np.bincount(face_of_idx, minlength=len(bodies))
    starts_f = np.cumsum(sizes_f) - sizes_f
    col = np.arange(idx.size) - starts_f[face_of_idx]
    faces_fk = np.full((len(bodies), max(int(sizes_f.max()), 3)), -1, dtype=np.int64)
    faces_fk[face_of_idx, col] = idx
    return verts_v3, faces_fk


def _face_lines(faces_fk: np.ndarray, head: np.ndarray, offset: int) -> str:
    """One text line per face: ``head[f]`` then the valid indices (+ ``offset``)."""
    lines = head.astype(str).astype(object)
    for k in range(faces_fk.shape[1]):  # loop over polygon degree, not faces
        col = faces_fk[:, k]
        tokens = np.char.add(" ", (col + offset).astype(str)).astype(object)
        lines = lines + np.where(col >= 0, tokens, "")
    return "".join(line + "\n" for line in lines.tolist())


def _format_obj(verts_v3: np.ndarray, faces_fk: np.ndarray, precision: int) -> str:
    out = _io.StringIO()
    np.savetxt(out, verts_v3, fmt=f"v %.{precision}g %.{precision}g %.{precision}g")
    out.write(_face_lines(faces_fk, np.full(len(faces_fk), "f"), 1))
    return out.getvalue()


def _ply_binary_faces(faces_fk: np.ndarray) -> bytes:
    """Binary little-endian ``list uchar int`` records for variable-size faces."""
    valid_fk = faces_fk >= 0
    sizes_f = valid_fk.sum(1)
    rec_len_f = 1 + 4 * sizes_f
    starts_f = np.cumsum(rec_len_f) - rec_len_f
    buf = np.zeros(int(rec_len_f.sum()), dtype=np.uint8)
    buf[starts_f] = sizes_f.astype(np.uint8)
    idx_bytes = faces_fk[valid_fk].astype("<i4").view(np.uint8).reshape(-1, 4)
    face_of = np.nonzero(valid_fk)[0]
    col_of = np.nonzero(valid_fk)[1]
    pos = starts_f[face_of] + 1 + 4 * col_of
    buf[pos[:, None] + np.arange(4)[None, :]] = idx_bytes
    return buf.tobytes()


def _mesh_arrays(verts: torch.Tensor, faces) -> tuple[torch.Tensor, torch.Tensor]:
    check_tensor(verts, "verts")
    check_shape(verts, ["V", "3"], "verts")
    check_float(verts, "verts")
    faces_fk = pad_faces(faces)
    if isinstance(faces, torch.Tensor) and faces.device != verts.device:
        raise ValueError(
            f"verts and faces must be on the same device, got {verts.device} and {faces.device}"
        )
    faces_fk = check_faces(
        faces_fk.cpu(), verts.shape[0], allow_duplicates=True, allow_degenerate=True
    )
    return verts, faces_fk


def save_mesh(path: str | os.PathLike, verts: torch.Tensor, faces, binary: bool = True) -> None:
    """Write a polygon mesh to ``.obj`` or ``.ply``, keeping polygons of any size.

    Convention:
        See the module docstring; OBJ indices are written 1-based. PLY is written
        binary little-endian (``binary=False``: ASCII), with ``float``/``double``
        ``x, y, z`` following ``verts.dtype`` and ``list uchar int vertex_indices``.

    Args:
        path: destination; the suffix (``.obj`` or ``.ply``, any case) picks the format.
        verts: ``(V, 3)`` float (detached and moved to the CPU for writing).
        faces: ``(F, K)`` long padded with ``-1``, or a list of index lists.
        binary: PLY only; ignored for OBJ.

    Raises:
        ValueError: unknown suffix or invalid faces.

    Example:
        >>> import tempfile, os
        >>> d = tempfile.mkdtemp()
        >>> v = torch.tensor([[0., 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]])
        >>> save_mesh(os.path.join(d, "m.obj"), v, [[0, 1, 2, 3], [1, 4, 2]])
        >>> print(open(os.path.join(d, "m.obj")).read().splitlines()[-2:])
        ['f 1 2 3 4', 'f 2 5 3']
    """
    verts, faces_fk = _mesh_arrays(verts, faces)
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    verts_v3 = verts.detach().cpu().numpy()
    faces_np = faces_fk.numpy()
    if suffix == ".obj":
        precision = 17 if verts.dtype == torch.float64 else 9
        with open(path, "w") as fh:
            fh.write(_format_obj(verts_v3, faces_np, precision))
        return
    if suffix != ".ply":
        raise ValueError(f"path: expected a .obj or .ply suffix, got {suffix!r}")
    if faces_np.shape[1] > 255:
        raise ValueError(
            f"faces: PLY stores at most 255 vertices per face, got {faces_np.shape[1]}"
        )
    ftype, npf = ("double", "<f8") if verts.dtype == torch.float64 else ("float", "<f4")
    header = (
        f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\n"
        f"comment torchgeo_cg\nelement vertex {len(verts_v3)}\n"
        f"property {ftype} x\nproperty {ftype} y\nproperty {ftype} z\n"
        f"element face {len(faces_np)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        if binary:
            fh.write(np.ascontiguousarray(verts_v3, dtype=npf).tobytes())
            fh.write(_ply_binary_faces(faces_np))
        else:
            body = _io.StringIO()
            np.savetxt(body, verts_v3, fmt="%.17g" if ftype == "double" else "%.9g")
            body.write(_face_lines(faces_np, (faces_np >= 0).sum(1), 0))
            fh.write(body.getvalue().encode("ascii"))


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def _ply_header(data: bytes) -> tuple[str, list, int]:
    """Parse a PLY header -> (format, [(element, count, [(prop, type, list_count_type)])], body)."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise ValueError("path: not a PLY file (no 'ply' magic or no 'end_header')")
    body = data.index(b"\n", end) + 1
    fmt, elements = "", []
    for line in data[:end].decode("ascii", errors="replace").splitlines():  # header lines
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "format":
            fmt = tok[1]
        elif tok[0] == "element":
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property" and tok[1] == "list":
            elements[-1][2].append((tok[4], _PLY_TYPES[tok[3]], _PLY_TYPES[tok[2]]))
        elif tok[0] == "property":
            elements[-1][2].append((tok[2], _PLY_TYPES[tok[1]], None))
    return fmt, elements, body


def _ply_list_starts(count_at: np.ndarray, start: int, n_records: int, fixed: int, item: int):
    """Record start offsets of ``n_records`` variable-size binary records, vectorized.

    A record at byte ``i`` has ``fixed + item * count_at[i]`` bytes, so
    ``next[i]`` is a jump table; pointer doubling (loop over ``log2 F`` levels)
    collects ``next^m(start)`` for ``m < n_records`` without a loop over records.
    """
    size = len(count_at) + 1  # the last slot is a sink for jumps past the end
    next_b = np.minimum(np.arange(size) + fixed + item * np.r_[count_at, 0], size - 1)
    starts = np.array([start], dtype=np.int64)
    jump = next_b
    while len(starts) < n_records:
        starts = np.concatenate([starts, jump[starts]])
        jump = jump[jump]
    return starts[:n_records]


def _load_ply(path) -> tuple[np.ndarray, np.ndarray]:
    """Small PLY reader (ASCII and binary) keeping the face lists of any size."""
    with open(path, "rb") as fh:
        data = fh.read()
    fmt, elements, offset = _ply_header(data)
    verts_v3 = np.zeros((0, 3))
    faces_fk = np.zeros((0, 3), dtype=np.int64)
    if fmt == "ascii":
        lines = data[offset:].decode("ascii").splitlines()
        row = 0
        for name, count, props in elements:  # loop over the few element kinds
            recs = lines[row:row + count]
            row += count
            if name == "vertex":
                table = np.loadtxt(recs, dtype=np.float64, ndmin=2).reshape(count, -1)
                cols = [[p[0] for p in props].index(a) for a in "xyz"]
                verts_v3 = table[:, cols]
            elif name == "face" and count:
                # the list is assumed first: "n i0 .. in-1 [other props]"
                stream = " -1 ".join(recs) + " -1"
                flat = np.array(stream.split(), dtype=np.float64).astype(np.int64)
                sep = flat == -1
                rec_of = np.cumsum(sep) - sep
                head = np.r_[0, np.nonzero(sep)[0][:-1] + 1]  # first token of each record
                n_f = flat[head]
                pos = np.arange(flat.size) - head[rec_of]
                take = ~sep & (pos >= 1) & (pos <= n_f[rec_of])
                faces_fk = np.full((count, max(int(n_f.max()), 3)), -1, dtype=np.int64)
                faces_fk[rec_of[take], pos[take] - 1] = flat[take]
        return verts_v3, faces_fk
    if fmt not in ("binary_little_endian", "binary_big_endian"):
        raise ValueError(f"path: unsupported PLY format {fmt!r}")
    end = "<" if fmt == "binary_little_endian" else ">"
    buf = np.frombuffer(data, dtype=np.uint8, offset=offset)
    pos = 0
    for name, count, props in elements:
        lists = [p for p in props if p[2] is not None]
        if not lists:
            dt = np.dtype([(p[0], end + p[1]) for p in props])
            table = np.frombuffer(buf[pos:pos + count * dt.itemsize].tobytes(), dtype=dt)
            pos += count * dt.itemsize
            if name == "vertex":
                verts_v3 = np.stack([table[a].astype(np.float64) for a in "xyz"], axis=1)
            continue
        if name != "face" or len(lists) != 1 or props[0][2] is None:
            raise ValueError(f"path: unsupported PLY element {name!r} with list properties")
        _, item_t, count_t = props[0]
        cnt_dt, item_dt = np.dtype(end + count_t), np.dtype(end + item_t)
        rest = sum(np.dtype(p[1]).itemsize for p in props[1:])
        fixed = cnt_dt.itemsize + rest
        body = buf[pos:]
        pad = np.zeros(cnt_dt.itemsize, dtype=np.uint8)
        padded = np.concatenate([body, pad])
        count_at = np.lib.stride_tricks.sliding_window_view(padded, cnt_dt.itemsize)
        count_at = count_at[: len(body)].copy().view(cnt_dt).reshape(-1).astype(np.int64)
        starts = _ply_list_starts(count_at, 0, count, fixed, item_dt.itemsize)
        n_f = count_at[starts]
        width = max(int(n_f.max()) if count else 3, 3)
        col = np.arange(width)
        valid = col[None, :] < n_f[:, None]
        byte0 = starts[:, None] + cnt_dt.itemsize + col[None, :] * item_dt.itemsize
        idx_bytes = body[(byte0[valid][:, None] + np.arange(item_dt.itemsize)).clip(0)]
        faces_fk = np.full((count, width), -1, dtype=np.int64)
        faces_fk[valid] = idx_bytes.copy().view(item_dt).reshape(-1)
        pos += int(starts[-1] + fixed + item_dt.itemsize * n_f[-1]) if count else 0
    return verts_v3, faces_fk


def load_mesh(
    path: str | os.PathLike,
    dtype: torch.dtype | None = None,
    device: torch.device | str | None = None,
) -> Mesh:
    """Read an ``.obj`` or ``.ply`` polygon mesh, keeping polygons of any size.

    Convention:
        See the module docstring. OBJ: only ``v`` and ``f`` records are read
        (``vt``/``vn``/groups/materials are ignored; ``f 1/2/3`` keeps ``1``).
        PLY (ASCII or binary, any scalar types) needs ``x, y, z`` vertex
        properties and a face element whose first property is the index list.
        No vertex is merged or dropped.

    Args:
        path: an ``.obj`` or ``.ply`` file.
        dtype: dtype of ``verts`` (default: ``torch.get_default_dtype()``).
        device: device of both tensors (default: CPU).

    Returns:
        :class:`Mesh` with ``verts`` ``(V, 3)`` and ``faces`` ``(F, K)`` padded with ``-1``.

    Raises:
        ValueError: unknown suffix, or face indices out of range.

    Example:
        >>> import tempfile, os
        >>> path = os.path.join(tempfile.mkdtemp(), "m.obj")
        >>> with open(path, "w") as fh:
        ...     _ = fh.write("v 0 0 0\\nv 1 0 0\\nv 1 1 0\\nv 0 1 0\\nv 2 0 0\\n"
        ...                  "f 1/1 2/2 3/3 4/4\\nf -4 -1 -3\\n")
        >>> load_mesh(path).faces
        tensor([[ 0,  1,  2,  3],
                [ 1,  4,  2, -1]])
    """
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    if suffix == ".obj":
        with open(path, encoding="utf-8", errors="replace") as fh:
            verts_v3, faces_fk = _parse_obj(fh.read())
    elif suffix == ".ply":
        verts_v3, faces_fk = _load_ply(path)
    else:
        raise ValueError(f"path: expected a .obj or .ply suffix, got {suffix!r}")
    faces = check_faces(
        torch.from_numpy(faces_fk), len(verts_v3), allow_duplicates=True, allow_degenerate=True
    )
    verts = torch.from_numpy(verts_v3).to(device=device, dtype=_resolve_dtype(dtype))
    return Mesh(verts, faces.to(device))


def from_trimesh(
    mesh: Any, dtype: torch.dtype | None = None, device: torch.device | str | None = None
) -> Mesh:
    """Convert a ``trimesh.Trimesh`` to a :class:`Mesh` (triangles, same order).

    Args:
        mesh: a ``trimesh.Trimesh`` (anything with ``.vertices`` ``(V, 3)`` and
            ``.faces`` ``(F, 3)``).
        dtype: dtype of ``verts`` (default: ``torch.get_default_dtype()``).
        device: device of both tensors (default: CPU).

    Returns:
        :class:`Mesh` with ``verts`` ``(V, 3)`` and ``faces`` ``(F, 3)`` long.

    Example:
        >>> import trimesh
        >>> m = from_trimesh(trimesh.creation.box())
        >>> m.verts.shape, m.faces.shape, m.faces.dtype
        (torch.Size([8, 3]), torch.Size([12, 3]), torch.int64)
    """
    for attr in ("vertices", "faces"):
        if not hasattr(mesh, attr):
            raise TypeError(f"mesh: expected a trimesh.Trimesh, got {type(mesh).__name__}")
    verts = torch.as_tensor(np.asarray(mesh.vertices, dtype=np.float64))
    faces = torch.as_tensor(np.asarray(mesh.faces, dtype=np.int64)).reshape(-1, 3)
    return Mesh(verts.to(device=device, dtype=_resolve_dtype(dtype)), faces.to(device))


def to_trimesh(verts_or_result: Any, faces=None, process: bool = False):
    """Build a ``trimesh.Trimesh`` from tensors or from any result with ``.verts``/``.faces``.

    Convention:
        Polygons are fan-triangulated (:func:`~torchgeo_cg.mesh.faces.triangulate_faces`),
        keeping winding and face order. Tensors are detached and copied to the CPU.
        ``process=False`` (default) keeps vertices exactly as given.

    Args:
        verts_or_result: ``(V, 3)`` float tensor, or an object with ``.verts``
            ``(V, 3)`` and ``.faces`` attributes (e.g. :class:`Mesh`, a marching
            cubes result).
        faces: ``(F, K)`` long padded with ``-1`` (``K = 3`` for triangles), or a
            list of index lists; must be ``None`` when a result object is given.
        process: passed to ``trimesh.Trimesh`` (merge vertices etc. when ``True``).

    Returns:
        ``trimesh.Trimesh`` with ``V`` vertices and ``sum(size_f - 2)`` triangles.

    Example:
        >>> v = torch.tensor([[0., 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
        >>> tm = to_trimesh(v, torch.tensor([[0, 1, 2, 3]]))
        >>> tm.faces.tolist(), float(tm.area)
        ([[0, 1, 2], [0, 2, 3]], 1.0)
    """
    import trimesh

    if faces is None:
        if not (hasattr(verts_or_result, "verts") and hasattr(verts_or_result, "faces")):
            raise TypeError(
                "to_trimesh: expected (verts, faces) tensors or an object with .verts and "
                f".faces, got {type(verts_or_result).__name__} and faces=None"
            )
        verts, faces = verts_or_result.verts, verts_or_result.faces
    else:
        verts = verts_or_result
    verts, faces_fk = _mesh_arrays(verts, faces)
    tris_t3 = triangulate_faces(faces_fk) if faces_fk.shape[0] else faces_fk.new_zeros(0, 3)
    return trimesh.Trimesh(
        vertices=verts.detach().cpu().numpy(), faces=tris_t3.numpy(), process=process
    )
