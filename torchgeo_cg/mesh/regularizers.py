"""Mesh regularizers for fitting: Laplacian smoothing, normal consistency, edge length.

All three take ``verts (*, V, 3)`` sharing one topology ``faces (F, K)`` (triangles, or
polygons padded with ``-1`` as in :mod:`torchgeo_cg.mesh.faces`) and return one loss per
mesh ``(*,)``. The connectivity (edges, adjacent face pairs) is built under
``torch.no_grad()`` with sort and unique; the losses are differentiable w.r.t. ``verts``.

Convention:
    - The edges of a polygon are its sides ``(f_i, f_{i+1 mod n})``; diagonals are not
      edges. Each undirected edge counts once.
    - Where a formula needs triangles (cotangent weights) polygons are fan-triangulated
      with :func:`~torchgeo_cg.mesh.faces.triangulate_faces` (``(v0, vk, vk+1)``), so the
      fan diagonals get cotangent weights too.
    - Face normals are vector areas ``1/2 sum_k v_k x v_{k+1}`` (Newell), which is the
      usual cross product for triangles; faces are wound counter-clockwise seen from
      outside.
    - Vertices used by no face are ignored.
    - float16/bfloat16 vertices are computed in float32 and the result is returned in
      the input dtype. NaN in a vertex gives NaN in every result it touches.

Scale (multiplying ``verts`` by ``s``): the Laplacian losses scale as ``s``, the
normal consistency is invariant, the edge-length loss scales as ``s^2`` (with
``target`` scaled by ``s``). No threshold is absolute: the scale-invariant parts
(cotangent weights, normal directions) are computed on the vertices multiplied by a
power of two per mesh (exact), and lengths are overflow-safe norms, so every finite
mesh gives finite results.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_broadcastable, check_choice, check_float, check_shape
from torchgeo_cg.core.coerce import as_tensor_like
from torchgeo_cg.core.numerics import cast_back, power_of_two_scale, safe_norm, working_dtype
from torchgeo_cg.mesh.faces import check_faces, pad_faces, triangulate_faces

__all__ = [
    "MeshEdges",
    "mesh_edges",
    "mesh_laplacian",
    "laplacian_smoothing_loss",
    "normal_consistency_loss",
    "edge_length_loss",
]

_METHODS = ("uniform", "cotangent")


class MeshEdges(NamedTuple):
    """Undirected edges of a polygon mesh.

    Attributes:
        edges: ``(E, 2)`` long, ``edges[:, 0] < edges[:, 1]``, sorted.
        face_pairs: ``(P, 2)`` long, pairs of faces sharing an edge (consecutive faces in
            index order when more than two share one).
    """

    edges: torch.Tensor
    face_pairs: torch.Tensor


def _check(verts: torch.Tensor, faces) -> torch.Tensor:
    check_float(verts, "verts")
    check_shape(verts, ["*", "V", "3"], "verts")
    return check_faces(faces, verts.shape[-2], "faces", allow_duplicates=True)


def _unit_scaled(verts: torch.Tensor) -> torch.Tensor:
    """``verts`` times a power of two per mesh (exact) making the largest coordinate
    ``[0.5, 1)``: products of coordinates then neither overflow nor underflow, and
    scale-invariant quantities are unchanged. NaN/inf/zero meshes are left as they are."""
    if verts.shape[-2] == 0:
        return verts
    big = verts.detach().abs().flatten(-2).amax(-1)[..., None, None]  # (*, 1, 1)
    return verts / power_of_two_scale(big)


def mesh_edges(faces: torch.Tensor) -> MeshEdges:
    """Unique undirected edges and adjacent face pairs of padded polygon faces.

    Args:
        faces: ``(F, K)`` long padded with ``-1``, or a list of index lists (each face
            of at least 3 distinct vertices).

    Returns:
        :class:`MeshEdges` ``(edges (E, 2), face_pairs (P, 2))``.

    Raises:
        TypeError: the faces are not integers. ShapeError: a tensor that is not 2-D.
        ValueError: a negative index (other than trailing padding) or a face of fewer
            than 3 vertices.

    Example:
        >>> mesh_edges(torch.tensor([[0, 1, 2, 3], [1, 4, 2, -1]]))
        MeshEdges(edges=tensor([[0, 1],
                [0, 3],
                [1, 2],
                [1, 4],
                [2, 3],
                [2, 4]]), face_pairs=tensor([[0, 1]]))
    """
    faces = pad_faces(faces)
    faces = check_faces(faces, int(faces.max()) + 1 if faces.numel() else 0, "faces",
                        allow_duplicates=True)
    F, K = faces.shape
    with torch.no_grad():
        size_f = (faces >= 0).sum(1)
        col = torch.arange(K, device=faces.device)
        nxt_fk = torch.remainder(col[None, :] + 1, size_f.clamp_min(1)[:, None])
        valid_fk = col[None, :] < size_f[:, None]
        a_fk, b_fk = faces, faces.gather(1, nxt_fk)
        lo, hi = torch.minimum(a_fk, b_fk)[valid_fk], torch.maximum(a_fk, b_fk)[valid_fk]
        face_e = torch.arange(F, device=faces.device)[:, None].expand(F, K)[valid_fk]
        key = lo * (int(faces.max()) + 1 if faces.numel() else 1) + hi
        key, order = torch.sort(key, stable=True)
        first = torch.ones_like(key, dtype=torch.bool)
        first[1:] = key[1:] != key[:-1]
        edges = torch.stack([lo[order][first], hi[order][first]], -1)
        same = ~first[1:]
        face_sorted = face_e[order]
        pairs = torch.stack([face_sorted[:-1][same], face_sorted[1:][same]], -1)
    return MeshEdges(edges, pairs.reshape(-1, 2))


def _cotangent_weights(verts: torch.Tensor, faces: torch.Tensor):
    """Edges ``(E2, 2)`` (directed pairs, both ways) and weights ``(*, E2)``.

    ``w_ij = cot(alpha_ij) + cot(beta_ij)`` over the triangles of the fan triangulation,
    ``alpha, beta`` the angles opposite edge ``ij``; one triangle on boundary edges.
    """
    tris = triangulate_faces(faces)  # (T, 3)
    corners = _unit_scaled(verts)[..., tris, :]  # (*, T, 3, 3), cotangents are unitless
    cots = []
    for k in range(3):  # the angle at corner k is opposite edge (k+1, k+2)
        a = corners[..., (k + 1) % 3, :] - corners[..., k, :]
        b = corners[..., (k + 2) % 3, :] - corners[..., k, :]
        sin = safe_norm(torch.linalg.cross(a, b))
        dot = (a * b).sum(-1)
        # cot = cos / sin; a degenerate triangle (sin exactly 0) contributes nothing; NaN
        # stays NaN
        zero = sin == 0
        cots.append(torch.where(zero, 0.0, dot / torch.where(zero, 1.0, sin)))
    cot_tk = torch.stack(cots, -1)  # (*, T, 3)
    i = tris[:, [1, 2, 0]]  # edge opposite corner k: (k+1, k+2)
    j = tris[:, [2, 0, 1]]
    src = torch.cat([i.reshape(-1), j.reshape(-1)])
    dst = torch.cat([j.reshape(-1), i.reshape(-1)])
    w = cot_tk.flatten(-2)
    return src, dst, torch.cat([w, w], -1)


def mesh_laplacian(verts: torch.Tensor, faces, method: str = "uniform") -> torch.Tensor:
    """Laplacian vectors ``(*, V, 3)`` of every vertex.

    Formulas:
        - uniform: ``L x_i = (1 / |N(i)|) sum_{j in N(i)} x_j - x_i``, ``N(i)`` the
          edge neighbours of ``i``;
        - cotangent: ``L x_i = sum_j w_ij (x_j - x_i) / sum_j w_ij`` with
          ``w_ij = cot(alpha_ij) + cot(beta_ij)`` (PyTorch3D's ``"cot"``). Where
          ``sum_j w_ij <= 0`` (only around very obtuse triangles) the uniform value is used.

    Convention:
        See the module docstring; ``L x_i = 0`` for unreferenced vertices.

    Args:
        verts: ``(*, V, 3)``.
        faces: ``(F, K)`` long padded with ``-1``, or a list of index lists.
        method: ``"uniform"`` or ``"cotangent"``.

    Returns:
        ``(*, V, 3)``.

    Example:
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]])
        >>> faces = torch.tensor([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
        >>> mesh_laplacian(verts, faces)[4]
        tensor([ 0.,  0., -1.])
    """
    check_choice(method, _METHODS, "method")
    faces = _check(verts, faces)
    dtype = verts.dtype
    return cast_back(_laplacian(verts.to(working_dtype(dtype)), faces, method), dtype)


def _laplacian(verts: torch.Tensor, faces: torch.Tensor, method: str) -> torch.Tensor:
    """:func:`mesh_laplacian` of checked arguments."""
    V = verts.shape[-2]
    edges = mesh_edges(faces).edges
    src = torch.cat([edges[:, 0], edges[:, 1]])
    dst = torch.cat([edges[:, 1], edges[:, 0]])
    deg = torch.zeros(V, dtype=verts.dtype, device=verts.device).index_add_(
        0, src, torch.ones_like(src, dtype=verts.dtype))
    neighbours = torch.zeros_like(verts).index_add_(-2, src, verts[..., dst, :])
    has = deg > 0
    uniform = torch.where(has[:, None], neighbours / torch.where(has, deg, 1.0)[:, None] - verts,
                          0.0)
    if method == "uniform":
        return uniform
    csrc, cdst, w = _cotangent_weights(verts, faces)
    wsum = torch.zeros_like(verts[..., 0]).index_add_(-1, csrc, w)  # (*, V)
    pull = torch.zeros_like(verts).index_add_(
        -2, csrc, w[..., None] * (verts[..., cdst, :] - verts[..., csrc, :]))
    ok = ~(wsum <= 0)  # NaN weights keep the (NaN) cotangent value
    return torch.where(ok[..., None], pull / torch.where(ok, wsum, 1.0)[..., None], uniform)


def laplacian_smoothing_loss(verts: torch.Tensor, faces, method: str = "uniform") -> torch.Tensor:
    """Mean norm of the Laplacian over the referenced vertices, per mesh.

    Formula:
        ``loss = (1 / |V'|) sum_{i in V'} |L x_i|`` with ``L`` from :func:`mesh_laplacian`
        (``"uniform"`` or ``"cotangent"``), ``V'`` the vertices used by a face. As in
        PyTorch3D's ``mesh_laplacian_smoothing`` (norm, not squared norm). ``L x_i = 0``
        at interior vertices of any flat mesh for ``"cotangent"``, and of a regular
        flat grid for ``"uniform"`` (boundary vertices are pulled inwards by both).
        Scales as ``s`` when ``verts`` scale by ``s``; the gradient of a zero
        Laplacian is 0, not NaN.

    Convention:
        See the module docstring.

    Args:
        verts: ``(*, V, 3)``.
        faces: ``(F, K)`` padded polygon or triangle faces.
        method: ``"uniform"`` or ``"cotangent"``.

    Returns:
        ``(*,)`` one loss per mesh.

    Example:
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]])
        >>> faces = torch.tensor([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
        >>> laplacian_smoothing_loss(verts, faces)
        tensor(0.8254)
    """
    check_choice(method, _METHODS, "method")
    faces = _check(verts, faces)
    dtype = verts.dtype
    lap = _laplacian(verts.to(working_dtype(dtype)), faces, method)
    used = torch.zeros(verts.shape[-2], dtype=torch.bool, device=verts.device)
    used[faces[faces >= 0]] = True
    norms = safe_norm(lap)  # overflow-safe; gradient 0 (not NaN) at a zero Laplacian
    return cast_back((norms * used).sum(-1) / used.sum().clamp_min(1), dtype)


def _face_normals(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Vector areas ``(*, F, 3)``: ``1/2 sum_k (v_k - v_0) x (v_{k+1} - v_0)`` (Newell,
    relative to the face's first vertex, so a mesh far from the origin keeps its digits)."""
    F, K = faces.shape
    size_f = (faces >= 0).sum(1)
    col = torch.arange(K, device=faces.device)
    nxt = torch.remainder(col[None, :] + 1, size_f.clamp_min(1)[:, None])
    valid = (col[None, :] < size_f[:, None]).to(verts.dtype)
    first = verts[..., faces[:, :1], :]  # (*, F, 1, 3)
    a = verts[..., faces.clamp_min(0), :] - first  # (*, F, K, 3)
    b = verts[..., faces.gather(1, nxt).clamp_min(0), :] - first
    return 0.5 * (torch.linalg.cross(a, b) * valid[..., None]).sum(-2)


def normal_consistency_loss(verts: torch.Tensor, faces) -> torch.Tensor:
    """Mean ``1 - cos`` between the normals of faces sharing an edge, per mesh.

    Formula:
        ``loss = (1 / |P|) sum_{(f, g) in P} (1 - n_f . n_g / (|n_f| |n_g|))`` over the
        pairs ``P`` of faces sharing an edge (:func:`mesh_edges`), ``n`` the vector area.
        A pair with a zero-area face contributes 0 (its normal is undefined). Zero on
        any flat, consistently oriented mesh; in ``[0, 2]``; scale invariant.

    Convention:
        See the module docstring.

    Args:
        verts: ``(*, V, 3)``.
        faces: ``(F, K)`` padded polygon or triangle faces.

    Returns:
        ``(*,)`` one loss per mesh (0 without adjacent faces).

    Example:
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        >>> normal_consistency_loss(verts, torch.tensor([[0, 1, 2], [0, 3, 1]]))
        tensor(1.)
    """
    faces = _check(verts, faces)
    dtype = verts.dtype
    pairs = mesh_edges(faces).face_pairs
    n = _face_normals(_unit_scaled(verts.to(working_dtype(dtype))), faces)
    length = safe_norm(n, keepdim=True)
    zero = length == 0  # an exactly zero area: undefined normal (NaN is not zero)
    unit = n / torch.where(zero, 1.0, length)
    cos = (unit[..., pairs[:, 0], :] * unit[..., pairs[:, 1], :]).sum(-1)
    skip = zero[..., pairs[:, 0], 0] | zero[..., pairs[:, 1], 0]
    term = torch.where(skip, 0.0, 1 - cos)
    return cast_back(term.sum(-1) / max(pairs.shape[0], 1), dtype)


def edge_length_loss(
    verts: torch.Tensor, faces, target: float | torch.Tensor = 0.0
) -> torch.Tensor:
    """Mean squared deviation of the edge lengths from ``target``, per mesh.

    Formula:
        ``loss = (1 / |E|) sum_{(i, j) in E} (|x_i - x_j| - target)^2`` over the unique
        undirected polygon sides (PyTorch3D's ``mesh_edge_loss``). Scales as ``s^2``.

    Convention:
        See the module docstring.

    Args:
        verts: ``(*, V, 3)``.
        faces: ``(F, K)`` padded polygon or triangle faces.
        target: the preferred edge length, ``>= 0``: a number, or a float tensor of the
            dtype of ``verts`` broadcastable to ``(*,)`` (differentiable).

    Returns:
        ``(*,)`` one loss per mesh (0 without edges).

    Raises:
        ValueError: ``target`` is negative or NaN.
        TypeError: ``target`` is a tensor of another dtype than ``verts``.
        ShapeError: ``target``'s shape does not broadcast with the batch dims of ``verts``.

    Example:
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
        >>> edge_length_loss(verts, torch.tensor([[0, 1, 2, 3]]), target=0.5)
        tensor(0.2500)
    """
    faces = _check(verts, faces)
    dtype = verts.dtype
    v = verts.to(working_dtype(dtype))
    # a tensor must have the dtype of verts; a number is taken in the working dtype
    like = verts if isinstance(target, torch.Tensor) else v
    target = as_tensor_like(target, like, "target", like_name="verts")
    if not bool((target.detach() >= 0).all()):
        raise ValueError(f"target: expected a length >= 0, got {target.detach().tolist()}")
    check_broadcastable({"verts": verts.shape[:-2], "target": target.shape})
    target = target.to(v.dtype)[..., None]
    edges = mesh_edges(faces).edges
    length = safe_norm(v[..., edges[:, 0], :] - v[..., edges[:, 1], :])  # (*, E)
    loss = (length - target).square().sum(-1) / max(edges.shape[0], 1)
    return cast_back(loss, dtype)
