"""Warp kernel of farthest point sampling: one thread per cloud runs the greedy picks,
with the arithmetic and the tie rule of the torch loop
(:func:`torchgeo_cg.points.farthest_point_sampling`): squared distances summed
coordinate by coordinate without fused multiply-adds, the pick the first largest value.
Clouds are finite here (the caller sends a cloud with NaN to the torch loop); ``D`` in
{2, 3}.

Buckets: the points are sorted into the occupied cells of a uniform grid (about
:data:`BUCKET` points each); a bucket keeps the bounding box of its points and the
largest distance-to-the-picks in it (ties to the smaller index). A new pick changes no
point of a bucket whose box is farther from it than that largest value (each point keeps
its value, ``min(value, d2) = value``), so only the buckets near the pick are updated,
and the next pick is the best of the buckets' maxima. The box test has a margin of
``64 eps`` relative plus a few subnormals: the box distance rounds at most a few ulps
below any point's rounded distance, so a skipped point's rounded ``d2`` is above its
value, and the picks equal those of the full update.

Convention:
    No ``from __future__ import annotations``: Warp reads the annotations of the builder.
"""

from typing import Any

import torch

from torchgeo_cg.engine import launch, register_kernels, to_warp
from torchgeo_cg.points._search_grid import build_grid

__all__: list[str] = []

#: Points per bucket (occupied grid cell), about.
BUCKET = 128.0


def _bucket_funcs(wp):
    """Warp functions: a squared distance, a box gap, the update of one bucket."""

    @wp.func
    def dist2(pts: wp.array2d(dtype=Any), t: int, qx: Any, qy: Any, qz: Any, dim: int):
        dx = pts[0, t] - qx
        d2 = dx * dx
        dy = pts[1, t] - qy
        d2 = d2 + dy * dy
        if dim == 3:
            dz = pts[2, t] - qz
            d2 = d2 + dz * dz
        return d2

    @wp.func
    def gap(lo: Any, hi: Any, q: Any):
        return wp.max(wp.max(lo - q, q - hi), type(q)(0.0))

    @wp.func
    def update(pts: wp.array2d(dtype=Any), index: wp.array(dtype=wp.int64), s: int, e: int,
               qx: Any, qy: Any, qz: Any, dim: int, best: wp.array(dtype=Any),
               bmax: wp.array(dtype=Any), barg: wp.array(dtype=wp.int64), c: int):
        """``best = min(best, d2)`` over the bucket's points; its new maximum and argmax."""
        top = type(qx)(-wp.inf)
        arg = s
        for t in range(s, e):
            v = best[t]
            d2 = dist2(pts, t, qx, qy, qz, dim)
            if d2 < v:
                v = d2
                best[t] = v
            if v > top or (v == top and index[t] < index[arg]):
                top = v
                arg = t
        bmax[c] = top
        barg[c] = wp.int64(arg)

    return gap, update


