"""Polygon mesh I/O (OBJ, PLY, OFF) with UVs and subdivision tags, and trimesh interop.

Convention:
    - A mesh is ``Mesh(verts, faces, uvs, uv_faces, tags, options)``: ``verts``
      ``(V, 3)`` float, ``faces`` ``(F, K)`` long padded with ``-1`` (see
      :mod:`torchgeo_cg.mesh.faces`); ``uvs`` ``(T, 2)`` and ``uv_faces`` ``(F, K)``
      (same padding as ``faces``; ``-1`` on every corner of a face without texture
      indices) are the OBJ texture coordinates, ``tags`` the
      OpenSubdiv ``t`` tags (:class:`~torchgeo_cg.mesh.SubdivisionTags`) and
      ``options`` the scheme options they set (``{"boundary": "edge_only", ...}``,
      see :mod:`torchgeo_cg.mesh.io._obj_tags`).
    - Indices are 0-based in memory; OBJ files are 1-based (negative OBJ indices,
      relative to the last vertex read, are resolved); tag indices are 0-based.
    - Faces keep their order and winding (counter-clockwise seen from outside);
      vertices keep their file order. Nothing is merged, removed or re-ordered.
    - Every malformed file raises ``ValueError("<file>, line <n>: ...")`` (binary
      PLY: ``"<file>: element 'face' record <i>: ..."``); nothing is read silently
      wrong. Faces need at least 3 vertices, on load and on save.
    - What real exporters write outside the format but cannot change positions or
      faces (an unknown OBJ statement, non-UTF-8 bytes in an OBJ comment or name,
      non-ASCII bytes in a PLY ``comment``/``obj_info`` line) is skipped with one
      :class:`~torchgeo_cg.mesh.io.MeshFileWarning` (a ``UserWarning``) per
      file, naming the file, the first line skipped and how many were.
    - trimesh holds triangles only: :func:`to_trimesh` fan-triangulates polygons.
"""

from __future__ import annotations

import os
import warnings
from typing import Any, NamedTuple

import numpy as np
import torch

from torchgeo_cg.core.check import check_float, check_shape, check_tensor
from torchgeo_cg.core.numerics import cast_back
from torchgeo_cg.mesh.faces import check_faces, pad_faces, triangulate_faces
from torchgeo_cg.mesh.io._obj import ObjContent, format_obj, read_obj
from torchgeo_cg.mesh.io._obj_tags import ObjTags, check_tags
from torchgeo_cg.mesh.io._off import format_off, read_off
from torchgeo_cg.mesh.io._ply import format_ply, read_ply
from torchgeo_cg.mesh.io._text import MeshFileWarning
from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags
from torchgeo_cg.mesh.subdivision.tags import check_tags as check_tensor_tags

__all__ = ["Mesh", "MeshFileWarning", "load_mesh", "save_mesh", "from_trimesh", "to_trimesh"]


class Mesh(NamedTuple):
    """A polygon mesh, with optional texture coordinates and subdivision tags.

    Attributes:
        verts: ``(V, 3)`` float vertex positions.
        faces: ``(F, K)`` long vertex indices, padded with ``-1``.
        uvs: ``(T, 2)`` float texture coordinates, or ``None``.
        uv_faces: ``(F, K)`` long indices into ``uvs``, padded like ``faces``, or ``None``.
            A face without texture coordinates has ``-1`` on every corner (an OBJ
            whose objects do not all have UVs); tell it from padding by ``faces``,
            which is ``-1`` only where it pads.
        tags: :class:`~torchgeo_cg.mesh.SubdivisionTags`, or ``None``.
        options: ``dict`` of subdivision scheme options, or ``None``.

    The last four default to ``None``, so ``Mesh(verts, faces)`` still works.

    Example:
        >>> m = Mesh(torch.zeros(4, 3), torch.tensor([[0, 1, 2, 3]]))
        >>> m.verts.shape, m.faces.shape, m.uvs
        (torch.Size([4, 3]), torch.Size([1, 4]), None)
    """

    verts: torch.Tensor
    faces: torch.Tensor
    uvs: torch.Tensor | None = None
    uv_faces: torch.Tensor | None = None
    tags: SubdivisionTags | None = None
    options: dict | None = None


def _resolve_dtype(dtype: torch.dtype | None) -> torch.dtype:
    """``dtype`` (default: ``torch.get_default_dtype()``), a floating-point dtype."""
    dtype = torch.get_default_dtype() if dtype is None else dtype
    if not isinstance(dtype, torch.dtype) or not dtype.is_floating_point:
        raise TypeError(f"dtype: expected a floating-point dtype for verts, got {dtype}")
    return dtype


