"""Padded polygon faces: conversion, validation, sizes and fan triangulation.

Convention:
    - A polygon mesh stores its faces as one ``(F, K)`` long tensor, ``K`` the
      largest face size; a face of ``n < K`` vertices fills its first ``n``
      entries and pads the rest with ``-1``. Padding is trailing only.
    - Indices are 0-based into the ``(V, 3)`` vertex tensor.
    - Face winding is counter-clockwise seen from outside (outward normals),
      as in trimesh and OBJ files.
    - As input, every function also accepts a list of index lists (ragged).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape, check_tensor

__all__ = [
    "pad_faces", "face_sizes", "check_faces", "check_mesh", "triangulate_faces", "unpad_faces"
]


def pad_faces(
    faces: torch.Tensor | Sequence[Sequence[int]] | np.ndarray,
    device: torch.device | str | None = None,
) -> torch.Tensor:
    """Turn faces given as a tensor, an array or a list of index lists into ``(F, K)`` long.

    Convention:
        Padding with ``-1`` is trailing (see the module docstring).

    Args:
        faces: ``(F, K)`` integer tensor/array padded with ``-1``, or a list of
            ``F`` index lists of any lengths.
        device: device of the result; ``None`` keeps a tensor's device (CPU for lists).

    Returns:
        ``(F, K)`` long tensor, ``K`` the longest face (``K = 0`` when ``F = 0``).

    Raises:
        TypeError: the faces are not integers.
        ShapeError: a tensor/array is not 2-D.

    Example:
        >>> pad_faces([[0, 1, 2, 3], [1, 4, 2]])
        tensor([[ 0,  1,  2,  3],
                [ 1,  4,  2, -1]])
    """
    if isinstance(faces, torch.Tensor) or isinstance(faces, np.ndarray):
        if isinstance(faces, np.ndarray) and faces.dtype != object:
            faces = torch.from_numpy(np.ascontiguousarray(faces))
        if isinstance(faces, torch.Tensor):
            if faces.is_floating_point() or faces.is_complex() or faces.dtype == torch.bool:
                raise TypeError(f"faces: expected an integer tensor, got dtype {faces.dtype}")
            check_shape(faces, ["F", "K"], "faces")
            return faces.to(device=device if device is not None else faces.device,
                            dtype=torch.long)
        faces = list(faces)  # numpy object array of per-face arrays
    faces = list(faces)
    if len(faces) == 0:
        return torch.zeros(0, 0, dtype=torch.long, device=device)
    lengths_f = np.fromiter(map(len, faces), dtype=np.int64, count=len(faces))
    flat = np.asarray(list(itertools.chain.from_iterable(faces)))
    if flat.size == 0:
        flat = flat.astype(np.int64)
    if flat.size and not np.issubdtype(flat.dtype, np.integer):
        raise TypeError(f"faces: expected integer indices, got {flat.dtype}")
    width = int(lengths_f.max())
    padded_fk = np.full((len(faces), width), -1, dtype=np.int64)
    cols = np.arange(width)[None, :] < lengths_f[:, None]
    padded_fk[cols] = flat
    return torch.from_numpy(padded_fk).to(device)


def face_sizes(faces: torch.Tensor) -> torch.Tensor:
    """Number of vertices of each padded face.

    Args:
        faces: ``(F, K)`` long, padded with ``-1``.

    Returns:
        ``(F,)`` long.

    Example:
        >>> face_sizes(torch.tensor([[0, 1, 2, 3], [1, 4, 2, -1]]))
        tensor([4, 3])
    """
    check_shape(faces, ["F", "K"], "faces")
    return (faces >= 0).sum(dim=1)


def check_faces(
    faces: torch.Tensor | Sequence[Sequence[int]],
    num_vertices: int,
    name: str = "faces",
    allow_duplicates: bool = False,
    allow_degenerate: bool = False,
) -> torch.Tensor:
    """Validate polygon faces and return them padded; errors name the offending face.

    Checks: integer ``(F, K)``; padding only trailing; indices in
    ``[0, num_vertices)``; at least 3 vertices per face, all distinct; and (unless
    ``allow_duplicates``) no face repeated, where two faces are the same if they
    use the same vertex set, in any order or orientation. ``allow_degenerate``
    skips the distinct-vertex checks (I/O accepts collapsed faces).

    Args:
        faces: ``(F, K)`` long padded with ``-1``, or a list of index lists.
        num_vertices: ``V``, the number of vertices.
        name: argument name for the messages.
        allow_duplicates: skip the repeated-face check.
        allow_degenerate: skip the "3 distinct vertices" and "repeats a vertex" checks.

    Returns:
        ``(F, K)`` long tensor.

    Raises:
        ValueError: one of the checks fails (the message gives the face index).

    Example:
        >>> check_faces([[0, 1, 2], [0, 2, 3]], 4)
        tensor([[0, 1, 2],
                [0, 2, 3]])
        >>> check_faces([[0, 1, 2], [0, 2, 4]], 4)
        Traceback (most recent call last):
        ...
        ValueError: faces: face 1 has index 4, out of range [0, 4)
    """
    faces_fk = pad_faces(faces)
    if isinstance(num_vertices, bool) or not isinstance(num_vertices, (int, np.integer)):
        raise TypeError(f"num_vertices: expected an int, got {type(num_vertices).__name__}")
    if num_vertices < 0:
        raise ValueError(f"num_vertices: expected >= 0, got {num_vertices}")
    F, K = faces_fk.shape
    if F == 0:
        return faces_fk
    if K < 3:
        raise ShapeError(f"{name}: expected at least 3 columns (F, K>=3), got ({F}, {K})")

    def first(bad_f: torch.Tensor) -> int | None:
        idx = torch.nonzero(bad_f).flatten()
        return int(idx[0]) if idx.numel() else None

    valid_fk = faces_fk >= 0
    bad = first((faces_fk < -1).any(dim=1) | (faces_fk >= num_vertices).any(dim=1))
    if bad is not None:
        row = faces_fk[bad]
        wrong = row[(row < -1) | (row >= num_vertices)][0]
        raise ValueError(
            f"{name}: face {bad} has index {int(wrong)}, out of range [0, {num_vertices})"
        )
    # trailing padding: once invalid, stays invalid
    bad = first((valid_fk[:, 1:] & ~valid_fk[:, :-1]).any(dim=1))
    if bad is not None:
        raise ValueError(
            f"{name}: face {bad} has -1 padding before a vertex index "
            f"({faces_fk[bad].tolist()}); padding must be trailing"
        )
    if allow_degenerate and allow_duplicates:
        return faces_fk
    big = torch.iinfo(torch.long).max
    sorted_fk = torch.where(valid_fk, faces_fk, big).sort(dim=1).values
    distinct_f = 1 + ((sorted_fk[:, 1:] != sorted_fk[:, :-1]) & (sorted_fk[:, 1:] != big)).sum(1)
    bad = None if allow_degenerate else first(distinct_f < 3)
    if bad is not None:
        raise ValueError(
            f"{name}: face {bad} has fewer than 3 distinct vertices ({faces_fk[bad].tolist()})"
        )
    bad = None if allow_degenerate else first(distinct_f < valid_fk.sum(1))
    if bad is not None:
        raise ValueError(f"{name}: face {bad} repeats a vertex ({faces_fk[bad].tolist()})")
    if not allow_duplicates:
        # lexicographic order of the sorted rows: stable sorts, last column first
        order_f = torch.arange(F, device=faces_fk.device)
        for k in range(K - 1, -1, -1):  # loop over polygon degree, not faces
            order_f = order_f[torch.sort(sorted_fk[order_f, k], stable=True).indices]
        rows_fk = sorted_fk[order_f]
        same_f = (rows_fk[1:] == rows_fk[:-1]).all(dim=1)
        bad = first(same_f)
        if bad is not None:
            # stable sorts keep the earlier face first among equal rows
            later, earlier = int(order_f[bad + 1]), int(order_f[bad])
            raise ValueError(
                f"{name}: face {later} repeats face {earlier} (same vertices "
                f"{faces_fk[later][valid_fk[later]].tolist()})"
            )
    return faces_fk


def triangulate_faces(faces: torch.Tensor | Sequence[Sequence[int]]) -> torch.Tensor:
    """Fan-triangulate padded polygons: ``(v0, v1, v2, ..., vn-1)`` -> ``(v0, vk, vk+1)``.

    Convention:
        Triangles keep the polygon's winding; the triangles of face ``f`` come
        before those of face ``f + 1``, in fan order. Exact for convex polygons.

    Args:
        faces: ``(F, K)`` long padded with ``-1``, or a list of index lists.

    Returns:
        ``(T, 3)`` long, ``T = sum(size_f - 2)``.

    Example:
        >>> triangulate_faces([[0, 1, 2, 3], [1, 4, 2]])
        tensor([[0, 1, 2],
                [0, 2, 3],
                [1, 4, 2]])
    """
    faces_fk = pad_faces(faces)
    F, K = faces_fk.shape
    if K <= 3:
        return faces_fk[(faces_fk >= 0).all(dim=1)] if K == 3 else faces_fk.new_zeros(0, 3)
    apex_fk = faces_fk[:, :1].expand(F, K - 2)
    tris_fk3 = torch.stack([apex_fk, faces_fk[:, 1:-1], faces_fk[:, 2:]], dim=-1)
    keep_fk = tris_fk3[..., 2] >= 0
    return tris_fk3[keep_fk]


def check_mesh(
    verts: torch.Tensor,
    faces: torch.Tensor | Sequence[Sequence[int]],
    finite: bool = False,
) -> torch.Tensor:
    """Validate a mesh for queries on its triangles; return the triangles ``(T, 3)`` long.

    The one mesh validator of the distance queries, samplers and the command line: the
    vertices are checked here, the faces by :func:`check_faces` (repeated and collapsed
    faces allowed: they are harmless to distances), and polygons are fan-triangulated
    with :func:`triangulate_faces`, so face ids of the queries index those triangles.

    Convention:
        Faces as in the module docstring; the triangles keep the polygons' winding.

    Args:
        verts: ``(*, V, 3)`` float vertex positions.
        faces: ``(F, K)`` integer (tensor, array or list of index lists), ``K >= 3``,
            padded with ``-1``.
        finite: also require finite vertex coordinates.

    Returns:
        ``(T, 3)`` long triangles on the device of ``verts``.

    Raises:
        TypeError: float vertices expected, integer faces expected.
        ShapeError: ``verts`` not ``(*, V, 3)``, or fewer than 3 face columns.
        ValueError: an empty mesh, indices out of range, misplaced padding, or (with
            ``finite``) NaN or inf coordinates.

    Example:
        >>> check_mesh(torch.zeros(4, 3), torch.tensor([[0, 1, 2, 3]]))
        tensor([[0, 1, 2],
                [0, 2, 3]])
        >>> check_mesh(torch.zeros(3, 3), [[0, 1, 3]])
        Traceback (most recent call last):
        ...
        ValueError: faces: expected indices in [0, 2], got range [0, 3]
    """
    check_float(verts, "verts")
    check_shape(verts, ["*", "V", "3"], "verts")
    faces_fk = pad_faces(faces)
    num_vertices, (F, K) = verts.shape[-2], faces_fk.shape
    if F and K < 3:
        raise ShapeError(f"faces: expected shape (F, K) with K >= 3 vertices per face, got "
                         f"{(F, K)}")
    if num_vertices == 0 or F == 0:
        raise ValueError(f"mesh: expected a non-empty mesh, got {num_vertices} vertices "
                         f"and {F} faces")
    used = faces_fk[faces_fk >= 0] if K > 3 else faces_fk
    lo, hi = int(faces_fk[:, :3].min()), int(used.max())
    if lo < 0 or hi >= num_vertices:
        raise ValueError(f"faces: expected indices in [0, {num_vertices - 1}], got range "
                         f"[{lo}, {hi}]")
    faces_fk = check_faces(faces_fk, num_vertices, "faces", allow_duplicates=True,
                           allow_degenerate=True)
    if finite and not bool(torch.isfinite(verts).all()):
        raise ValueError("verts: expected finite coordinates, got NaN or inf")
    tris = triangulate_faces(faces_fk) if K > 3 else faces_fk
    return tris.to(verts.device)


def unpad_faces(faces: torch.Tensor) -> list[list[int]]:
    """Padded ``(F, K)`` faces back to a list of ``F`` index lists (for export/printing).

    Args:
        faces: ``(F, K)`` long padded with ``-1``.

    Returns:
        A list of ``F`` lists of ints.

    Example:
        >>> unpad_faces(torch.tensor([[0, 1, 2, 3], [1, 4, 2, -1]]))
        [[0, 1, 2, 3], [1, 4, 2]]
    """
    check_tensor(faces, "faces")
    check_shape(faces, ["F", "K"], "faces")
    ends = face_sizes(faces).cumsum(0)[:-1].cpu().numpy()
    return [part.tolist() for part in np.split(faces[faces >= 0].cpu().numpy(), ends)]
