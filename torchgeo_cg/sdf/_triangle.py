"""Triangle geometry shared by the mesh distance, both searches and the Warp engine.

One place for the formulas on a single triangle and on a triangle mesh's features:

- :func:`closest_point_on_triangle`: the exact closest point and its feature (face,
  edge or vertex), differentiable; the Warp kernel evaluates the same operations in
  float64 (:mod:`~torchgeo_cg.sdf._engine_warp`);
- :func:`face_table` and :func:`pair_d2`: the same distance, squared, from per-face
  constants precomputed once (the float64 torch search and brute-force checks);
- :func:`pseudo_normals`: the angle-weighted pseudo-normals of every feature
  (Baerentzen & Aanaes 2005), signing the distance on watertight meshes;
- :func:`solid_angles_sum`: the signed solid angles (Van Oosterom & Strackee 1983) of
  the generalized winding number (Jacobson et al. 2013).

Convention:
    Triangles are ``(v0, v1, v2)`` wound counter-clockwise seen from outside (unit
    normal along ``(v1 - v0) x (v2 - v0)``, zero for degenerate triangles). Feature
    codes are those of :data:`FEATURES`. Callers scale coordinates by a power of two
    (:func:`~torchgeo_cg.core.numerics.power_of_two_scale`) so no product overflows.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import check_same_dtype
from torchgeo_cg.core.numerics import cast_back, power_of_two_scale, working_dtype

__all__ = [
    "FEATURES",
    "TriangleClosestPoint",
    "closest_point_on_triangle",
    "closest_on_segment",
    "dot3",
    "unit_normals",
    "pseudo_normals",
    "solid_angles_sum",
    "face_table",
    "gather_rows",
    "pair_d2",
]


#: Feature codes of :func:`closest_point_on_triangle`: the closest point lies on
#: 0 the face interior, 1 edge v0v1, 2 edge v1v2, 3 edge v2v0, 4 vertex v0, 5 v1, 6 v2.
FEATURES = ("face", "edge01", "edge12", "edge20", "vertex0", "vertex1", "vertex2")


class TriangleClosestPoint(NamedTuple):
    """Closest point on a triangle and the feature it lies on.

    Attributes:
        points: ``(*, 3)`` closest points.
        feature: ``(*,)`` long codes: 0 interior, 1-3 edges v0v1/v1v2/v2v0, 4-6 vertices.
    """

    points: torch.Tensor
    feature: torch.Tensor


def dot3(a, b):
    """Dot product of two 3-vectors given as component lists (structure of arrays)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def closest_on_segment(p, a, b):
    """Closest point on segment ab (component lists): (point, t in [0, 1], detached
    squared distance); zero-length safe."""
    ab = [y - x for x, y in zip(a, b)]
    den = dot3(ab, ab)
    ok = den > 0
    t = torch.where(ok, dot3([y - x for x, y in zip(a, p)], ab)
                    / torch.where(ok, den, torch.ones_like(den)), 0.0).clamp(0.0, 1.0)
    q = [x + t * y for x, y in zip(a, ab)]
    with torch.no_grad():
        diff = [x - y for x, y in zip(p, q)]
        return q, t, dot3(diff, diff)