def _numpy(x: torch.Tensor) -> np.ndarray:
    """``x`` detached on the CPU as numpy; bfloat16 (which numpy lacks) as float32, exactly."""
    x = x.detach().cpu()
    return (x.float() if x.dtype == torch.bfloat16 else x).numpy()


def _digits(x: torch.Tensor | None) -> int:
    """Significant digits that write ``x``'s dtype exactly: 17 (float64) or 9 (float32 and
    the half types, which float32 holds)."""
    return 17 if x is not None and x.dtype == torch.float64 else 9


def _suffix(path) -> str:
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    if suffix not in (".obj", ".ply", ".off"):
        raise ValueError(f"path: expected a .obj, .ply or .off suffix, got {suffix!r}")
    return suffix


def _check_min_degree(faces_fk: torch.Tensor, name: str = "faces") -> None:
    sizes_f = (faces_fk >= 0).sum(1)
    small = torch.nonzero(sizes_f < 3).flatten()
    if small.numel():
        f = int(small[0])
        raise ValueError(f"{name}: face {f} has {int(sizes_f[f])} vertices; a face needs at "
                         "least 3")


def _mesh_arrays(verts: torch.Tensor, faces) -> tuple[torch.Tensor, torch.Tensor]:
    check_tensor(verts, "verts")
    check_shape(verts, ["V", "3"], "verts")
    check_float(verts, "verts")
    faces_fk = pad_faces(faces)
    if isinstance(faces, torch.Tensor) and faces.device != verts.device:
        raise ValueError(
            f"verts and faces must be on the same device, got {verts.device} and {faces.device}"
        )
    faces_fk = faces_fk.cpu()
    if faces_fk.shape[0]:
        _check_min_degree(faces_fk)
    faces_fk = check_faces(faces_fk, verts.shape[0], allow_duplicates=True, allow_degenerate=True)
    return verts, faces_fk


def _uv_arrays(uvs, uv_faces, faces_fk: torch.Tensor):
    """Checked numpy ``(T, 2)`` uvs and ``(F, K)`` uv faces (same padding as faces)."""
    if uvs is None and uv_faces is None:
        return None, None
    if uvs is None:
        raise ValueError("uvs: uv_faces were given without uvs")
    check_tensor(uvs, "uvs")
    check_shape(uvs, ["T", "2"], "uvs")
    check_float(uvs, "uvs")
    uvs_np = _numpy(uvs)
    if uv_faces is None:
        return uvs_np, None
    uv_fk = pad_faces(uv_faces).cpu()
    width = faces_fk.shape[1]
    if uv_fk.shape[1] < width:
        uv_fk = torch.cat([uv_fk, uv_fk.new_full((uv_fk.shape[0], width - uv_fk.shape[1]), -1)], 1)
    same = uv_fk.shape[0] == faces_fk.shape[0] and not (uv_fk[:, width:] >= 0).any()
    if same:
        uv_fk = uv_fk[:, :width]
        used_fk, has_f = uv_fk >= 0, (uv_fk >= 0).any(1)
        same = not (used_fk & (faces_fk < 0)).any()
    if not same:
        raise ValueError(f"uv_faces: expected the padding of faces {tuple(faces_fk.shape)}, "
                         f"got shape {tuple(uv_fk.shape)} with other face sizes")
    part = torch.nonzero(has_f & (used_fk != (faces_fk >= 0)).any(1)).flatten()
    if part.numel():
        f = int(part[0])
        raise ValueError(f"uv_faces: face {f} has texture indices on some corners only "
                         f"({uv_fk[f].tolist()}); give every corner one, or -1 on every corner")
    uv_fk = check_faces(uv_fk, uvs.shape[0], name="uv_faces",
                        allow_duplicates=True, allow_degenerate=True)
    return uvs_np, uv_fk.numpy()


def _tag_arrays(tags: SubdivisionTags | None, options: dict | None, num_vertices: int,
                faces_fk: np.ndarray) -> ObjTags:
    """Checked numpy tags for writing."""
    if tags is None:
        return ObjTags.empty()._replace(options=dict(options or {}))
    if not isinstance(tags, SubdivisionTags):
        raise TypeError(f"tags: expected a SubdivisionTags, got {type(tags).__name__}")
    creases, crease_s, corners, corner_s, holes = (_numpy(t) for t in check_tensor_tags(tags))
    out = ObjTags(creases.reshape(-1, 2).astype(np.int64), crease_s.astype(np.float64),
                  corners.reshape(-1).astype(np.int64), corner_s.astype(np.float64),
                  holes.reshape(-1).astype(np.int64), dict(options or {}))
    check_tags(out, num_vertices, faces_fk)  # write only what load_mesh reads back
    return out


