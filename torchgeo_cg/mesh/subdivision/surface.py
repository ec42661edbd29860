"""The Catmark and Loop limit surfaces at any point of any control face, as sparse stencils.

Convention:
    - Points are ``(face_ids, uv)`` in OpenSubdiv's ptex numbering (``Far::PtexIndices``)
      of the operator's input mesh: faces in order, a quad (Catmark) or a triangle (Loop)
      is one ptex face, any other ``k``-gon is ``k`` of them (sub-face ``j`` is the quad
      at corner ``j``). A quad's corners 0-3 sit at ``uv`` (0,0), (1,0), (1,1), (0,1); a
      triangle's corners 0-2 at (0,0), (1,0), (0,1) (``u + v <= 1``); sub-face ``j`` of
      a ``k``-gon has (0,0) at corner ``j``, (1,0) at the middle of edge ``j -> j+1`` and
      (1,1) at the face's centre. ``du``, ``dv`` are the derivatives in that parametrisation, and
      ``normals = normalize(du x dv)`` point outward for counter-clockwise faces.
    - Evaluation is OpenSubdiv's feature-adaptive scheme: the point's quad (triangle)
      after one level (the operator) is refined around the point until its patch is
      regular, and there it is the bicubic B-spline patch
      (:mod:`~torchgeo_cg.mesh.subdivision._patches`: smooth valence-4 corners,
      boundary and infinitely sharp crease corners, corners of valence 2) or Loop's
      quartic box-spline patch (:mod:`~torchgeo_cg.mesh.subdivision._loop_patches`:
      smooth valence-6 corners, crease and boundary corners with 3 faces on their side),
      exact to rounding. Infinitely sharp creases are patch boundaries (OpenSubdiv's
      ``useInfSharpPatch``).
    - A face with one smooth interior extraordinary vertex (any valence) and smooth
      regular other corners, with no sharp edge at its corners, is evaluated exactly at
      any distance from that vertex, as soon as refinement isolates it (Stam's
      evaluation, in ``mesh/subdivision/_ev_patches.py``): positions and
      normals are continuous across every edge there and equal the limit's to rounding
      (measured in float64 next to vertices of valence 3 to 16: 1e-11 or better).
      The ptex derivatives there scale like ``(2 lam)**n`` at ``2**-n`` from the vertex
      (``lam`` the subdominant eigenvalue: above 1/2 for valences above the regular one,
      so they grow without bound; below it for Catmark's valence 3 and Loop's 3-5);
      at the vertex itself, where they are unbounded or zero, ``du`` and ``dv`` are
      their limits along the face's two edges divided by ``(2 lam)**n``: tangent to
      the edges, so the normal is the exact limit normal, but their lengths are not
      those of nearby points.
    - Points still in an irregular face at level ``max_level`` (within
      ``2**-max_level`` of the face size of an irregular-boundary vertex, a dart, a
      corner of another valence, a hole's vertex, an extraordinary vertex next to a
      crease or to another irregular vertex at that level, or a semi-sharp feature
      sharper than ``max_level``) take a bilinear (Loop: linear) end cap through the
      exact limit positions of that face's corners: so at every vertex the result
      equals :func:`limit_positions`, and positions stay continuous across every edge,
      but normals there are those of the cap (off the limit's by up to the cap's
      chord error, and not continuous across its edges).
    - Tags, holes and the boundary are those the operator was built with; pass the same
      ``options`` (the operator does not record the crease method and triangle rule).
      Points on holes raise.
    - The result is linear in the control points: :func:`limit_stencils` builds sparse
      ``(N, V0)`` matrices once (under ``torch.no_grad()``, without Python loops over
      faces or points; a loop over the levels), and :func:`limit_surface` applies them,
      one sparse matmul for a whole batch of shapes sharing the topology, differentiable
      in ``verts``.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_shape, check_tensor
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.mesh.subdivision._creasing import effective_sharpness
from torchgeo_cg.mesh.subdivision._ev_patches import (
    CHILD_A,
    CHILD_B,
    TRI_A,
    TRI_B,
    ev_face_corners,
    ev_tables,
    ev_weights,
    ring_slots,
    rotate_to_corner,
)
from torchgeo_cg.mesh.subdivision._limit_assembly import (
    Patches,
    PointBlock,
    assemble_limit_stencils,
)
from torchgeo_cg.mesh.subdivision._limit_masks import catmark_limit_stencils, loop_limit_stencils
from torchgeo_cg.mesh.subdivision._loop_patches import (
    box_spline_weights,
    phantom_fold_loop,
    phantom_rules,
    regular_triangles,
    triangle_slots,
)
from torchgeo_cg.mesh.subdivision._normals import unit_normals
from torchgeo_cg.mesh.subdivision._patches import (
    bspline_basis,
    patch_grids,
    phantom_fold,
    quad_twins,
    regular_quads,
)
from torchgeo_cg.mesh.subdivision._stencil_build import StencilMatrix, stencil_matrix
from torchgeo_cg.mesh.subdivision._topology import check_verts, mesh_topology
from torchgeo_cg.mesh.subdivision.catmark import catmull_clark_operator
from torchgeo_cg.mesh.subdivision.loop import loop_operator
from torchgeo_cg.mesh.subdivision.operator import SubdivisionOperator
from torchgeo_cg.mesh.subdivision.options import SchemeOptions
from torchgeo_cg.mesh.subdivision.stencils import apply_stencils
from torchgeo_cg.mesh.subdivision.tags import INFINITELY_SHARP, SubdivisionTags

__all__ = [
    "LimitSurfaceSample", "LimitStencils", "SurfaceSamples", "limit_stencils", "limit_surface",
    "sample_limit_surface",
]


class LimitSurfaceSample(NamedTuple):
    """Points of the limit surface.

    Attributes:
        positions: ``(*, N, D)``.
        du: ``(*, N, D)`` derivative along ptex ``u``.
        dv: ``(*, N, D)`` derivative along ptex ``v``.
        normals: ``(*, N, 3)`` unit ``du x dv`` (zero where it vanishes), or ``None`` when
            ``D != 3``.

    Example:
        >>> from torchgeo_cg.mesh import catmull_clark_operator
        >>> x = torch.arange(4.0)
        >>> grid = torch.stack(torch.meshgrid(x, x, indexing="xy"), -1).reshape(-1, 2)
        >>> verts = torch.cat([grid, torch.zeros(16, 1)], 1)  # a flat 4x4 grid of points
        >>> faces = torch.tensor([[4 * r + c, 4 * r + c + 1, 4 * r + c + 5, 4 * r + c + 4]
        ...                       for r in range(3) for c in range(3)])
        >>> sample = limit_surface(catmull_clark_operator(faces, 16), verts, torch.tensor([4]),
        ...                        torch.tensor([[0.5, 0.5]]))
        >>> sample.positions, sample.normals
        (tensor([[1.5000, 1.5000, 0.0000]]), tensor([[0., 0., 1.]]))
    """

    positions: torch.Tensor
    du: torch.Tensor
    dv: torch.Tensor
    normals: torch.Tensor | None


class LimitStencils(NamedTuple):
    """Sparse ``(N, V0)`` stencils of the limit positions and derivatives at N points.

    Their indices are int32 where the sizes fit (MKL's faster sparse product). The three
    matrices share one pattern, the union of their nonzeros (so a derivative may hold
    explicit zeros), and its index tensors. Rows list increasing columns; the rows of the
    transposes list their entries grouped by patch, not sorted (the products the stencils
    feed do not need the order).

    Attributes:
        positions: :class:`~torchgeo_cg.mesh.subdivision.stencils.StencilMatrix`.
        du: the same for the ``u`` derivative.
        dv: the same for the ``v`` derivative.
    """

    positions: StencilMatrix
    du: StencilMatrix
    dv: StencilMatrix


class SurfaceSamples(NamedTuple):
    """Points drawn on the limit surface.

    Attributes:
        positions: ``(*B, N, D)``.
        normals: ``(*B, N, 3)`` or ``None`` when ``D != 3``.
        face_ids: ``(N,)`` long ptex face of each point.
        uv: ``(N, 2)`` its ptex coordinates.
    """

    positions: torch.Tensor
    normals: torch.Tensor | None
    face_ids: torch.Tensor
    uv: torch.Tensor


class _Level(NamedTuple):
    faces: torch.Tensor  # (F, 4) quads of this level's (partial) mesh
    num_vertices: int
    tags: SubdivisionTags
    chain: tuple  # CSR (crow, col, weights) of this level's vertices in control vertices
    edge_tags: torch.Tensor | None  # (C,) per corner: sides kept apart (_parallel_edges)


def _expand(rows, cols, vals, csr):
    """Triplets ``(row, col, w)`` times a CSR matrix (indexed by ``col``): the triplets of
    the product, unsummed."""
    crow, col, val = csr
    start = crow[cols]
    n = crow[cols + 1] - start
    rep = torch.repeat_interleave(torch.arange(cols.numel(), device=cols.device), n)
    first = torch.repeat_interleave(torch.cumsum(n, 0) - n, n)
    k = start[rep] + torch.arange(rep.numel(), device=cols.device) - first
    return rows[rep], col[k], vals[rep] * val[k]


def _face_matrices(slots: torch.Tensor, fold: torch.Tensor | None, chains, num_cols: int,
                   dtype) -> Patches:
    """Per face, its ``S`` slots ``(m, S)`` (each ``sum_j fold[s, j] * vertex(slots[j])``,
    the vertex itself without ``fold``) composed through ``chains`` (CSR matrices applied
    right to left): :class:`Patches` with ``C (m, S, K)`` dense over ``cols (m, K)``."""
    m, S = slots.shape
    dev = slots.device
    if fold is None:
        rows = torch.arange(m * S, device=dev)
        cols, vals = slots.reshape(-1), torch.ones(m * S, dtype=dtype, device=dev)
    else:
        face, s, j = torch.nonzero(fold, as_tuple=True)
        rows, cols, vals = face * S + s, slots[face, j], fold[face, s, j].to(dtype)
    for csr in chains:
        rows, cols, vals = _expand(rows, cols, vals, csr)
    face = rows // S
    key, inverse = torch.unique(face * num_cols + cols, return_inverse=True)
    ukey_face = key // num_cols
    count = torch.bincount(ukey_face, minlength=m)
    first = torch.cumsum(count, 0) - count
    k_u = torch.arange(key.numel(), device=dev) - first[ukey_face]
    K = int(count.max()) if m else 0
    C = torch.zeros(m, S, K, dtype=dtype, device=dev)
    C.index_put_((face, rows % S, k_u[inverse]), vals, accumulate=True)
    out_cols = torch.zeros(m, K, dtype=torch.long, device=dev)
    out_cols[ukey_face, k_u] = key % num_cols
    return Patches(C, out_cols, count)


def _local_faces(face: torch.Tensor, num_faces: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``(faces used (m,) increasing, each point's index among them (n,))``, by marking
    (no sort of the points)."""
    mark = torch.zeros(num_faces, dtype=torch.bool, device=face.device)
    mark[face] = True
    local = torch.cumsum(mark, 0) - 1
    return torch.nonzero(mark).flatten(), local[face]


def _chain_rule(ws, wt, st):
    """Weights of d/du and d/dv from those of d/ds, d/dt and the Jacobian
    ``d(s, t)/d(u, v)`` in columns 2-5 of the packed points ``st`` (row-major)."""
    a, c, b, d = (st[:, i, None] for i in range(2, 6))
    return ws * a + wt * b, ws * c + wt * d


def _packed(s, t, jac) -> torch.Tensor:
    """``(n, 6)``: each point's ``(s, t)`` and its Jacobian, the weights' arguments."""
    return torch.cat([s[:, None], t[:, None], jac.reshape(-1, 4)], 1)


def _to_child(s, t, jac, scheme="catmark"):
    """Child quad (Loop: triangle) ``p (n,)`` holding local ``(s, t)``, and the point's
    coordinates and Jacobian in it."""
    hi_s, hi_t = s >= 0.5, t >= 0.5
    if scheme == "catmark":
        p = torch.where(hi_t, torch.where(hi_s, 2, 3), torch.where(hi_s, 1, 0))
        table_a, table_b = CHILD_A, CHILD_B
    else:
        p = torch.where(hi_s, 1, torch.where(hi_t, 2, torch.where(s + t <= 0.5, 0, 3)))
        table_a, table_b = TRI_A, TRI_B
    A = torch.tensor(table_a, dtype=s.dtype, device=s.device).reshape(4, 2, 2)[p]
    b = torch.tensor(table_b, dtype=s.dtype, device=s.device)[p]
    st = torch.einsum("nij,nj->ni", A, torch.stack([s, t], -1)) + b
    return p, st[:, 0].clamp(0, 1), st[:, 1].clamp(0, 1), A @ jac


def _ptex_to_level_one(operator, face_ids, uv, dtype):
    """``(face (n,), s, t, jac (n, 2, 2))`` of each ptex point in the operator's child quads
    (Loop: triangles)."""
    V0, F0 = operator.num_vertices_in, operator.num_faces_in
    child = operator.faces if operator.child_faces is None else operator.child_faces
    if operator.scheme == "loop":  # a triangle is one ptex face
        size = torch.full((F0,), 4, dtype=torch.long, device=child.device)
    else:
        size = torch.bincount(child[:, 2] - V0, minlength=F0)  # a child quad's face point
    first_child = torch.cumsum(size, 0) - size
    count = torch.where(size == 4, 1, size)
    ptex_end = torch.cumsum(count, 0)
    total = int(ptex_end[-1]) if F0 else 0
    bad = (face_ids < 0) | (face_ids >= total)
    if bool(bad.any()):
        i = int(torch.nonzero(bad.flatten())[0])
        raise ValueError(f"face_ids: expected ptex face ids in [0, {total}), got "
                         f"{int(face_ids.flatten()[i])} at flat index {i}")
    f = torch.searchsorted(ptex_end, face_ids, right=True)
    u, v = uv[:, 0].to(dtype), uv[:, 1].to(dtype)
    eye = torch.eye(2, dtype=dtype, device=uv.device).expand(face_ids.numel(), 2, 2)
    if operator.scheme == "loop":  # 4 child triangles per face
        p, s, t, jac = _to_child(u, v, eye, "loop")
        return first_child[f] + p, s, t, jac
    p, s, t, jac = _to_child(u, v, eye)
    quad = size[f] == 4
    sub = face_ids - (ptex_end[f] - count[f])
    face = first_child[f] + torch.where(quad, p, sub)
    s, t = torch.where(quad, s, u), torch.where(quad, t, v)
    jac = torch.where(quad[:, None, None], jac, eye)
    return face, s, t, jac


def _sub_tags(tags: SubdivisionTags, vmap, fmap, sub_faces) -> SubdivisionTags:
    """The tags of a partial mesh: creases that are edges of ``sub_faces``, kept corners
    and holes, renumbered by ``vmap`` / ``fmap`` (``-1``: dropped)."""
    n = max(int(vmap.max()) + 1 if vmap.numel() else 0, 1)
    a, b = vmap[tags.creases[:, 0]], vmap[tags.creases[:, 1]]
    ring = torch.cat([sub_faces, sub_faces[:, :1]], 1)
    lo = torch.minimum(ring[:, :-1], ring[:, 1:]).flatten()
    hi = torch.maximum(ring[:, :-1], ring[:, 1:]).flatten()
    keys = torch.unique(lo * n + hi)
    key = torch.minimum(a, b) * n + torch.maximum(a, b)
    pos = torch.searchsorted(keys, key).clamp(max=max(keys.numel() - 1, 0))
    keep = (a >= 0) & (b >= 0) & (keys[pos] == key) if keys.numel() else a < -1
    corner_keep = vmap[tags.corners] >= 0
    holes = fmap[tags.holes]
    return SubdivisionTags(
        torch.stack([a, b], 1)[keep], tags.crease_sharpness[keep],
        vmap[tags.corners][corner_keep], tags.corner_sharpness[corner_keep], holes[holes >= 0],
    )


def _refine_around(level: _Level, faces_needed, options, dtype, num_cols):
    """The next level of the part of ``level`` within two rings of ``faces_needed``, and
    the map from this level's faces to the part's faces (``-1`` outside)."""
    faces, V = level.faces, level.num_vertices
    mark_f = torch.zeros(faces.shape[0], dtype=torch.bool, device=faces.device)
    mark_f[faces_needed] = True
    for _ in range(2):  # two rings of faces: every vertex the next level needs is interior
        mark_v = torch.zeros(V, dtype=torch.bool, device=faces.device)
        mark_v[faces[mark_f].flatten()] = True
        mark_f = mark_v[faces].any(1)
    keep_f = torch.nonzero(mark_f).flatten()
    keep_v, sub_faces = torch.unique(faces[keep_f], return_inverse=True)
    sub_edge_tags = None if level.edge_tags is None else (
        level.edge_tags.reshape(faces.shape)[keep_f].flatten())
    vmap = torch.full((V,), -1, dtype=torch.long, device=faces.device)
    vmap[keep_v] = torch.arange(keep_v.numel(), device=faces.device)
    fmap = torch.full((faces.shape[0],), -1, dtype=torch.long, device=faces.device)
    fmap[keep_f] = torch.arange(keep_f.numel(), device=faces.device)
    tags = _sub_tags(level.tags, vmap, fmap, sub_faces)
    build = loop_operator if faces.shape[1] == 3 else catmull_clark_operator
    op = build(sub_faces, keep_v.numel(), dtype=dtype, tags=tags, edge_tags=sub_edge_tags,
               options=options)
    st = op.stencils
    rows = torch.repeat_interleave(torch.arange(op.num_vertices_out, device=faces.device),
                                   st.crow[1:] - st.crow[:-1])
    rows, cols, vals = _expand(rows, keep_v[st.col], st.weights, level.chain)
    chain = stencil_matrix(rows, cols, vals, (op.num_vertices_out, num_cols))
    child_tags = op.child_tags if op.child_tags is not None else SubdivisionTags.empty(
        dtype, faces.device)
    nxt = _Level(op.child_faces, op.num_vertices_out, child_tags,
                 (chain.crow, chain.col, chain.weights), op.child_edge_tags)
    return nxt, fmap


def _sharp_tags(tags: SubdivisionTags) -> SubdivisionTags:
    """Tags with every positive sharpness made infinite (the end caps' limit masks)."""
    inf = lambda s: torch.where(s > 0, torch.full_like(s, INFINITELY_SHARP), s)  # noqa: E731
    return tags._replace(crease_sharpness=inf(tags.crease_sharpness),
                         corner_sharpness=inf(tags.corner_sharpness))


def _tensor_weights(st):
    """``(n, 3, 16)`` bicubic B-spline weights of the position and ``d/du``, ``d/dv``."""
    bu, du = bspline_basis(st[:, 0])
    bv, dv = bspline_basis(st[:, 1])
    outer = lambda a, b: (a[:, :, None] * b[:, None, :]).reshape(-1, 16)  # noqa: E731
    wu, wv = _chain_rule(outer(bv, du), outer(dv, bu), st)
    return torch.stack([outer(bv, bu), wu, wv], 1)


def _box_weights(st):
    """``(n, 3, 12)`` quartic box-spline weights of the position and ``d/du``, ``d/dv``."""
    w, ws, wt = box_spline_weights(st[:, 0], st[:, 1])
    wu, wv = _chain_rule(ws, wt, st)
    return torch.stack([w, wu, wv], 1)


def _bilinear_weights(st):
    """``(n, 3, 4)`` bilinear weights of a quad's corners and their derivatives."""
    s, t = st[:, 0], st[:, 1]
    a, b = 1 - s, 1 - t
    ws, wt = torch.stack([-b, b, t, -t], -1), torch.stack([-a, -s, s, a], -1)
    wu, wv = _chain_rule(ws, wt, st)
    return torch.stack([torch.stack([a * b, s * b, s * t, a * t], -1), wu, wv], 1)


def _linear_weights(st):
    """``(n, 3, 3)`` linear weights of a triangle's corners and their derivatives."""
    s, t = st[:, 0], st[:, 1]
    one, zero = torch.ones_like(s), torch.zeros_like(s)
    ws, wt = torch.stack([-one, one, zero], -1), torch.stack([-one, zero, one], -1)
    wu, wv = _chain_rule(ws, wt, st)
    return torch.stack([torch.stack([1 - s - t, s, t], -1), wu, wv], 1)


def _emit_patches(out, level, topo, twin, sharp_e, sample, face, s, t, jac, num_cols):
    """The block of the points ``sample`` in regular quads ``face`` of ``level``."""
    fu, face_local = _local_faces(face, level.faces.shape[0])
    grid, phantom = patch_grids(topo, twin, sharp_e, fu)
    patches = _face_matrices(grid.reshape(-1, 16), phantom_fold(phantom, s.dtype),
                             (level.chain,), num_cols, s.dtype)
    out.append(PointBlock(sample, face_local, _packed(s, t, jac), _tensor_weights, patches))


def _emit_triangles(out, level, topo, twin, sharp_e, sample, face, s, t, jac, num_cols):
    """The block of the points ``sample`` in regular triangles ``face`` of ``level``."""
    fu, face_local = _local_faces(face, level.faces.shape[0])
    slots, present, _, _ = triangle_slots(topo, twin, sharp_e >= INFINITELY_SHARP, fu)
    rule, _ = phantom_rules(present)
    patches = _face_matrices(slots, phantom_fold_loop(present, rule, s.dtype), (level.chain,),
                             num_cols, s.dtype)
    out.append(PointBlock(sample, face_local, _packed(s, t, jac), _box_weights, patches))


def _emit_end_caps(out, level, boundary, sample, face, s, t, jac, num_cols):
    """The block of the points ``sample`` in irregular faces at the last level: the
    bilinear (Loop: linear) patch through the exact limit positions of its corners."""
    fu, face_local = _local_faces(face, level.faces.shape[0])
    masks = catmark_limit_stencils if level.faces.shape[1] == 4 else loop_limit_stencils
    limit = masks(level.faces, level.num_vertices, boundary, s.dtype, _sharp_tags(level.tags),
                  level.edge_tags)
    patches = _face_matrices(level.faces[fu], None, ((limit.crow, limit.col, limit.weights),
                                                      level.chain), num_cols, s.dtype)
    weights = _linear_weights if level.faces.shape[1] == 3 else _bilinear_weights
    out.append(PointBlock(sample, face_local, _packed(s, t, jac), weights, patches))


def _emit_ev_patches(out, level, topo, twin, corner, sample, face, s, t, jac, num_cols):
    """The blocks of the points ``sample`` in EV faces ``face`` (their EV at ``corner``),
    one per valence: Stam's exact evaluation on the faces' slots."""
    scheme = "catmark" if level.faces.shape[1] == 4 else "loop"
    valence = topo.valence_v[level.faces[face, corner]]
    corner_f = torch.zeros(level.faces.shape[0], dtype=torch.long, device=face.device)
    corner_f[face] = corner
    for N in torch.unique(valence).tolist():  # a loop over valences
        m = valence == N
        fu, face_local = _local_faces(face[m], level.faces.shape[0])
        slots = ring_slots(topo, twin, fu, corner_f[fu], N, scheme)
        patches = _face_matrices(slots, None, (level.chain,), num_cols, s.dtype)
        rs, rt, rjac = rotate_to_corner(s[m], t[m], jac[m], corner[m], scheme)
        weights = ev_weights(ev_tables(N, scheme, s.dtype, s.device), scheme)
        out.append(PointBlock(sample[m], face_local, _packed(rs, rt, rjac), weights, patches))


def _check_level(max_level) -> int:
    if isinstance(max_level, bool) or not isinstance(max_level, int) or max_level < 1:
        raise ValueError(f"max_level: expected an int >= 1, got {max_level!r}")
    return max_level


def _check_operator(operator) -> None:
    if not isinstance(operator, SubdivisionOperator):
        raise TypeError("operator: expected a SubdivisionOperator (catmull_clark_operator, "
                        f"loop_operator), got {type(operator).__name__}")


def _check_points(operator, face_ids, uv):
    _check_operator(operator)
    if operator.scheme not in ("catmark", "loop"):
        raise ValueError(f"operator: the limit surface needs a 'catmark' or 'loop' operator, "
                         f"got one of scheme {operator.scheme!r}")
    check_tensor(face_ids, "face_ids")
    check_tensor(uv, "uv")
    if face_ids.dtype.is_floating_point or face_ids.dtype.is_complex or face_ids.dtype == \
            torch.bool:
        raise TypeError(f"face_ids: expected an integer tensor, got {face_ids.dtype}")
    if not uv.dtype.is_floating_point:
        raise TypeError(f"uv: expected a floating-point tensor, got {uv.dtype}")
    check_shape(uv, [*(str(n) for n in face_ids.shape), "2"], "uv",
                {str(n): n for n in face_ids.shape})
    outside = ~((uv >= 0) & (uv <= 1))
    if bool(outside.any()):
        i = int(torch.nonzero(outside.reshape(-1, 2).any(1))[0])
        raise ValueError(f"uv: expected coordinates in [0, 1], got "
                         f"{uv.reshape(-1, 2)[i].tolist()} at point {i}")
    if operator.scheme == "loop":
        beyond = uv.sum(-1) > 1 + 2 * torch.finfo(uv.dtype).eps  # rounding of 1 - u
        if bool(beyond.any()):
            i = int(torch.nonzero(beyond.flatten())[0])
            raise ValueError(f"uv: expected u + v <= 1 on Loop's triangles, got "
                             f"{uv.reshape(-1, 2)[i].tolist()} at point {i}")


def limit_stencils(
    operator: SubdivisionOperator,
    face_ids: torch.Tensor,
    uv: torch.Tensor,
    *,
    options: SchemeOptions = SchemeOptions(),
    max_level: int = 8,
) -> LimitStencils:
    """Sparse ``(N, V0)`` stencils of the Catmark or Loop limit surface at ptex points.

    Convention:
        See the module docstring (ptex numbering and ``uv``, feature-adaptive evaluation,
        exact next to isolated smooth extraordinary vertices at any distance, and
        farther than ``2**-max_level`` from other irregular features).

    Args:
        operator: a ``"catmark"`` or ``"loop"`` :class:`SubdivisionOperator` of the
            control mesh.
        face_ids: ``(*, N)`` integer ptex face ids; the rows are the flattened points.
        uv: ``(*, N, 2)`` float in ``[0, 1]`` (Loop: ``u + v <= 1``).
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions` the operator
            was built with; its crease method and triangle rule refine near irregular
            features (the operator records its own boundary, which is used).
        max_level: refinement levels at most (``>= 1``; 8 by default).

    Returns:
        :class:`LimitStencils` of three ``(prod(*) * N, V0)`` stencil matrices in the
        operator's weights dtype.

    Raises:
        TypeError: ``operator`` is not a :class:`SubdivisionOperator` (a module such as
            :class:`~torchgeo_cg.mesh.CatmullClark` holds one per level, not one of the
            control mesh), or ``face_ids``/``uv`` have a wrong dtype.
        ValueError: an operator of another scheme, ``face_ids`` out of range, ``uv``
            outside ``[0, 1]`` (Loop: or ``u + v > 1``), a point on a hole, or a bad
            ``max_level``.

    Example:
        >>> from torchgeo_cg.mesh.subdivision import SchemeOptions, catmull_clark_operator
        >>> op = catmull_clark_operator([[0, 1, 2, 3]], 4, dtype=torch.float64,
        ...                             options=SchemeOptions(boundary="edge_and_corner"))
        >>> st = limit_stencils(op, torch.tensor([0]), torch.tensor([[0.5, 0.5]]))
        >>> st.positions.dense()
        tensor([[0.2500, 0.2500, 0.2500, 0.2500]], dtype=torch.float64)
    """
    _check_level(max_level)
    _check_points(operator, face_ids, uv)
    with torch.no_grad():
        return _build(operator, face_ids.reshape(-1).long(), uv.reshape(-1, 2),
                      SchemeOptions.check(options), max_level)


def _build(operator, face_ids, uv, options, max_level):
    V0, dtype = operator.num_vertices_in, operator.stencils.weights.dtype
    boundary = "edge_only" if operator.boundary == "none" else operator.boundary
    options = replace(options, boundary=boundary)
    st = operator.stencils
    faces = operator.faces if operator.child_faces is None else operator.child_faces
    tags = operator.child_tags if operator.child_tags is not None else SubdivisionTags.empty(
        dtype, faces.device)
    edge_tags = None if operator.child_faces is None else operator.child_edge_tags
    level = _Level(faces, operator.num_vertices_out, tags, (st.crow, st.col, st.weights),
                   edge_tags)
    face, s, t, jac = _ptex_to_level_one(operator, face_ids.to(faces.device), uv, dtype)
    sample = torch.arange(face.numel(), device=faces.device)
    loop = operator.scheme == "loop"
    out = []
    for depth in range(1, max_level + 1):  # a loop over levels
        if sample.numel() == 0:
            break
        topo = mesh_topology(level.faces, level.num_vertices, boundary, level.edge_tags)
        sharp_e, sharp_v, hole_f = effective_sharpness(
            topo, level.tags, level.num_vertices, level.faces.shape[0], boundary, dtype)
        if bool(hole_f[face].any()):
            i = int(sample[hole_f[face]][0])
            raise ValueError(f"face_ids: point {i} (ptex face {int(face_ids[i])}) is on a hole")
        twin = quad_twins(topo)
        if loop:
            regular = regular_triangles(topo, level.faces, sharp_e, sharp_v, hole_f, twin)[face]
        else:
            regular = regular_quads(topo, level.faces, sharp_e, sharp_v, hole_f)[face]
        points = (sample, face, s, t, jac)
        if bool(regular.any()):
            emit = _emit_triangles if loop else _emit_patches
            emit(out, level, topo, twin, sharp_e, *(x[regular] for x in points), V0)
        corner = ev_face_corners(topo, twin, level.faces, sharp_e, sharp_v,
                                 operator.scheme)[face]
        ev = ~regular & (corner >= 0)
        if bool(ev.any()):
            _emit_ev_patches(out, level, topo, twin, corner[ev], *(x[ev] for x in points), V0)
        rest = ~regular & ~ev
        if depth == max_level:
            if bool(rest.any()):
                _emit_end_caps(out, level, boundary, *(x[rest] for x in points), V0)
            break
        sample, face, s, t, jac = (x[rest] for x in points)
        if sample.numel() == 0:
            break
        level, fmap = _refine_around(level, torch.unique(face), options, dtype, V0)
        p, s, t, jac = _to_child(s, t, jac, operator.scheme)
        face = 4 * fmap[face] + p
    return LimitStencils(*assemble_limit_stencils(out, face_ids.numel(), V0, dtype,
                                                 faces.device))


def limit_surface(
    operator: SubdivisionOperator,
    verts: torch.Tensor,
    face_ids: torch.Tensor,
    uv: torch.Tensor,
    *,
    options: SchemeOptions = SchemeOptions(),
    max_level: int = 8,
) -> LimitSurfaceSample:
    """Positions, derivatives and normals of the Catmark or Loop limit surface at ptex points.

    Convention:
        See the module docstring: exact (positions and normals to rounding, normals
        continuous across edges) except within ``2**-max_level`` of irregular features
        other than isolated smooth extraordinary vertices. Builds :func:`limit_stencils`
        and applies them; to
        evaluate the same points on many shapes or steps, build the stencils once and
        use :func:`~torchgeo_cg.mesh.subdivision.stencils.apply_stencils`.

    Args:
        operator: a ``"catmark"`` or ``"loop"`` :class:`SubdivisionOperator` of the
            control mesh.
        verts: ``(*B, V0, D)`` float control points (shapes sharing the topology).
        face_ids: ``(*P, N)`` integer ptex face ids.
        uv: ``(*P, N, 2)`` float in ``[0, 1]`` (Loop: ``u + v <= 1``).
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions` the operator
            was built with; its crease method and triangle rule refine near irregular
            features (the operator records its own boundary, which is used).
        max_level: refinement levels at most (``>= 1``).

    Returns:
        :class:`LimitSurfaceSample` of ``(*B, *P, N, D)`` tensors (normals ``(*B, *P, N,
        3)`` or ``None`` when ``D != 3``), differentiable in ``verts``.

    Example:
        >>> from torchgeo_cg.mesh.subdivision import catmull_clark_operator
        >>> cube_v = torch.tensor([[x, y, z] for x in (0., 1.) for y in (0., 1.)
        ...                        for z in (0., 1.)], dtype=torch.float64)
        >>> cube_f = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6],
        ...           [0, 2, 6, 4], [1, 5, 7, 3]]
        >>> op = catmull_clark_operator(cube_f, 8, dtype=torch.float64)
        >>> out = limit_surface(op, cube_v, torch.tensor([0]), torch.tensor([[0.5, 0.5]]))
        >>> out.positions  # the middle of the face x = 0 (OpenSubdiv: 0.0802469...)
        tensor([[0.0802, 0.5000, 0.5000]], dtype=torch.float64)
        >>> out.normals.round(decimals=12) + 0.0
        tensor([[-1.,  0.,  0.]], dtype=torch.float64)
        >>> from torchgeo_cg.mesh.subdivision import loop_operator
        >>> octa_v = torch.tensor([[0., 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0],
        ...                        [0, 0, -1]], dtype=torch.float64)
        >>> octa_f = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [5, 2, 1], [5, 3, 2],
        ...           [5, 4, 3], [5, 1, 4]]
        >>> centre = torch.tensor([[1 / 3, 1 / 3]], dtype=torch.float64)  # of triangle 0
        >>> limit_surface(loop_operator(octa_f, 6, dtype=torch.float64), octa_v,
        ...               torch.tensor([0]), centre).positions
        tensor([[0.2352, 0.2352, 0.2352]], dtype=torch.float64)
    """
    _check_operator(operator)
    check_verts(verts, operator.num_vertices_in)
    st = limit_stencils(operator, face_ids, uv, options=options,
                        max_level=max_level)
    shape = (*verts.shape[:-2], *face_ids.shape, verts.shape[-1])
    pos, du, dv = (apply_stencils(m, verts).reshape(shape) for m in st)
    wdt = working_dtype(verts.dtype)  # half precision: the normals in float32, cast back
    normals = cast_back(unit_normals(du.to(wdt), dv.to(wdt)), verts.dtype) \
        if verts.shape[-1] == 3 else None
    return LimitSurfaceSample(pos, du, dv, normals)


def _num_ptex_faces(operator) -> int:
    if operator.scheme == "loop":
        return operator.num_faces_in
    child = operator.faces if operator.child_faces is None else operator.child_faces
    size = torch.bincount(child[:, 2] - operator.num_vertices_in,
                          minlength=operator.num_faces_in)
    return int(torch.where(size == 4, 1, size).sum())


def sample_limit_surface(
    operator: SubdivisionOperator,
    verts: torch.Tensor,
    num_samples: int,
    *,
    generator: torch.Generator | None = None,
    options: SchemeOptions = SchemeOptions(),
    max_level: int = 8,
) -> SurfaceSamples:
    """Points uniformly distributed by area on the Catmark or Loop limit surface, with normals.

    Convention:
        Each ptex face gets an area bound from ``|du x dv|`` on a 5 x 5 grid (times 1.5,
        a margin for the interior maximum; Loop: its 15 points with ``u + v <= 1``);
        candidates are drawn by that bound, uniform in ``uv`` (on the triangle for
        Loop), and kept with probability ``|du x dv| / bound`` (rejection sampling, a
        loop over rounds, not faces). With several shapes ``(*B, V0, D)``, the area is
        the first shape's, and the same ``(face_ids, uv)`` are evaluated on all of them.
        Differentiable in ``verts`` (the choice of points is not).

    Args:
        operator: a ``"catmark"`` or ``"loop"`` :class:`SubdivisionOperator` of the
            control mesh.
        verts: ``(*B, V0, 3)`` float control points.
        num_samples: ``N >= 0``.
        generator: the ``torch.Generator`` for the draws (``None``: the global one).
        options, max_level: as in :func:`limit_stencils`.

    Returns:
        :class:`SurfaceSamples`.

    Example:
        >>> from torchgeo_cg.mesh.subdivision import catmull_clark_operator
        >>> cube_v = torch.tensor([[x, y, z] for x in (0., 1.) for y in (0., 1.)
        ...                        for z in (0., 1.)], dtype=torch.float64)
        >>> cube_f = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6],
        ...           [0, 2, 6, 4], [1, 5, 7, 3]]
        >>> op = catmull_clark_operator(cube_f, 8, dtype=torch.float64)
        >>> out = sample_limit_surface(op, cube_v, 1000, generator=torch.Generator().manual_seed(0))
        >>> out.positions.shape, bool(((out.positions - 0.5).norm(dim=-1) < 0.5).all())
        (torch.Size([1000, 3]), True)
    """
    _check_operator(operator)
    check_verts(verts, operator.num_vertices_in)
    if isinstance(num_samples, bool) or not isinstance(num_samples, int) or num_samples < 0:
        raise ValueError(f"num_samples: expected an int >= 0, got {num_samples!r}")
    first = verts.detach().reshape(-1, *verts.shape[-2:])[0] if verts.numel() else verts
    device, dtype = verts.device, verts.dtype
    P = _num_ptex_faces(operator)
    grid = torch.linspace(0, 1, 5, dtype=dtype, device=device)
    uv_g = torch.stack(torch.meshgrid(grid, grid, indexing="ij"), -1).reshape(-1, 2)
    loop = operator.scheme == "loop"
    if loop:  # Loop's ptex faces are the triangles u + v <= 1
        uv_g = uv_g[uv_g.sum(-1) <= 1]
    faces_g = torch.arange(P, device=device).repeat_interleave(uv_g.shape[0])
    probe = limit_surface(operator, first, faces_g, uv_g.repeat(P, 1),
                          options=options, max_level=max_level)
    bound = 1.5 * torch.linalg.cross(probe.du, probe.dv).norm(dim=-1).reshape(P, -1).amax(1)
    chosen_f, chosen_uv = [], []
    have = 0
    while have < num_samples and float(bound.sum()) > 0:  # rounds of rejection sampling
        n = 2 * (num_samples - have) + 16
        f = torch.multinomial(bound, n, replacement=True, generator=generator)
        uv = torch.rand(n, 2, dtype=dtype, device=device, generator=generator)
        if loop:  # uniform on the triangle: fold the square's upper half onto the lower
            uv = torch.where(uv.sum(-1, keepdim=True) > 1, 1 - uv, uv)
        at = limit_surface(operator, first, f, uv, options=options,
                           max_level=max_level)
        area = torch.linalg.cross(at.du, at.dv).norm(dim=-1)
        keep = torch.rand(n, dtype=dtype, device=device, generator=generator) * bound[f] < area
        chosen_f.append(f[keep])
        chosen_uv.append(uv[keep])
        have += int(keep.sum())
    face_ids = torch.cat(chosen_f)[:num_samples] if chosen_f else torch.zeros(
        0, dtype=torch.long, device=device)
    uv = torch.cat(chosen_uv)[:num_samples] if chosen_uv else torch.zeros(
        0, 2, dtype=dtype, device=device)
    out = limit_surface(operator, verts, face_ids, uv, options=options,
                        max_level=max_level)
    return SurfaceSamples(out.positions, out.normals, face_ids, uv)
