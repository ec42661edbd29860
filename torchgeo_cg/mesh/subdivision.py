"""Catmull-Clark subdivision as a sparse operator built once from the topology (report 1.5).

The topology (faces) gives a sparse matrix ``S`` of shape ``(V1, V0)`` whose
rows are OpenSubdiv's Catmark stencils; the geometry is refined by one sparse
matmul per level, ``V1 = S @ V0``, for any batch of shapes sharing the faces
and for any per-vertex data (positions, UVs, features). Backward multiplies by
the cached transpose ``S^T``.

Convention:
    - Faces are ``(F, K)`` long padded with ``-1`` (or a list of index lists) and
      may mix triangles, quads and n-gons; winding counter-clockwise seen from
      outside. Output faces are quads ``(F1, 4)``, ``F1 = sum of face sizes``,
      with the winding of their parent face.
    - New vertex order (stable, documented): first the ``V0`` *vertex points*
      (new vertex ``i`` is the child of old vertex ``i``), then the ``F0`` *face
      points* (in face order), then the ``E0`` *edge points*, edges sorted by
      ``(min(a, b), max(a, b))``. So ``V1 = V0 + F0 + E0``, and an original
      vertex keeps its index at every level.
    - Output face ``sum(size[:f]) + p`` is the quad at corner ``p`` of face ``f``:
      ``(vertex_point[v_p], edge_point[v_p, v_p+1], face_point[f], edge_point[v_p-1, v_p])``.
    - Rules (OpenSubdiv Catmark, Halstead et al. 1993), untagged: an edge with exactly
      two consistently wound faces is *smooth*; any other edge (boundary: 1 face,
      non-manifold: 3+ faces or inconsistent winding) is *sharp*. Face point: mean of
      its vertices. Smooth edge point:
      ``1/4 (v0 + v1) + 1/4 (f0 + f1)``; sharp edge point: ``1/2 (v0 + v1)``.
      Vertex with ``s`` sharp edges out of ``n`` edges and ``m`` faces:
      ``s <= 1`` (smooth, or a dart): ``((n - 2) V + mean(edge nbrs) + mean(face points)) / n``,
      which is ``(n-2)/n V + 1/n^2 sum e + 1/n^2 sum f`` when ``m = n``;
      ``s = 2`` (boundary/crease): ``3/4 V + 1/8 (a + b)``, ``a, b`` its sharp
      neighbours; ``s > 2`` (e.g. non-manifold fins): corner, kept.
      A *corner* is a boundary vertex of valence 2 (one face): it is kept with
      ``boundary="edge_and_corner"`` and smoothed by the boundary rule with
      ``boundary="edge_only"`` (OpenSubdiv ``VTX_BOUNDARY_EDGE_ONLY``, the default).
      Non-manifold vertices (several face fans) are corners, except along an
      interior non-manifold crease (OpenSubdiv).
    - Tags (:class:`~torchgeo_cg.mesh.tags.SubdivisionTags`): creases and corners
      with OpenSubdiv's semi-sharp rules (:mod:`torchgeo_cg.mesh.creasing`), decayed
      from level to level by ``crease_method``; holes keep their vertices and rules
      but have no child faces (``operator.faces`` omits them, ``operator.child_faces``
      and ``operator.child_tags`` carry everything to the next level).
    - Unreferenced vertices pass through unchanged (their row of ``S`` is ``e_i``).
    - Every row of ``S`` sums to 1, so ``S`` commutes with rotations and
      translations applied to the (row-per-vertex) positions.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import torch
from torch import nn

from torchgeo_cg.core.check import check_float, check_shape, check_tensor
from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.core.numerics import working_dtype
from torchgeo_cg.mesh.creasing import (
    CREASE_METHODS,
    child_tags,
    limit_rules,
    subdivision_rules,
)
from torchgeo_cg.mesh.faces import check_faces
from torchgeo_cg.mesh.stencils import StencilMatrix, apply_stencils, stencil_matrix, weights_dtype
from torchgeo_cg.mesh.tags import SubdivisionTags

__all__ = [
    "SubdivisionOperator",
    "catmull_clark_operator",
    "apply_operator",
    "catmull_clark",
    "CatmullClark",
    "limit_positions",
    "catmark_limit_stencils",
    "mesh_topology",
]

_BOUNDARY_MODES = ("edge_only", "edge_and_corner", "none")
TRIANGLE_RULES = ("catmark", "smooth")


class SubdivisionOperator(NamedTuple):
    """One level of subdivision, built once from the topology.

    Attributes:
        stencils: the ``(V1, V0)`` stencil matrix ``S`` (``V1 = S @ V0``) and its
            transpose as plain CSR tensors (:class:`~torchgeo_cg.mesh.stencils.StencilMatrix`).
        faces: ``(F1, 4)`` long output quads (Loop: ``(F1, 3)`` triangles).
        num_vertices_in: ``V0``.
        num_vertices_out: ``V1 = V0 + F0 + E0`` (Loop: ``V0 + E0``).
        num_faces_in: ``F0`` (Catmark face points start at row ``V0``).
        num_edges_in: ``E0`` (edge points start at row ``V0 + F0``; Loop: ``V0``).
        boundary: ``"edge_only"`` (default), ``"edge_and_corner"`` (keep valence-2
            boundary vertices fixed) or ``"none"`` (faces touching an untagged boundary
            become holes).
        scheme: ``"catmark"`` or ``"loop"``, the rules that built it.
        child_faces: every child face, holes' children included (what the next level
            is built from); ``faces`` is this without the holes' children.
        child_tags: :class:`~torchgeo_cg.mesh.tags.SubdivisionTags` of the refined
            mesh (child creases with their decayed sharpness, corners, holes as rows
            of ``child_faces``), or ``None`` for an untagged mesh without holes.

    The properties ``matrix`` and ``matrix_t`` give ``S`` and ``S^T`` as
    ``torch.sparse_csr`` tensors (built on use; they share the stencils' memory).

    Example:
        >>> op = catmull_clark_operator([[0, 1, 2]], 3)  # rows: 3 vertex, 1 face, 3 edge points
        >>> op.matrix.shape, op.faces.tolist(), op.scheme
        (torch.Size([7, 3]), [[0, 4, 3, 5], [1, 6, 3, 4], [2, 5, 3, 6]], 'catmark')
    """

    stencils: StencilMatrix
    faces: torch.Tensor
    num_vertices_in: int
    num_vertices_out: int
    num_faces_in: int
    num_edges_in: int
    boundary: str
    scheme: str = "catmark"
    child_faces: torch.Tensor | None = None
    child_tags: SubdivisionTags | None = None

    @property
    def matrix(self) -> torch.Tensor:
        """``(V1, V0)`` sparse CSR stencil matrix."""
        return self.stencils.sparse()

    @property
    def matrix_t(self) -> torch.Tensor:
        """``(V0, V1)`` sparse CSR transpose (what backward applies)."""
        return self.stencils.sparse_t()


class _Topology(NamedTuple):
    """Corner/edge/vertex tables of a padded polygon mesh (all 1-D, long or bool)."""

    face_c: torch.Tensor  # (C,) face of each corner, corners in face-major order
    pos_c: torch.Tensor  # (C,) position of the corner in its face
    vert_c: torch.Tensor  # (C,) vertex at the corner
    next_c: torch.Tensor  # (C,) next vertex in the face (half-edge vert_c -> next_c)
    prev_corner_c: torch.Tensor  # (C,) index of the previous corner of the same face
    size_c: torch.Tensor  # (C,) size of the corner's face
    edge_c: torch.Tensor  # (C,) edge of the half-edge vert_c -> next_c
    edge_lo_e: torch.Tensor  # (E,) smaller endpoint
    edge_hi_e: torch.Tensor  # (E,) larger endpoint
    sharp_e: torch.Tensor  # (E,) bool: not exactly two faces
    valence_v: torch.Tensor  # (V,) number of edges
    num_faces_v: torch.Tensor  # (V,) number of incident faces
    kind_v: torch.Tensor  # (V,) 0 isolated, 1 smooth/dart, 2 crease, 3 corner


def _check_triangle_rule(triangle_rule: str) -> str:
    if triangle_rule not in TRIANGLE_RULES:
        raise ValueError(f"triangle_rule: expected one of {TRIANGLE_RULES}, got {triangle_rule!r}")
    return triangle_rule


def _check_crease_method(crease_method: str) -> str:
    if crease_method not in CREASE_METHODS:
        raise ValueError(f"crease_method: expected one of {CREASE_METHODS}, got {crease_method!r}")
    return crease_method


def _check_boundary(boundary: str) -> str:
    if boundary not in _BOUNDARY_MODES:
        raise ValueError(f"boundary: expected one of {_BOUNDARY_MODES}, got {boundary!r}")
    return boundary


def mesh_topology(faces_fk: torch.Tensor, num_vertices: int, boundary: str = "edge_only"
                  ) -> _Topology:
    """Corner, edge and vertex tables of ``(F, K)`` padded faces (sort/unique/bincount).

    Example:
        >>> topo = mesh_topology(torch.tensor([[0, 1, 2]]), 3)
        >>> topo.edge_lo_e.tolist(), topo.edge_hi_e.tolist(), topo.valence_v.tolist()
        ([0, 0, 1], [1, 2, 2], [2, 2, 2])
    """
    V = num_vertices
    valid_fk = faces_fk >= 0
    size_f = valid_fk.sum(1)
    F, K = faces_fk.shape
    if bool(valid_fk.all()):  # no padding (pure triangles or quads): skip nonzero
        face_c = torch.arange(F, device=faces_fk.device).repeat_interleave(K)
        pos_c = torch.arange(K, device=faces_fk.device).repeat(F)
    else:
        face_c, pos_c = torch.nonzero(valid_fk, as_tuple=True)  # face-major, then position
    size_c = size_f[face_c]
    start_c = (torch.cumsum(size_f, 0) - size_f)[face_c]
    vert_c = faces_fk[face_c, pos_c]
    next_c = faces_fk[face_c, (pos_c + 1) % size_c]
    prev_corner_c = start_c + (pos_c - 1) % size_c
    lo_c, hi_c = torch.minimum(vert_c, next_c), torch.maximum(vert_c, next_c)
    key_e, edge_c = torch.unique(lo_c * max(V, 1) + hi_c, return_inverse=True)
    E = key_e.numel()
    edge_lo_e, edge_hi_e = key_e // max(V, 1), key_e % max(V, 1)
    sharp_e = torch.bincount(edge_c, minlength=E) != 2
    ends = torch.cat([edge_lo_e, edge_hi_e])
    valence_v = torch.bincount(ends, minlength=V)
    sharp_v = torch.bincount(ends[torch.cat([sharp_e, sharp_e])], minlength=V)
    num_faces_v = torch.bincount(vert_c, minlength=V)
    kind_v = torch.ones(V, dtype=torch.long, device=faces_fk.device)
    kind_v[sharp_v == 2] = 2
    if boundary == "edge_and_corner":
        kind_v[(sharp_v == 2) & (valence_v == 2)] = 3
    kind_v[sharp_v > 2] = 3
    kind_v[valence_v == 0] = 0
    return _Topology(
        face_c, pos_c, vert_c, next_c, prev_corner_c, size_c, edge_c, edge_lo_e, edge_hi_e,
        sharp_e, valence_v, num_faces_v, kind_v,
    )


def catmull_clark_operator(
    faces: torch.Tensor | Sequence[Sequence[int]],
    num_vertices: int,
    boundary: str = "edge_only",
    device: torch.device | str | None = None,
    dtype: torch.dtype | None = None,
    tags: SubdivisionTags | None = None,
    crease_method: str = "uniform",
    triangle_rule: str = "catmark",
) -> SubdivisionOperator:
    """Build one level of Catmull-Clark subdivision as a sparse ``(V1, V0)`` matrix.

    Convention:
        OpenSubdiv Catmark rules and the new-vertex order of the module
        docstring: ``[vertex points (V0) | face points (F0) | edge points (E0)]``.
        The build runs under ``torch.no_grad()`` with sort/unique/bincount only
        (no Python loop over faces, edges or vertices).

    Args:
        faces: ``(F0, K)`` long padded with ``-1``, or a list of index lists;
            triangles, quads and n-gons may be mixed.
        num_vertices: ``V0`` (vertices not used by any face pass through).
        boundary: ``"edge_only"`` (default), ``"edge_and_corner"`` (keep valence-2
            boundary vertices fixed) or ``"none"`` (faces touching an untagged boundary
            become holes).
        device: device of the operator (default: that of ``faces``, CPU for lists).
        dtype: dtype of the weights (default: ``torch.get_default_dtype()``).
        tags: :class:`~torchgeo_cg.mesh.tags.SubdivisionTags` (creases, corners, holes)
            or ``None``; sharpness follows OpenSubdiv (see :mod:`torchgeo_cg.mesh.creasing`).
        crease_method: ``"uniform"`` (default) or ``"chaikin"`` decay of semi-sharp creases.
        triangle_rule: ``"catmark"`` (default) or ``"smooth"`` (OpenSubdiv's
            ``TRI_SUB_SMOOTH`` edge weights next to triangles).

    Returns:
        :class:`SubdivisionOperator` with ``matrix`` ``(V1, V0)``, ``matrix_t``
        ``(V0, V1)``, ``faces`` ``(F1, 4)`` and the sizes.

    Raises:
        ValueError: bad ``boundary``; indices out of range, faces with fewer than
            3 distinct vertices, repeated vertices or repeated faces (the message
            names the face index).
        TypeError, ShapeError: a tags field of the wrong dtype or shape (named).
        TypeError: ``dtype`` is not a floating-point dtype.

    Example:
        >>> from torchgeo_cg.mesh.tags import SubdivisionTags
        >>> quad = [[0, 1, 2, 3]]
        >>> op = catmull_clark_operator(quad, 4)
        >>> op.num_vertices_out, op.faces.shape
        (9, torch.Size([4, 4]))
        >>> op.matrix.to_dense()[4:6]  # the face point, then the edge point of (0, 1)
        tensor([[0.2500, 0.2500, 0.2500, 0.2500],
                [0.5000, 0.5000, 0.0000, 0.0000]])
        >>> hole = SubdivisionTags.empty()._replace(holes=torch.tensor([0]))
        >>> holed = catmull_clark_operator(quad, 4, tags=hole)
        >>> holed.faces.shape, holed.child_faces.shape, holed.child_tags.holes.tolist()
        (torch.Size([0, 4]), torch.Size([4, 4]), [0, 1, 2, 3])
    """
    _check_boundary(boundary)
    _check_crease_method(crease_method)
    _check_triangle_rule(triangle_rule)
    with torch.no_grad():
        faces_fk = check_faces(faces, num_vertices)
        if device is not None:
            faces_fk = faces_fk.to(device)
        wdtype = weights_dtype(dtype)
        V0, F0 = num_vertices, faces_fk.shape[0]
        topo = mesh_topology(faces_fk, V0, boundary)
        rules = subdivision_rules(topo, V0, F0, tags, boundary, crease_method, wdtype)
        E0 = topo.edge_lo_e.numel()
        V1 = V0 + F0 + E0
        row_face, row_edge = V0, V0 + F0
        entries = [
            (row_face + topo.face_c, topo.vert_c, 1.0 / topo.size_c.to(wdtype)),  # face points
            *_catmark_edge_entries(faces_fk, topo, rules, row_edge, wdtype, triangle_rule),
            *_catmark_vertex_entries(faces_fk, topo, rules, wdtype),
        ]
        rows, cols, vals = (torch.cat(parts) for parts in zip(*entries))
        stencils = stencil_matrix(rows, cols, vals, (V1, V0))
        faces_q4 = torch.stack(
            [
                topo.vert_c,
                row_edge + topo.edge_c,
                row_face + topo.face_c,
                row_edge + topo.edge_c[topo.prev_corner_c],
            ],
            dim=1,
        )
        hole_child = rules.hole_f[topo.face_c]
        edge_point_e = row_edge + torch.arange(E0, device=faces_fk.device)
        tags_1 = child_tags(rules, topo.edge_lo_e, topo.edge_hi_e, edge_point_e, hole_child, tags)
    visible = faces_q4 if tags_1 is None or tags_1.holes.numel() == 0 else faces_q4[~hole_child]
    return SubdivisionOperator(
        stencils, visible, V0, V1, F0, E0, boundary, "catmark", faces_q4, tags_1
    )


def _face_offsets(faces_fk, topo, first: int, last_from_end: int):
    """(corner, vertex) pairs for the face vertices at offsets ``first .. size -
    last_from_end`` from each corner (a loop over the face degree only)."""
    corner, vert = [], []
    size_c = topo.size_c
    for d in range(first, faces_fk.shape[1] - last_from_end + 1):
        c_idx = torch.nonzero(d <= size_c - last_from_end).flatten()
        corner.append(c_idx)
        vert.append(faces_fk[topo.face_c[c_idx], (topo.pos_c[c_idx] + d) % size_c[c_idx]])
    if not corner:
        empty = faces_fk.new_zeros(0)
        return empty, empty
    return torch.cat(corner), torch.cat(vert)


def _catmark_edge_entries(faces_fk, topo, rules, row_edge: int, wdtype, triangle_rule):
    """Edge points: ``crease_e`` of ``1/2 (v0 + v1)`` plus ``1 - crease_e`` of the smooth
    ``(1/2 - w) (v0 + v1) + w (f0 + f1)``, the face points spread over their vertices (the
    two ends accumulated per edge, the other vertices one entry each). ``w = 1/4``, or
    with ``triangle_rule="smooth"`` (OpenSubdiv ``TRI_SUB_SMOOTH``) the mean over the two
    faces of ``0.47`` for a triangle and ``1/4`` for any other face."""
    edge_c, size_c = topo.edge_c, topo.size_c.to(wdtype)
    crease_e = rules.crease_e
    face_w_e = torch.full_like(crease_e, 0.25)
    if triangle_rule == "smooth":
        tris_e = torch.zeros_like(crease_e).index_add_(0, edge_c, (topo.size_c == 3).to(wdtype))
        face_w_e = face_w_e + (0.47 - 0.25) / 2 * tris_e  # only 2-face (smooth) edges matter
    smooth_c = ((1.0 - crease_e) * face_w_e)[edge_c]
    end_e = 0.5 * crease_e + (0.5 - face_w_e) * (1.0 - crease_e)
    end_e = end_e.index_add(0, edge_c, smooth_c / size_c)
    rows_e = row_edge + torch.arange(crease_e.numel(), device=edge_c.device)
    oc, ou = _face_offsets(faces_fk, topo, 2, 1)  # every vertex but the edge's two ends
    return [
        (rows_e, topo.edge_lo_e, end_e),
        (rows_e, topo.edge_hi_e, end_e),
        (row_edge + edge_c[oc], ou, smooth_c[oc] / size_c[oc]),
    ]


def _catmark_vertex_entries(faces_fk, topo, rules, wdtype):
    """Vertex points: ``smooth_v`` of ``((n-2) V + mean(edge nbrs) + mean(face points)) / n``,
    ``crease_v`` of ``3/4 V + 1/8 (a + b)`` and ``corner_v`` of ``V``; the face points are
    spread over their vertices (V and its two face neighbours accumulated)."""
    v_c, edge_c = topo.vert_c, topo.edge_c
    lo_e, hi_e = topo.edge_lo_e, topo.edge_hi_e
    n_v = topo.valence_v.to(wdtype).clamp(min=1)
    m_v = topo.num_faces_v.to(wdtype).clamp(min=1)
    smooth_v = rules.smooth_v
    face_w_c = smooth_v[v_c] / (n_v[v_c] * m_v[v_c] * topo.size_c.to(wdtype))
    self_v = smooth_v * (n_v - 2) / n_v + 0.75 * rules.crease_v + rules.corner_v
    self_v = self_v.index_add(0, v_c, face_w_c)
    side_lo = smooth_v[lo_e] / (n_v[lo_e] ** 2) + rules.crease_end_lo_e
    side_hi = smooth_v[hi_e] / (n_v[hi_e] ** 2) + rules.crease_end_hi_e
    lo_side_c = v_c == lo_e[edge_c]  # is the corner's vertex the edge's lo end?
    prev_edge_c = edge_c[topo.prev_corner_c]
    lo_side_prev_c = v_c == lo_e[prev_edge_c]
    side_lo = side_lo.index_add(0, edge_c, face_w_c * lo_side_c)
    side_hi = side_hi.index_add(0, edge_c, face_w_c * ~lo_side_c)
    side_lo = side_lo.index_add(0, prev_edge_c, face_w_c * lo_side_prev_c)
    side_hi = side_hi.index_add(0, prev_edge_c, face_w_c * ~lo_side_prev_c)
    arange_v = torch.arange(n_v.numel(), device=v_c.device)
    oc, ou = _face_offsets(faces_fk, topo, 2, 2)  # every vertex but V and its neighbours
    return [
        (arange_v, arange_v, self_v),
        (lo_e, hi_e, side_lo),
        (hi_e, lo_e, side_hi),
        (v_c[oc], ou, face_w_c[oc]),
    ]


def _check_verts(verts: torch.Tensor, num_vertices: int, name: str = "verts") -> None:
    check_tensor(verts, name)
    check_shape(verts, ["*", "V", "D"], name, {"V": num_vertices})
    check_float(verts, name)


def apply_operator(operator: SubdivisionOperator, verts: torch.Tensor) -> torch.Tensor:
    """Refine per-vertex data with one operator: ``(*, V0, D) -> (*, V1, D)``.

    Convention:
        Rows are vertices (``verts[..., i, :]`` is vertex ``i``); ``D`` is any
        width, so positions, UVs and features refine alike. Differentiable in
        ``verts``; backward applies ``S^T`` from ``operator.stencils``. The
        weights are cast to ``verts``' dtype and device when they differ. Works
        under ``torch.compile(fullgraph=True)``, ``torch.func.vmap`` and ``jacrev``.

    Args:
        operator: from :func:`catmull_clark_operator`.
        verts: ``(*, V0, D)`` float.

    Returns:
        ``(*, V1, D)``.

    Example:
        >>> op = catmull_clark_operator([[0, 1, 2]], 3)
        >>> apply_operator(op, torch.tensor([[0., 0.], [3., 0.], [0., 3.]]))[3:5]
        tensor([[1.0000, 1.0000],
                [1.5000, 0.0000]])
    """
    _check_verts(verts, operator.num_vertices_in)
    return apply_stencils(operator.stencils, verts)


def catmull_clark(
    verts: torch.Tensor,
    faces: torch.Tensor | Sequence[Sequence[int]],
    levels: int = 1,
    boundary: str = "edge_only",
    tags: SubdivisionTags | None = None,
    crease_method: str = "uniform",
    triangle_rule: str = "catmark",
) -> tuple[torch.Tensor, torch.Tensor]:
    """Subdivide ``levels`` times; convenience wrapper over :class:`CatmullClark`.

    Convention:
        See the module docstring (OpenSubdiv Catmark rules, new-vertex order).

    Args:
        verts: ``(*, V, D)`` float; a batch of shapes sharing ``faces``. float16 and
            bfloat16 are refined in float32 (weights and sums) and returned in their dtype.
        faces: ``(F, K)`` long padded with ``-1`` (same device as ``verts``), or
            a list of index lists.
        levels: number of subdivision steps, ``>= 0``.
        boundary: ``"edge_only"`` (default), ``"edge_and_corner"`` (keep valence-2
            boundary vertices fixed) or ``"none"`` (faces touching an untagged boundary
            become holes).
        tags: :class:`~torchgeo_cg.mesh.tags.SubdivisionTags` or ``None`` (see
            :func:`catmull_clark_operator`); carried from level to level.
        crease_method: ``"uniform"`` (default) or ``"chaikin"``.
        triangle_rule: ``"catmark"`` (default) or ``"smooth"``.

    Returns:
        ``(verts (*, V_L, D), faces (F_L, 4) long)``; ``levels = 0`` returns the
        input unchanged (faces padded).

    Raises:
        TypeError: ``verts`` is not a floating-point tensor.
        ValueError: ``verts`` and ``faces`` on different devices, or bad faces.

    Example:
        >>> cube_v = torch.tensor([[x, y, z] for x in (0., 1.) for y in (0., 1.) for z in (0., 1.)])
        >>> cube_f = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
        ...           [1, 5, 7, 3]]
        >>> v1, f1 = catmull_clark(cube_v, cube_f)
        >>> v1.shape, f1.shape
        (torch.Size([26, 3]), torch.Size([24, 4]))
        >>> v1[0] * 9  # the corner moved to (2/9, 2/9, 2/9)
        tensor([2.0000, 2.0000, 2.0000])
    """
    check_float(verts, "verts")
    if isinstance(faces, torch.Tensor) and faces.device != verts.device:
        raise ValueError(
            f"verts and faces must be on the same device, got {verts.device} and {faces.device}"
        )
    check_shape(verts, ["*", "V", "D"], "verts")
    module = CatmullClark(
        faces, verts.shape[-2], levels=levels, boundary=boundary,
        device=verts.device, dtype=working_dtype(verts.dtype),
        tags=tags, crease_method=crease_method, triangle_rule=triangle_rule,
    )
    return module(verts), module.faces


class _SubdivisionModule(nn.Module):
    """Shared machinery: one cached operator per level, applied by sparse matmuls."""

    scheme = ""  # the subclass's scheme name

    @staticmethod
    def _build_operator(faces, num_vertices, boundary, dtype=None, tags=None,
                        crease_method="uniform") -> SubdivisionOperator:
        raise NotImplementedError

    def __init__(
        self,
        faces: torch.Tensor | Sequence[Sequence[int]],
        num_vertices: int,
        levels: int = 1,
        boundary: str = "edge_only",
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
        tags: SubdivisionTags | None = None,
        crease_method: str = "uniform",
        **options: str,
    ) -> None:
        super().__init__()
        if isinstance(levels, bool) or not isinstance(levels, int) or levels < 0:
            raise ValueError(f"levels: expected an int >= 0, got {levels!r}")
        _check_boundary(boundary)
        _check_crease_method(crease_method)
        self.levels, self.boundary, self.crease_method = levels, boundary, crease_method
        self.num_vertices_in = num_vertices
        faces_fk = check_faces(faces, num_vertices)
        if device is not None:
            faces_fk = faces_fk.to(device)
        self.register_buffer("faces_0", faces_fk, persistent=False)
        count = num_vertices
        self.sizes: list[tuple[int, int, int, int]] = []  # (V_in, V_out, F_in, E_in)
        self._child_tag_levels: list[bool] = []
        level_boundary = boundary
        for level in range(levels):  # loop over levels only
            op = self._build_operator(faces_fk, count, level_boundary, dtype=dtype, tags=tags,
                                      crease_method=crease_method, **options)
            for field, tensor in zip(StencilMatrix._fields, op.stencils):
                self.register_buffer(f"{field}_{level}", tensor, persistent=False)
            self.register_buffer(f"faces_{level + 1}", op.faces, persistent=False)
            self.register_buffer(f"child_faces_{level + 1}", op.child_faces, persistent=False)
            self._child_tag_levels.append(op.child_tags is not None)
            if op.child_tags is not None:
                for field, tensor in zip(SubdivisionTags._fields, op.child_tags):
                    self.register_buffer(f"tags_{field}_{level + 1}", tensor, persistent=False)
            self.sizes.append(
                (op.num_vertices_in, op.num_vertices_out, op.num_faces_in, op.num_edges_in)
            )
            faces_fk, count, tags = op.child_faces, op.num_vertices_out, op.child_tags
            # OpenSubdiv applies boundary "none" (boundary faces become holes) at the base
            # level only; the children of those holes are holes of the next levels
            level_boundary = "edge_only" if boundary == "none" else boundary
        self.num_vertices_out = count

    @property
    def faces(self) -> torch.Tensor:
        """``(F_L, 4)`` (Loop: ``(F_L, 3)``) long faces of the last level (input faces,
        padded, when ``levels = 0``)."""
        return getattr(self, f"faces_{self.levels}")

    def operator(self, level: int) -> SubdivisionOperator:
        """The cached :class:`SubdivisionOperator` of step ``level`` (0-based)."""
        if not 0 <= level < self.levels:
            raise IndexError(f"level: expected 0 <= level < {self.levels}, got {level}")
        v_in, v_out, f_in, e_in = self.sizes[level]
        tags = None
        if self._child_tag_levels[level]:
            tags = SubdivisionTags(
                *(getattr(self, f"tags_{f}_{level + 1}") for f in SubdivisionTags._fields)
            )
        boundary = "edge_only" if level and self.boundary == "none" else self.boundary
        return SubdivisionOperator(
            self._stencils(level), getattr(self, f"faces_{level + 1}"),
            v_in, v_out, f_in, e_in, boundary, self.scheme,
            getattr(self, f"child_faces_{level + 1}"), tags,
        )

    def _stencils(self, level: int) -> StencilMatrix:
        return StencilMatrix(*(getattr(self, f"{f}_{level}") for f in StencilMatrix._fields))

    def forward(self, verts: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, verts, "verts", exclude=("tags_",))  # tags built the operators
        _check_verts(verts, self.num_vertices_in)
        for level in range(self.levels):
            verts = apply_stencils(self._stencils(level), verts)
        return verts

    def extra_repr(self) -> str:
        return (
            f"levels={self.levels}, boundary={self.boundary!r}, "
            f"num_vertices={self.num_vertices_in} -> {self.num_vertices_out}"
        )



class CatmullClark(_SubdivisionModule):
    """Catmull-Clark subdivision, ``levels`` steps, operators built once and cached.

    Convention:
        See the module docstring. One :class:`SubdivisionOperator` per level is
        stored as plain non-persistent buffers (the stencil tensors ``crow_{l}``,
        ``col_{l}``, ``weights_{l}``, ``crow_t_{l}``, ``col_t_{l}``, ``weights_t_{l}``
        and ``faces_{l}``), so ``.to(device, dtype)``, ``copy.deepcopy``, DDP,
        ``torch.compile(fullgraph=True)`` and ``torch.func.vmap`` work.

    Args:
        faces: ``(F, K)`` long padded with ``-1``, or a list of index lists.
        num_vertices: ``V``.
        levels: number of subdivision steps, ``>= 0`` (default 1).
        boundary: ``"edge_only"`` (default), ``"edge_and_corner"`` (keep valence-2
            boundary vertices fixed) or ``"none"`` (faces touching an untagged boundary
            become holes).
        device: device of the buffers (default: that of ``faces``).
        dtype: dtype of the weights (default: ``torch.get_default_dtype()``).
        tags: :class:`~torchgeo_cg.mesh.tags.SubdivisionTags` (creases, corners, holes)
            or ``None``; sharpness follows OpenSubdiv (see :mod:`torchgeo_cg.mesh.creasing`).
        crease_method: ``"uniform"`` (default) or ``"chaikin"`` decay of semi-sharp creases.
        triangle_rule: ``"catmark"`` (default) or ``"smooth"`` (OpenSubdiv's
            ``TRI_SUB_SMOOTH`` edge weights next to triangles).

    Shape:
        - forward input ``verts``: ``(*, V, D)`` float, any ``D``.
        - forward output: ``(*, V_L, D)``; ``.faces``: ``(F_L, 4)`` long (the input
          faces, padded, when ``levels = 0``).

    Example:
        >>> cc = CatmullClark([[0, 1, 2, 3]], 4, levels=2)
        >>> out = cc(torch.rand(5, 4, 3))  # 5 shapes sharing one quad
        >>> out.shape, cc.faces.shape, cc.num_vertices_out
        (torch.Size([5, 25, 3]), torch.Size([16, 4]), 25)
    """

    _build_operator = staticmethod(catmull_clark_operator)
    scheme = "catmark"

    def __init__(
        self,
        faces: torch.Tensor | Sequence[Sequence[int]],
        num_vertices: int,
        levels: int = 1,
        boundary: str = "edge_only",
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
        tags: SubdivisionTags | None = None,
        crease_method: str = "uniform",
        triangle_rule: str = "catmark",
    ) -> None:
        _check_triangle_rule(triangle_rule)
        super().__init__(faces, num_vertices, levels, boundary, device, dtype, tags,
                         crease_method, triangle_rule=triangle_rule)
        self.triangle_rule = triangle_rule


def limit_positions(operator: SubdivisionOperator, verts: torch.Tensor) -> torch.Tensor:
    """Exact limit-surface positions of the refined vertices: ``L @ S @ verts``.

    ``S`` is ``operator.stencils``; ``L`` applies the limit masks of the operator's
    scheme on the refined mesh ``operator.faces``. Catmark (Halstead et al. 1993):
    smooth vertex of valence ``n``: ``(n^2 V + 4 sum e_i + sum d_i) / (n (n + 5))``
    (``e_i`` edge neighbours, ``d_i`` the opposite corner of each incident quad).
    Loop: smooth vertex ``(1 - n chi) V + chi sum e_i``, ``chi = 1 / (n + 3 / (8 beta))``
    with Loop's ``beta`` (OpenSubdiv's ``assignSmoothLimitMask``). Both schemes:
    boundary/crease vertex ``(a + 4 V + b) / 6`` (the cubic B-spline limit of the
    crease rule), corners and unreferenced vertices ``V``.

    Convention:
        Same classification and ``boundary`` mode as the operator. Because the
        vertex points come first, ``out[..., :V0, :]`` are the limit positions of
        the original control vertices. Differentiable in ``verts``.

    Args:
        operator: from :func:`catmull_clark_operator` or
            :func:`~torchgeo_cg.mesh.loop.loop_operator`.
        verts: ``(*, V0, D)`` float control data at the operator's input level.

    Returns:
        ``(*, V1, D)`` limit positions of the vertices of ``operator.faces``.

    Raises:
        ValueError: the operator's scheme has no limit masks here (only
            ``"catmark"`` and ``"loop"`` do).

    Example:
        >>> square = torch.tensor([[0., 0.], [1., 0.], [1., 1.], [0., 1.]])
        >>> op = catmull_clark_operator([[0, 1, 2, 3]], 4, boundary="edge_and_corner")
        >>> limit_positions(op, square)[4:6]  # centre, then the middle of the bottom edge
        tensor([[0.5000, 0.5000],
                [0.5000, 0.0000]])
    """
    _check_verts(verts, operator.num_vertices_in)
    wdtype = operator.stencils.weights.dtype
    faces = operator.faces if operator.child_faces is None else operator.child_faces
    args = (faces, operator.num_vertices_out, operator.boundary, wdtype, operator.child_tags)
    if operator.scheme == "catmark":
        limit = catmark_limit_stencils(*args)
    elif operator.scheme == "loop":
        from torchgeo_cg.mesh.loop import loop_limit_stencils  # loop builds on this module

        limit = loop_limit_stencils(*args)
    else:
        raise ValueError(
            f"operator: limit_positions has limit masks for the 'catmark' and 'loop' "
            f"schemes, got an operator of scheme {operator.scheme!r}"
        )
    return apply_stencils(limit, apply_stencils(operator.stencils, verts))


def catmark_limit_stencils(
    faces_q4: torch.Tensor,
    num_vertices: int,
    boundary: str,
    dtype: torch.dtype,
    tags: SubdivisionTags | None = None,
) -> StencilMatrix:
    """``(V, V)`` Catmark limit masks of an all-quad mesh (see :func:`limit_positions`).

    Example:
        >>> catmark_limit_stencils(torch.tensor([[0, 1, 2, 3]]), 4, "edge_only",
        ...                        torch.float64).dense()[0] * 6
        tensor([4., 1., 0., 1.], dtype=torch.float64)
    """
    V1 = num_vertices
    with torch.no_grad():
        topo = mesh_topology(faces_q4, V1, boundary)
        dev, wdtype = faces_q4.device, dtype
        n_v = topo.valence_v.to(wdtype).clamp(min=1)
        m_v = topo.num_faces_v.to(wdtype).clamp(min=1)
        rule_v, sharp_e = limit_rules(topo, V1, faces_q4.shape[0], tags, boundary, wdtype)
        kind_v = rule_v + 1  # 1 smooth, 2 crease, 3 corner
        smooth_v, crease_v = kind_v == 1, kind_v == 2
        self_v = torch.where(smooth_v, n_v / (n_v + 5), 1.0 - crease_v.to(wdtype) / 3.0)
        v_side = torch.cat([topo.edge_lo_e, topo.edge_hi_e])
        nbr_side = torch.cat([topo.edge_hi_e, topo.edge_lo_e])
        sharp_side = torch.cat([sharp_e, sharp_e])
        kind_side = kind_v[v_side]
        w_side = torch.where(
            kind_side == 1,
            4.0 / (n_v[v_side] * (n_v[v_side] + 5)),
            ((kind_side == 2) & sharp_side).to(wdtype) / 6.0,
        )
        # opposite corner of each quad corner: two steps along the face
        diag_c = topo.vert_c[topo.prev_corner_c[topo.prev_corner_c]]
        v_c = topo.vert_c
        w_c = torch.where(smooth_v[v_c], 1.0 / (m_v[v_c] * (n_v[v_c] + 5)), 0.0)
        arange_v = torch.arange(V1, device=dev)
        limit = stencil_matrix(
            torch.cat([arange_v, v_side, v_c]),
            torch.cat([arange_v, nbr_side, diag_c]),
            torch.cat([self_v.to(wdtype), w_side.to(wdtype), w_c.to(wdtype)]),
            (V1, V1),
        )
    return limit
