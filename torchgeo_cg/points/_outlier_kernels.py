"""Warp kernel of the radius outlier test on a uniform grid of sorted cells (cell size
:data:`CELL` radii, :func:`~torchgeo_cg.points._search_grid.build_grid`).

One thread per point counts the points strictly within the radius (``d2 < r^2``, itself
included) and stops as soon as it has seen ``need`` of them; it returns 1 (inlier) or 0.
It scans the point's own cell first, then the other cells that meet the box
``[q - r, q + r]`` (widened by the grid's rounding margin). The squared distances are
summed coordinate by coordinate without fused multiply-adds, in the coordinates the
torch path decides on, so ``count >= need`` holds exactly when the torch path's
``need``-th nearest distance is below ``r^2``.

Convention:
    No ``from __future__ import annotations``: Warp reads the annotations of the builder.
"""

from typing import Any

import torch

from torchgeo_cg.engine import launch_rows, register_kernels, to_warp
from torchgeo_cg.points._grid_funcs import grid_funcs
from torchgeo_cg.points._search_grid import MAX_RING, build_grid

__all__: list[str] = []

#: Cell size of the grid, in radii (a larger cell: fewer cells to visit, and most points
#: find enough neighbours in their own cell).
CELL = 1.4


def _cell_funcs(wp):
    """Warp functions: the cells a point's box meets, the count of one cell."""
    funcs = grid_funcs()
    sq_dist, lookup = funcs.sq_dist, funcs.lookup

    @wp.func
    def cell_of(q: Any, lo: Any, h: Any, n: int) -> int:
        c = wp.floor((q - lo) / h)
        c = wp.clamp(c, type(q)(-1.0), type(q)(n))
        return wp.clamp(int(c), 0, n - 1)

    @wp.func
    def count_cell(pts: wp.array2d(dtype=Any), start: wp.array(dtype=wp.int64),
                   count: wp.array(dtype=wp.int64), keys: wp.array(dtype=wp.int64),
                   sparse: int, key: wp.int64, qx: Any, qy: Any, qz: Any, dim: int, r2: Any,
                   n: int, need: int) -> int:
        """``n`` plus the points of cell ``key`` strictly within the radius, up to ``need``."""
        c = lookup(keys, sparse, key)
        total = n
        if c >= wp.int64(0):
            s = int(start[c])
            for t in range(s, s + int(count[c])):
                d2 = sq_dist(pts[0, t], pts[1, t], pts[dim - 1, t], qx, qy, qz, dim)
                if d2 < r2:
                    total = total + 1
                    if total >= need:
                        break
        return total

    @wp.func
    def span(q: Any, w: Any, lo: Any, h: Any, n: int) -> wp.vec3i:
        """The point's cell and the first and last cells meeting ``[q - w, q + w]``."""
        return wp.vec3i(cell_of(q, lo, h, n), cell_of(q - w, lo, h, n), cell_of(q + w, lo, h, n))

    return count_cell, span