def save_mesh(
    path: str | os.PathLike,
    verts: torch.Tensor | Mesh,
    faces=None,
    binary: bool = True,
    *,
    uvs: torch.Tensor | None = None,
    uv_faces=None,
    tags: SubdivisionTags | None = None,
    options: dict | None = None,
) -> None:
    """Write a polygon mesh to ``.obj``, ``.ply`` or ``.off``, keeping polygons of any size.

    Convention:
        See the module docstring; OBJ indices are written 1-based, with ``v/vt``
        corners when ``uv_faces`` is given and OpenSubdiv ``t`` lines for ``tags``
        and ``options``. Numbers are written with 17 (float64) or 9 significant
        digits, so they read back exactly. PLY is written binary little-endian
        (``binary=False``: ASCII), with ``float``/``double`` ``x, y, z`` following
        ``verts.dtype`` and ``list uchar int vertex_indices``; OFF is ASCII. PLY and
        OFF hold no UVs or tags.

    Args:
        path: destination; the suffix (``.obj``, ``.ply``, ``.off``, any case) picks the
            format.
        verts: ``(V, 3)`` float (detached and moved to the CPU for writing), or a
            :class:`Mesh` (then ``faces`` and the keyword arguments come from it).
        faces: ``(F, K)`` long padded with ``-1``, or a list of index lists; every face
            has at least 3 vertices.
        binary: PLY only; ignored for OBJ.
        uvs: ``(T, 2)`` float texture coordinates (OBJ).
        uv_faces: ``(F, K)`` long indices into ``uvs``, padded like ``faces`` (OBJ);
            ``-1`` on every corner of a face without texture coordinates.
        tags: :class:`~torchgeo_cg.mesh.SubdivisionTags` (OBJ).
        options: scheme options, e.g. ``{"boundary": "edge_only"}`` (OBJ).

    Raises:
        ValueError: unknown suffix, faces of fewer than 3 vertices, indices out of
            range, a face with texture indices on some corners only, or UVs/tags for a
            PLY or OFF file.

    Example:
        >>> import tempfile, os
        >>> d = tempfile.mkdtemp()
        >>> v = torch.tensor([[0., 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]])
        >>> save_mesh(os.path.join(d, "m.obj"), v, [[0, 1, 2, 3], [1, 4, 2]])
        >>> print(open(os.path.join(d, "m.obj")).read().splitlines()[-2:])
        ['f 1 2 3 4', 'f 2 5 3']
    """
    if isinstance(verts, Mesh) and faces is None:
        mesh = verts
        verts, faces = mesh.verts, mesh.faces
        uvs = mesh.uvs if uvs is None else uvs
        uv_faces = mesh.uv_faces if uv_faces is None else uv_faces
        tags = mesh.tags if tags is None else tags
        options = mesh.options if options is None else options
    if faces is None:
        raise TypeError("save_mesh: faces are required unless verts is a Mesh")
    suffix = _suffix(path)
    verts, faces_fk = _mesh_arrays(verts, faces)
    verts_v3 = _numpy(verts)
    precision = _digits(verts)
    if suffix != ".obj" and (uvs is not None or uv_faces is not None or options or (
            tags is not None and any(t.numel() for t in tags))):
        raise ValueError(f"path: {suffix[1:].upper()} holds no uvs, uv_faces, tags or options; "
                         "save as .obj")
    if suffix == ".off":
        with open(path, "w", encoding="ascii", newline="\n") as fh:
            fh.write(format_off(verts_v3, faces_fk.numpy(), precision))
        return
    if suffix == ".ply":
        if faces_fk.shape[1] > 255:
            raise ValueError(
                f"faces: PLY stores at most 255 vertices per face, got {faces_fk.shape[1]}")
        with open(path, "wb") as fh:
            fh.write(format_ply(verts_v3, faces_fk.numpy(), binary, precision))
        return
    uvs_np, uv_np = _uv_arrays(uvs, uv_faces, faces_fk)
    tag_np = _tag_arrays(tags, options, len(verts_v3), faces_fk.numpy())
    content = ObjContent(verts_v3, faces_fk.numpy(), uvs_np, uv_np, tag_np)
    text = format_obj(content, precision, uv_precision=_digits(uvs),
                      tag_precision=_digits(None if tags is None else tags.crease_sharpness))
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)