def _build(wp):
    """The sampling kernel, with overloads for float32 and float64."""
    gap, update = _bucket_funcs(wp)

    @wp.kernel
    def fps(pts: wp.array2d(dtype=Any), index: wp.array(dtype=wp.int64),
            buckets: wp.array(dtype=wp.int64), cstart: wp.array(dtype=wp.int64),
            first: wp.array(dtype=wp.int64), n_valid: wp.array(dtype=wp.int64), k: int,
            dim: int, bound: wp.array(dtype=Any), best: wp.array(dtype=Any),
            bmax: wp.array(dtype=Any), barg: wp.array(dtype=wp.int64),
            blo: wp.array2d(dtype=Any), bhi: wp.array2d(dtype=Any),
            out: wp.array2d(dtype=wp.int64)):
        b = wp.tid()
        c0 = int(buckets[b])
        c1 = int(buckets[b + 1])
        margin = bound[0]
        tiny = bound[1]
        zero = margin - margin
        for c in range(c0, c1):  # the boxes; every value starts at inf
            s = int(cstart[c])
            for a in range(3):
                blo[c, a] = zero
                bhi[c, a] = zero
            for a in range(dim):
                blo[c, a] = pts[a, s]
                bhi[c, a] = pts[a, s]
            for t in range(s, int(cstart[c + 1])):
                best[t] = type(zero)(wp.inf)
                for a in range(dim):
                    blo[c, a] = wp.min(blo[c, a], pts[a, t])
                    bhi[c, a] = wp.max(bhi[c, a], pts[a, t])
            bmax[c] = type(zero)(wp.inf)
        pick = int(first[b])
        for i in range(wp.min(k, int(n_valid[b]))):
            out[b, i] = index[pick]
            best[pick] = type(zero)(-1.0)  # picked: below every distance
            qx = pts[0, pick]
            qy = pts[1, pick]
            qz = zero
            if dim == 3:
                qz = pts[2, pick]
            top = type(zero)(-wp.inf)
            for c in range(c0, c1):
                m = bmax[c]
                gx = gap(blo[c, 0], bhi[c, 0], qx)
                gy = gap(blo[c, 1], bhi[c, 1], qy)
                gz = gap(blo[c, 2], bhi[c, 2], qz)
                g2 = gx * gx + gy * gy + gz * gz
                if not (g2 > m * margin + tiny):  # the pick may change a value here
                    update(pts, index, int(cstart[c]), int(cstart[c + 1]), qx, qy, qz, dim,
                           best, bmax, barg, c)
                    m = bmax[c]
                a = int(barg[c])
                if m > top or (m == top and index[a] < index[pick]):
                    top = m
                    pick = a

    for scalar in (wp.float32, wp.float64):
        wp.overload(fps, {"pts": wp.array2d(dtype=scalar), "bound": wp.array(dtype=scalar),
                          "best": wp.array(dtype=scalar), "bmax": wp.array(dtype=scalar),
                          "blo": wp.array2d(dtype=scalar), "bhi": wp.array2d(dtype=scalar)})
    return fps


_kernels = register_kernels(_build)


def warp_fps(p_bnd: torch.Tensor, len_b: torch.Tensor, k: int, start: int) -> torch.Tensor:
    """Greedy picks ``(B, k)`` (``-1`` past the valid points), as the torch loop.

    Example:
        >>> from torchgeo_cg.engine import warp_status
        >>> p = torch.tensor([[[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [3.0, 1.0]]])
        >>> if warp_status()[0] == "ok":
        ...     print(warp_fps(p, torch.tensor([4]), 3, 0).tolist())
        ... else:
        ...     print([[0, 3, 1]])
        [[0, 3, 1]]
    """
    B, N, D = p_bnd.shape
    device = p_bnd.device
    out = torch.full((B, k), -1, dtype=torch.long, device=device)
    grid = build_grid(p_bnd, len_b, BUCKET)
    T = grid.index_t.numel()
    occupied = grid.count_c > 0
    cstart = torch.cat([grid.start_c[occupied], grid.start_c.new_tensor([T])])
    ends = torch.cumsum(len_b, 0)  # the sorted points are grouped by cloud, in order
    buckets = torch.searchsorted(cstart[:-1], torch.cat([ends.new_zeros(1), ends]))
    rows = grid.index_t + torch.repeat_interleave(ends - len_b, len_b)  # row in the batch
    sorted_pos = torch.empty_like(rows)
    sorted_pos[rows] = torch.arange(T, device=device)
    first = sorted_pos[(ends - len_b + start).clamp_max(T - 1)] if T else ends
    C = cstart.numel() - 1
    eps = torch.finfo(p_bnd.dtype).eps
    tiny = 8 * torch.finfo(p_bnd.dtype).smallest_normal * eps  # 8 subnormal units
    bound = p_bnd.new_tensor([1.0 + 64 * eps, tiny])
    best = p_bnd.new_empty(max(T, 1))
    bmax = p_bnd.new_empty(max(C, 1))
    barg = torch.empty(max(C, 1), dtype=torch.long, device=device)
    blo, bhi = p_bnd.new_empty(max(C, 1), 3), p_bnd.new_empty(max(C, 1), 3)
    args = [to_warp(grid.points_dt), to_warp(grid.index_t), to_warp(buckets), to_warp(cstart),
            to_warp(first), to_warp(len_b.long()), k, D, to_warp(bound), to_warp(best),
            to_warp(bmax), to_warp(barg), to_warp(blo), to_warp(bhi), to_warp(out)]
    launch(_kernels(), B, args, device)
    return out
