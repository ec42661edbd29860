"""Catmull-Clark (OpenSubdiv "Catmark") subdivision as a sparse operator built once (report 1.5).

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
      ``SchemeOptions(boundary="edge_and_corner")`` and smoothed by the boundary rule
      with ``boundary="edge_only"`` (OpenSubdiv ``VTX_BOUNDARY_EDGE_ONLY``, the default).
      Non-manifold vertices (several face fans) are corners, except along an
      interior non-manifold crease (OpenSubdiv).
    - Tags (:class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags`): creases and corners
      with OpenSubdiv's semi-sharp rules (OpenSubdiv's rules), decayed
      from level to level by ``crease_method``; holes keep their vertices and rules
      but have no child faces (``operator.faces`` omits them, ``operator.child_faces``
      and ``operator.child_tags`` carry everything to the next level).
    - Unreferenced vertices pass through unchanged (their row of ``S`` is ``e_i``).
    - Every row of ``S`` sums to 1, so ``S`` commutes with rotations and
      translations applied to the (row-per-vertex) positions.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.core.numerics import working_dtype
from torchgeo_cg.mesh.faces import check_faces
from torchgeo_cg.mesh.subdivision._creasing import child_tags, subdivision_rules
from torchgeo_cg.mesh.subdivision._levels import SubdivisionModule
from torchgeo_cg.mesh.subdivision._parallel_edges import catmark_child_edge_tags
from torchgeo_cg.mesh.subdivision._stencil_build import stencil_matrix, weights_dtype
from torchgeo_cg.mesh.subdivision._topology import mesh_topology
from torchgeo_cg.mesh.subdivision.operator import SubdivisionOperator
from torchgeo_cg.mesh.subdivision.options import SchemeOptions
from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags

__all__ = ["catmull_clark_operator", "catmull_clark", "CatmullClark"]

def catmull_clark_operator(
    faces: torch.Tensor | Sequence[Sequence[int]],
    num_vertices: int,
    device: torch.device | str | None = None,
    dtype: torch.dtype | None = None,
    tags: SubdivisionTags | None = None,
    edge_tags: torch.Tensor | None = None,
    *,
    options: SchemeOptions = SchemeOptions(),
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
        device: device of the operator (default: that of ``faces``, CPU for lists).
        dtype: dtype of the weights (default: ``torch.get_default_dtype()``).
        tags: :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` (creases, corners, holes)
            or ``None``; sharpness follows OpenSubdiv (OpenSubdiv's creasing rules).
        edge_tags: ``(C,)`` long per corner of ``faces`` or ``None``: the previous
            operator's ``child_edge_tags`` when ``faces`` is its ``child_faces``.
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions` (boundary,
            crease method, triangle rule); the defaults are OpenSubdiv's.

    Returns:
        :class:`SubdivisionOperator` with ``matrix`` ``(V1, V0)``, ``matrix_t``
        ``(V0, V1)``, ``faces`` ``(F1, 4)`` and the sizes.

    Raises:
        TypeError: ``options`` is not a :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions`.
        ValueError: indices out of range or negative other than
            trailing ``-1`` padding (the message names the face index). Faces that
            repeat a vertex (degenerate quads as poles) and repeated faces
            (back-to-back, duplicated) are refined as OpenSubdiv refines them: a
            degenerate side is an edge of its own, a face's second side on the same
            pair is split off and, with the first, non-manifold (sharp).
        TypeError, ShapeError: a tags field of the wrong dtype or shape (named).
        TypeError: ``dtype`` is not a floating-point dtype.

    Example:
        >>> from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags
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
    options = SchemeOptions.check(options)
    boundary, crease_method = options.boundary, options.crease_method
    with torch.no_grad():
        faces_fk = check_faces(faces, num_vertices, allow_duplicates=True, allow_degenerate=True)
        if device is not None:
            faces_fk = faces_fk.to(device)
        wdtype = weights_dtype(dtype)
        V0, F0 = num_vertices, faces_fk.shape[0]
        topo = mesh_topology(faces_fk, V0, boundary, edge_tags)
        rules = subdivision_rules(topo, V0, F0, tags, boundary, crease_method, wdtype)
        E0 = topo.edge_lo_e.numel()
        V1 = V0 + F0 + E0
        row_face, row_edge = V0, V0 + F0
        entries = [
            (row_face + topo.face_c, topo.vert_c, 1.0 / topo.size_c.to(wdtype)),  # face points
            *_catmark_edge_entries(faces_fk, topo, rules, row_edge, wdtype,
                                   options.triangle_rule),
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
        stencils, visible, V0, V1, F0, E0, boundary, "catmark", faces_q4, tags_1,
        catmark_child_edge_tags(topo, rules.inherit_e),
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


def catmull_clark(
    verts: torch.Tensor,
    faces: torch.Tensor | Sequence[Sequence[int]],
    levels: int = 1,
    tags: SubdivisionTags | None = None,
    *,
    options: SchemeOptions = SchemeOptions(),
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
        tags: :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` or ``None`` (see
            :func:`catmull_clark_operator`); carried from level to level.
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions` (boundary,
            crease method, triangle rule); the defaults are OpenSubdiv's.

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
    module = CatmullClark(faces, verts.shape[-2], levels=levels, device=verts.device,
                          dtype=working_dtype(verts.dtype), tags=tags, options=options)
    return module(verts), module.faces


class CatmullClark(SubdivisionModule):
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
        device: device of the buffers (default: that of ``faces``).
        dtype: dtype of the weights (default: ``torch.get_default_dtype()``).
        tags: :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` (creases, corners, holes)
            or ``None``; sharpness follows OpenSubdiv (OpenSubdiv's creasing rules).
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions` (boundary,
            crease method, triangle rule); the defaults are OpenSubdiv's.

    Shape:
        - forward input ``verts``: ``(*, V, D)`` float, any ``D``.
        - forward output: ``(*, V_L, D)``; ``.faces``: ``(F_L, 4)`` long (the input
          faces, padded, when ``levels = 0``).
        - forward ``out`` (optional): a ``(*, V_L, D)`` buffer of ``verts``' dtype and
          device that takes the result (outside autograd, eager only; see
          :func:`~torchgeo_cg.mesh.subdivision.apply_operator`).

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
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
        tags: SubdivisionTags | None = None,
        *,
        options: SchemeOptions = SchemeOptions(),
    ) -> None:
        super().__init__(faces, num_vertices, levels, device, dtype, tags, options=options)