def load_mesh(
    path: str | os.PathLike,
    dtype: torch.dtype | None = None,
    device: torch.device | str | None = None,
) -> Mesh:
    """Read an ``.obj``, ``.ply`` or ``.off`` polygon mesh, with its UVs and subdivision tags.

    Convention:
        See the module docstring and :mod:`torchgeo_cg.mesh.io._obj`
        (statements, ``vt``, negative indices, ``\\`` continuations, comments),
        :mod:`torchgeo_cg.mesh.io._obj_tags` (OpenSubdiv ``t`` tags) and
        :mod:`torchgeo_cg.mesh.io._ply` (header checks, ASCII and binary) and
        :mod:`torchgeo_cg.mesh.io._off`. A BOM and
        CRLF line ends are accepted. No vertex is merged or dropped. What cannot
        change positions or faces but the format does not allow is skipped with
        one warning (module docstring).

    Args:
        path: an ``.obj``, ``.ply`` or ``.off`` file.
        dtype: floating dtype of ``verts``, ``uvs`` and the tag sharpness (default:
            ``torch.get_default_dtype()``); float16/bfloat16 saturate at their largest
            finite value (never ``inf`` for a finite number in the file).
        device: device of every tensor (default: CPU).

    Returns:
        :class:`Mesh`: ``verts`` ``(V, 3)``, ``faces`` ``(F, K)`` padded with ``-1``;
        ``uvs`` ``(T, 2)`` when the OBJ has ``vt`` lines and ``uv_faces`` ``(F, K)``
        when its faces use them (else ``None``; ``-1`` on every corner of a face
        without them, e.g. ``f 1//1 2//1 3//1``); ``tags`` (empty without ``t``
        lines, and for PLY/OFF) and ``options`` (``{}`` without option tags).

    Raises:
        ValueError: unknown suffix, or a malformed file (naming the file and line).

    Warns:
        MeshFileWarning: (a ``UserWarning``) once per file, when lines were skipped.

    Example:
        >>> import tempfile, os
        >>> path = os.path.join(tempfile.mkdtemp(), "m.obj")
        >>> with open(path, "w") as fh:
        ...     _ = fh.write("v 0 0 0\\nv 1 0 0\\nv 1 1 0\\nv 0 1 0\\nv 2 0 0\\nvt 0 0\\n"
        ...                  "f 1/1 2/1 3/1 4/1\\nf -4/1 -1/1 -3/1\\nt crease 2/1/0 0 1 2.5\\n")
        >>> m = load_mesh(path)
        >>> m.faces
        tensor([[ 0,  1,  2,  3],
                [ 1,  4,  2, -1]])
        >>> m.uv_faces.shape, m.tags.creases.tolist(), m.tags.crease_sharpness.tolist()
        (torch.Size([2, 4]), [[0, 1]], [2.5])
    """
    suffix = _suffix(path)
    with open(path, "rb") as fh:
        data = fh.read()
    name = os.fspath(path)
    dtype = _resolve_dtype(dtype)
    if suffix == ".ply":
        verts_v3, faces_fk, skipped = read_ply(data, name)
        content = ObjContent(verts_v3, faces_fk, None, None, ObjTags.empty(), skipped)
    elif suffix == ".off":
        content = ObjContent(*read_off(data, name), None, None, ObjTags.empty())
    else:
        content = read_obj(data, name)
    if content.skipped:
        warnings.warn(content.skipped, MeshFileWarning, stacklevel=2)

    def real(a):  # saturating: a value beyond a half type's range reads as its largest
        return None if a is None else cast_back(torch.from_numpy(a), dtype).to(device)

    def index(a):
        return None if a is None else torch.from_numpy(a).to(device=device)

    t = content.tags
    tags = SubdivisionTags(index(t.creases), real(t.crease_sharpness), index(t.corners),
                           real(t.corner_sharpness), index(t.holes))
    return Mesh(real(content.verts_v3), index(content.faces_fk), real(content.uvs_t2),
                index(content.uv_faces_fk), tags, dict(t.options))


def from_trimesh(
    mesh: Any, dtype: torch.dtype | None = None, device: torch.device | str | None = None
) -> Mesh:
    """Convert a ``trimesh.Trimesh`` to a :class:`Mesh` (triangles, same order).

    Args:
        mesh: a ``trimesh.Trimesh`` (anything with ``.vertices`` ``(V, 3)`` and
            ``.faces`` ``(F, 3)``).
        dtype: floating dtype of ``verts`` (default: ``torch.get_default_dtype()``);
            float16/bfloat16 saturate at their largest finite value.
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
    return Mesh(cast_back(verts, _resolve_dtype(dtype)).to(device), faces.to(device))


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
        vertices=_numpy(verts), faces=tris_t3.numpy(), process=process
    )