def _build(wp):
    """The counting kernel, with overloads for float32 and float64."""
    count_cell, span = _cell_funcs(wp)

    @wp.kernel
    def radius_inliers(query: wp.array2d(dtype=Any), q_batch: wp.array(dtype=wp.int64),
                       radius2: wp.array(dtype=Any), reach: wp.array(dtype=Any),
                       pts: wp.array2d(dtype=Any), start: wp.array(dtype=wp.int64),
                       count: wp.array(dtype=wp.int64), keys: wp.array(dtype=wp.int64),
                       sparse: int, lo: wp.array2d(dtype=Any), h_b: wp.array(dtype=Any),
                       dims: wp.array2d(dtype=wp.int64), base: wp.array(dtype=wp.int64),
                       stride: wp.array2d(dtype=wp.int64), dim: int, need: int, pad: int,
                       rows: wp.array(dtype=wp.int64), out: wp.array(dtype=wp.int8)):
        row = int(rows[wp.tid()])  # the point (and output row) this thread answers
        b = int(q_batch[row])
        h = h_b[b]
        w = reach[b]
        r2 = radius2[b]
        qx = query[row, 0]
        qy = query[row, 1]
        qz = qx - qx
        sx = span(qx, w, lo[b, 0], h, int(dims[b, 0]))
        sy = span(qy, w, lo[b, 1], h, int(dims[b, 1]))
        sz = wp.vec3i(0, 0, 0)
        if dim == 3:
            qz = query[row, 2]
            sz = span(qz, w, lo[b, 2], h, int(dims[b, 2]))
        key0 = base[b] + wp.int64(pad) * (stride[b, 0] + stride[b, 1] + stride[b, 2])
        key = key0 + wp.int64(sx[0]) * stride[b, 0] + wp.int64(sy[0]) * stride[b, 1] + (
            wp.int64(sz[0]) * stride[b, 2])
        n = count_cell(pts, start, count, keys, sparse, key, qx, qy, qz, dim, r2, 0, need)
        for x in range(sx[1], sx[2] + 1):  # then the other cells, until enough are found
            for y in range(sy[1], sy[2] + 1):
                for z in range(sz[1], sz[2] + 1):
                    if n < need and (x != sx[0] or y != sy[0] or z != sz[0]):
                        key = key0 + wp.int64(x) * stride[b, 0] + wp.int64(y) * stride[
                            b, 1] + wp.int64(z) * stride[b, 2]
                        n = count_cell(pts, start, count, keys, sparse, key, qx, qy, qz, dim,
                                       r2, n, need)
        out[row] = wp.int8(n >= need)

    for scalar in (wp.float32, wp.float64):
        wp.overload(radius_inliers, {
            "query": wp.array2d(dtype=scalar), "radius2": wp.array(dtype=scalar),
            "reach": wp.array(dtype=scalar), "pts": wp.array2d(dtype=scalar),
            "lo": wp.array2d(dtype=scalar), "h_b": wp.array(dtype=scalar)})
    return radius_inliers


_kernels = register_kernels(_build)


def warp_radius_inliers(p_bnd: torch.Tensor, ok_bn: torch.Tensor, packed_bmd: torch.Tensor,
                        count_b: torch.Tensor, radius: float, need: int) -> torch.Tensor:
    """Mask ``(B, N)``: the points ``ok_bn`` of ``p_bnd`` with at least ``need`` of the
    ``count_b`` points ``packed_bmd`` strictly within ``radius`` (``d2 < radius * radius``).

    Example:
        >>> from torchgeo_cg.engine import warp_status
        >>> p = torch.tensor([[[0.0, 0.0], [0.5, 0.0], [3.0, 0.0]]], dtype=torch.float64)
        >>> ok = torch.ones(1, 3, dtype=torch.bool)
        >>> if warp_status()[0] == "ok":
        ...     print(warp_radius_inliers(p, ok, p, torch.tensor([3]), 1.0, 2).tolist())
        ... else:
        ...     print([[True, True, False]])
        [[True, True, False]]
    """
    B, N, D = p_bnd.shape
    device = p_bnd.device
    qb, qn = ok_bn.nonzero(as_tuple=True)
    out = torch.zeros(qb.numel(), dtype=torch.int8, device=device)
    grid = build_grid(packed_bmd, count_b, 1.0, p_bnd.new_full((B,), CELL * radius))
    stride = torch.zeros(B, 3, dtype=torch.long, device=device)
    stride[:, :D] = grid.stride_bd
    dims = torch.ones_like(stride)
    dims[:, :D] = grid.dims_bd
    keys = grid.keys_c if grid.keys_c is not None else stride.new_zeros(1)
    r2_b = p_bnd.new_full((B,), radius * radius)
    args = [to_warp(p_bnd[qb, qn]), to_warp(qb), to_warp(r2_b), to_warp(grid.slack_b + radius),
            to_warp(grid.points_dt), to_warp(grid.start_c), to_warp(grid.count_c),
            to_warp(keys), int(grid.keys_c is not None), to_warp(grid.lo_bd), to_warp(grid.h_b),
            to_warp(dims), to_warp(grid.base_b), to_warp(stride), D, need, MAX_RING,
            None, to_warp(out)]
    rows = torch.arange(qb.numel(), device=device)
    launch_rows(_kernels(), rows, args, len(args) - 2, device)  # on torch's CPU threads
    mask = torch.zeros(B, N, dtype=torch.bool, device=device)
    mask[qb, qn] = out.bool()
    return mask