def closest_point_on_triangle(
    points: torch.Tensor, v0: torch.Tensor, v1: torch.Tensor, v2: torch.Tensor
) -> TriangleClosestPoint:
    """Exact closest point on triangle ``(v0, v1, v2)`` to each point, and its feature.

    The candidates are the projection onto the plane (when it falls inside the
    triangle) and the closest points of the three edges; the nearest wins, the face
    first on ties. Degenerate triangles fall back to their edges, so there is no
    division by a zero area.

    Convention:
        All arguments broadcast and share one float dtype (a ``TypeError`` naming two
        otherwise); feature codes as in :data:`FEATURES` (0 face, 1-3 edges v0v1, v1v2,
        v2v0, 4-6 vertices). Differentiable almost everywhere w.r.t. all inputs, with
        finite gradients. Scale-free: computed relative to ``v0`` and divided by a power
        of two per element, so no intermediate overflows at any finite scale.
        float16/bfloat16 are computed in float32 and returned in the input dtype.

    Args:
        points: ``(*, 3)``.
        v0, v1, v2: ``(*, 3)`` triangle corners.

    Returns:
        :class:`TriangleClosestPoint` ``(points (*, 3), feature (*,))``.

    Example:
        >>> tri = torch.eye(3)
        >>> r = closest_point_on_triangle(torch.tensor([[1.0, 1.0, 1.0], [2.0, -1.0, -1.0]]),
        ...                               tri[0], tri[1], tri[2])
        >>> r.points, r.feature
        (tensor([[0.3333, 0.3333, 0.3333],
                [1.0000, 0.0000, 0.0000]]), tensor([0, 4]))
    """
    named = {"points": points, "v0": v0, "v1": v1, "v2": v2}
    for name, x in named.items():
        check_float(x, name)
        check_shape(x, ["*", "3"], name)
    dtype = check_same_dtype(named).dtype
    shape = tuple(check_broadcastable({k: x.shape[:-1] for k, x in named.items()})) + (3,)
    # relative to v0 and divided by a power of two (exact, detached) per element, so that
    # no product (up to 4th powers of lengths) overflows or underflows at any scale;
    # float16/bfloat16 are computed in float32
    origin = v0.to(working_dtype(dtype))
    rel = [x.to(origin.dtype) - origin for x in (points, v1, v2)]
    big = torch.maximum(torch.maximum(rel[0].detach().abs().amax(-1),
                                      rel[1].detach().abs().amax(-1)),
                        rel[2].detach().abs().amax(-1))
    scale = power_of_two_scale(big)[..., None]
    rel = [x / scale for x in rel]
    p, a, b, c = (x.movedim(-1, 0).contiguous().unbind(0)  # structure of arrays
                  for x in (rel[0], torch.zeros_like(origin), rel[1], rel[2]))
    e0, e1 = [y - x for x, y in zip(a, b)], [y - x for x, y in zip(a, c)]
    w = [y - x for x, y in zip(a, p)]
    d00, d01, d11 = dot3(e0, e0), dot3(e0, e1), dot3(e1, e1)
    dot0, dot1 = dot3(w, e0), dot3(w, e1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-12 * d00 * d11
    den_safe = torch.where(ok, den, torch.ones_like(den))
    bv = (d11 * dot0 - d01 * dot1) / den_safe  # barycentric weight of v1
    bw = (d00 * dot1 - d01 * dot0) / den_safe  # barycentric weight of v2
    q = [x + bv * y + bw * z for x, y, z in zip(a, e0, e1)]
    with torch.no_grad():
        inside = ok & (bv >= 0) & (bw >= 0) & (bv + bw <= 1)
        diff = [x - y for x, y in zip(p, q)]
        best_d2 = torch.where(inside, dot3(diff, diff), math.inf)
        code = torch.zeros(best_d2.shape, dtype=torch.long, device=best_d2.device)
        t_best = torch.zeros_like(best_d2)
    # the nearest candidate wins: face first, then edges v0v1, v1v2, v2v0 on ties
    edges = [closest_on_segment(p, u, v) for u, v in ((a, b), (b, c), (c, a))]
    vertex_only = _defer_vertices([t.detach() for _, t, _ in edges])
    for k, ((q_k, t_k, d2_k), defer) in enumerate(zip(edges, vertex_only), start=1):
        better = (d2_k < best_d2) & ~inside & ~defer
        best_d2 = torch.where(better, d2_k, best_d2)
        code = torch.where(better, k, code)
        t_best = torch.where(better, t_k.detach(), t_best)
        q = [torch.where(better, y, x) for x, y in zip(q, q_k)]
    edge = (code - 1).clamp_min(0)
    start, end = (torch.tensor(x, device=code.device)[edge] for x in ([4, 5, 6], [5, 6, 4]))
    feature = torch.where(t_best <= 0, start, torch.where(t_best >= 1, end, code))
    feature = torch.where(code == 0, 0, feature).expand(shape[:-1])
    q = torch.stack(torch.broadcast_tensors(*q), dim=-1) * scale + origin
    # a NaN corner loses every comparison, so the nearest finite edge would win: NaN in
    # any argument gives a NaN closest point instead
    nan = torch.zeros((), dtype=torch.bool, device=q.device)
    for x in named.values():
        nan = nan | x.isnan().any(-1)
    q = torch.where(nan[..., None], math.nan, q)
    return TriangleClosestPoint(cast_back(q.expand(shape), dtype), feature)


def _defer_vertices(t: list[torch.Tensor]) -> list[torch.Tensor]:
    """Per edge (v0v1, v1v2, v2v0), where its candidate is clamped to a corner that the
    other edge at that corner does not clamp to.

    The distances alone cannot choose there: the other edge's candidate is at least as
    near (the corner lies on it) and nearer by only the square of their gap, which
    rounding hides, so picking by distance would move the point by up to
    ``sqrt(eps) x distance``. Such a candidate defers to the other edge; the clamps are
    first-order tests. Likewise the face, where the projection is inside, beats every
    edge. (A degenerate triangle can make every edge defer; then none does.)
    """
    start, end = [x <= 0 for x in t], [x >= 1 for x in t]
    defer = [(start[k] & ~end[k - 1]) | (end[k] & ~start[(k + 1) % 3]) for k in range(3)]
    every = defer[0] & defer[1] & defer[2]
    return [d & ~every for d in defer]


def unit_normals(tri: torch.Tensor) -> torch.Tensor:
    """Unit normals ``(..., 3)`` of triangles ``(..., 3, 3)``, zero for degenerate ones; the
    norm is guarded only where it is exactly zero (coordinates are pre-scaled)."""
    v0, v1, v2 = tri.unbind(-2)
    n = torch.cross(v1 - v0, v2 - v0, dim=-1)
    length = torch.linalg.vector_norm(n, dim=-1, keepdim=True)
    good = length > 0
    return torch.where(good, n / torch.where(good, length, torch.ones_like(length)), 0.0)


def pseudo_normals(tri_bt33: torch.Tensor, tris_t3: torch.Tensor, num_vertices: int
                   ) -> torch.Tensor:
    """Per face, the 7 feature pseudo-normals (face, 3 edges, 3 vertices): ``(B, T, 7, 3)``.

    Edges: the sum of the unit normals of the faces sharing the undirected edge; vertices:
    the angle-weighted sum of the incident unit normals (Baerentzen & Aanaes 2005).

    Args:
        tri_bt33: ``(B, T, 3, 3)`` triangle corners.
        tris_t3: ``(T, 3)`` long vertex indices.
        num_vertices: ``V``.

    Example:
        >>> tet = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        >>> pseudo_normals(verts[tet][None], tet, 4)[0, 0, 0]
        tensor([ 0.,  0., -1.])
    """
    B, T = tri_bt33.shape[:2]
    unit = unit_normals(tri_bt33)  # (B, T, 3)
    a, b = tris_t3.reshape(-1), tris_t3[:, [1, 2, 0]].reshape(-1)
    key = torch.minimum(a, b) * num_vertices + torch.maximum(a, b)
    _, inverse = torch.unique(key, return_inverse=True)
    per_edge = unit.new_zeros(B, int(inverse.max()) + 1, 3).index_add(
        1, inverse, unit.repeat_interleave(3, dim=1))
    edge_n = per_edge[:, inverse].reshape(B, T, 3, 3)
    nxt, prv = tri_bt33[..., [1, 2, 0], :], tri_bt33[..., [2, 0, 1], :]
    u, w = nxt - tri_bt33, prv - tri_bt33
    angle = torch.atan2(torch.linalg.vector_norm(torch.cross(u, w, dim=-1), dim=-1),
                        (u * w).sum(-1))  # (B, T, 3)
    per_vertex = unit.new_zeros(B, num_vertices, 3).index_add(
        1, tris_t3.reshape(-1), (angle[..., None] * unit[..., None, :]).reshape(B, -1, 3))
    vert_n = per_vertex[:, tris_t3]  # (B, T, 3, 3)
    return torch.cat([unit[:, :, None], edge_n, vert_n], dim=2)


def solid_angles_sum(tri_bf33: torch.Tensor, points_bn3: torch.Tensor,
                      chunk_pairs: int) -> torch.Tensor:
    """Sum over faces of the signed solid angle, chunked over points: ``(B, N)``."""
    B, F = tri_bf33.shape[:2]
    N = points_bn3.shape[1]
    step = max(1, chunk_pairs // max(1, B * F))
    out = [points_bn3.new_zeros(B, 0)]
    for s in range(0, N, step):
        p = points_bn3[:, s:s + step, None]  # (B, m, 1, 3)
        a = tri_bf33[:, None, :, 0] - p  # (B, m, F, 3)
        b = tri_bf33[:, None, :, 1] - p
        c = tri_bf33[:, None, :, 2] - p
        la, lb, lc = a.norm(dim=-1), b.norm(dim=-1), c.norm(dim=-1)
        det = (a * torch.cross(b, c, dim=-1)).sum(-1)
        den = la * lb * lc + (a * b).sum(-1) * lc + (a * c).sum(-1) * lb + (b * c).sum(-1) * la
        out.append(2.0 * torch.atan2(det, den).sum(-1))
    return torch.cat(out, dim=1)


def face_table(tri_f33: torch.Tensor) -> torch.Tensor:
    """Per-face constants for the float64 search, one row each: ``(24, F)``.

    Rows: v0 (0-2), e0 = v1 - v0 (3-5), e1 = v2 - v0 (6-8), unit normal (9-11, zero if
    degenerate), d00, d01, d11 (12-14), 1/den, 1/d00, 1/d11, 1/d22 (15-18, zero where
    the denominator vanishes), d22 (19), centroid (20-22), bounding radius (23); with
    ``dij = ei . ej``, ``e2 = v2 - v1``, ``den = d00 d11 - d01^2``. Rows (structure of
    arrays) make every per-pair operation a contiguous 1-D kernel.

    Args:
        tri_f33: ``(F, 3, 3)`` triangle corners.

    Returns:
        ``(24, F)`` table.

    Example:
        >>> face_table(torch.eye(3)[None]).shape
        torch.Size([24, 1])
    """
    v0, v1, v2 = tri_f33.unbind(1)
    e0, e1, e2 = v1 - v0, v2 - v0, v2 - v1
    d00, d01, d11, d22 = (e0 * e0).sum(-1), (e0 * e1).sum(-1), (e1 * e1).sum(-1), (e2 * e2).sum(-1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-12 * d00 * d11

    def inv(x, good):
        return torch.where(good, 1.0 / torch.where(good, x, torch.ones_like(x)),
                           torch.zeros_like(x))

    n = torch.cross(e0, e1, dim=-1)
    length = n.norm(dim=-1, keepdim=True)
    unit = torch.where(ok.unsqueeze(-1), n / torch.where(length > 0, length, 1.0), 0.0)
    centroid = tri_f33.mean(1)
    radius = (tri_f33 - centroid[:, None]).norm(dim=-1).amax(-1)
    cols = [v0, e0, e1, unit,
            torch.stack([d00, d01, d11, inv(den, ok), inv(d00, d00 > 0), inv(d11, d11 > 0),
                         inv(d22, d22 > 0), d22], dim=-1),
            centroid, radius[:, None]]
    return torch.cat(cols, dim=-1).t().contiguous()


def gather_rows(table: torch.Tensor, index: torch.Tensor, rows) -> list[torch.Tensor]:
    """``[table[k, index] for k in rows]``: one 1-D gather per row (a fixed handful), about
    twice as fast as ``index_select`` along dim 1 of the 2-D table."""
    return [table[k].index_select(0, index) for k in rows]


def pair_d2(table: torch.Tensor, p_3m: torch.Tensor, f_m: torch.Tensor) -> torch.Tensor:
    """Squared point-triangle distances of pairs: points ``p_3m (3, M)`` (rows x, y, z) and
    faces ``f_m (M,)`` (columns of :func:`face_table`); returns ``(M,)``.

    Example:
        >>> t = face_table(torch.eye(3, dtype=torch.float64)[None])
        >>> pair_d2(t, torch.tensor([[0.0], [0.0], [0.0]], dtype=torch.float64),
        ...         torch.tensor([0]))
        tensor([0.3333], dtype=torch.float64)
    """
    g = gather_rows(table, f_m, range(20))
    wx, wy, wz = p_3m[0] - g[0], p_3m[1] - g[1], p_3m[2] - g[2]
    dot0 = wx * g[3] + wy * g[4] + wz * g[5]
    dot1 = wx * g[6] + wy * g[7] + wz * g[8]
    ww = wx * wx + wy * wy + wz * wz
    plane = (wx * g[9] + wy * g[10] + wz * g[11]).square()
    d00, d01, d11, inv_den, inv00, inv11, inv22, d22 = g[12:20]
    bv = (d11 * dot0 - d01 * dot1) * inv_den
    bw = (d00 * dot1 - d01 * dot0) * inv_den
    inside = (inv_den > 0) & (bv >= 0) & (bw >= 0) & (bv + bw <= 1)
    t = (dot0 * inv00).clamp(0.0, 1.0)
    best = ww - t * (2.0 * dot0 - t * d00)
    t = (dot1 * inv11).clamp(0.0, 1.0)
    best = torch.minimum(best, ww - t * (2.0 * dot1 - t * d11))
    wb_e2 = dot1 - dot0 - d01 + d00  # (w - e0) . (e1 - e0)
    wb2 = ww - 2.0 * dot0 + d00  # |w - e0|^2
    t = (wb_e2 * inv22).clamp(0.0, 1.0)
    best = torch.minimum(best, wb2 - t * (2.0 * wb_e2 - t * d22))
    return torch.where(inside, plane, best).clamp_min(0.0)
