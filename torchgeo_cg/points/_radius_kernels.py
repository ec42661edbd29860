"""Warp kernel of the radius search on a uniform grid of sorted cells (cell size about the
radius, :func:`~torchgeo_cg.points._search_grid.build_grid`).

One thread per query visits the cells that meet the box ``[q - r, q + r]`` and either
counts the references with ``|q - p|^2 <= r^2`` (pass 1) or keeps the ``K`` nearest of
them sorted by (squared distance, index) (pass 2). Squared distances are summed
coordinate by coordinate without fused multiply-adds, as the torch search does.

Convention:
    No ``from __future__ import annotations``: Warp reads the annotations of the builder.
"""

from typing import Any

import torch

from torchgeo_cg.engine import launch_rows, register_kernels, to_warp
from torchgeo_cg.points._grid_funcs import grid_funcs
from torchgeo_cg.points._search_grid import MAX_RING, GridIndex

__all__: list[str] = []


def _build(wp):
    """The radius kernel (count or collect), with overloads for float32 and float64."""
    funcs = grid_funcs()
    sq_dist, lookup, insert = funcs.sq_dist, funcs.lookup, funcs.insert

    @wp.func
    def cell_of(q: Any, lo: Any, h: Any, n: int) -> int:
        c = wp.floor((q - lo) / h)
        c = wp.clamp(c, type(q)(-1.0), type(q)(n))
        return wp.clamp(int(c), 0, n - 1)

    @wp.kernel
    def radius_grid(query: wp.array2d(dtype=Any), q_batch: wp.array(dtype=wp.int64),
                    radius2: wp.array(dtype=Any), radius: wp.array(dtype=Any),
                    pts: wp.array2d(dtype=Any), index: wp.array(dtype=wp.int64),
                    start: wp.array(dtype=wp.int64), count: wp.array(dtype=wp.int64),
                    keys: wp.array(dtype=wp.int64), sparse: int,
                    lo: wp.array2d(dtype=Any), h_b: wp.array(dtype=Any),
                    slack_b: wp.array(dtype=Any), dims: wp.array2d(dtype=wp.int64),
                    base: wp.array(dtype=wp.int64), stride: wp.array2d(dtype=wp.int64),
                    dim: int, slots: int, pad: int, rows: wp.array(dtype=wp.int64),
                    counts: wp.array(dtype=wp.int64), best: wp.array2d(dtype=Any),
                    best_i: wp.array2d(dtype=wp.int64)):
        row = int(rows[wp.tid()])  # the query (and output row) this thread answers
        b = int(q_batch[row])
        h = h_b[b]
        reach = radius[b] + slack_b[b]
        r2 = radius2[b]
        qx = query[row, 0]
        qy = query[row, 1]
        qz = qx - qx
        x0 = cell_of(qx - reach, lo[b, 0], h, int(dims[b, 0]))
        x1 = cell_of(qx + reach, lo[b, 0], h, int(dims[b, 0]))
        y0 = cell_of(qy - reach, lo[b, 1], h, int(dims[b, 1]))
        y1 = cell_of(qy + reach, lo[b, 1], h, int(dims[b, 1]))
        z0 = int(0)  # noqa: UP018  a dynamic variable for Warp
        z1 = int(0)  # noqa: UP018
        if dim == 3:
            qz = query[row, 2]
            z0 = cell_of(qz - reach, lo[b, 2], h, int(dims[b, 2]))
            z1 = cell_of(qz + reach, lo[b, 2], h, int(dims[b, 2]))
        n = int(0)  # noqa: UP018
        total = wp.int64(0)
        for x in range(x0, x1 + 1):
            for y in range(y0, y1 + 1):
                for z in range(z0, z1 + 1):
                    key = base[b] + wp.int64(x + pad) * stride[b, 0] + wp.int64(
                        y + pad) * stride[b, 1] + wp.int64(z + pad) * stride[b, 2]
                    c = lookup(keys, sparse, key)
                    if c < wp.int64(0):
                        continue
                    s = start[c]
                    for t in range(int(s), int(s + count[c])):
                        d2 = sq_dist(pts[0, t], pts[1, t], pts[dim - 1, t], qx, qy, qz, dim)
                        if d2 > r2:
                            continue
                        total = total + wp.int64(1)
                        if slots == 0:
                            continue
                        j = index[t]
                        if n == slots:
                            last = best[row, slots - 1]
                            if d2 > last or (d2 == last and j > best_i[row, slots - 1]):
                                continue
                            n = slots - 1
                        n = insert(best, best_i, row, n, d2, j)  # by (distance, index)
        counts[row] = total
        for t in range(n, slots):
            best_i[row, t] = wp.int64(-1)

    for scalar in (wp.float32, wp.float64):
        wp.overload(radius_grid, {
            "query": wp.array2d(dtype=scalar), "radius2": wp.array(dtype=scalar),
            "radius": wp.array(dtype=scalar), "pts": wp.array2d(dtype=scalar),
            "lo": wp.array2d(dtype=scalar), "h_b": wp.array(dtype=scalar),
            "slack_b": wp.array(dtype=scalar), "best": wp.array2d(dtype=scalar)})
    return radius_grid


_kernels = register_kernels(_build)


def warp_radius(grid: GridIndex, q_qd: torch.Tensor, b_q: torch.Tensor,
                radius_b: torch.Tensor, slots: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Counts ``(Q,)`` of references within ``radius_b[b_q]`` of each query (rows of batch
    item ``b_q``) and, for ``slots > 0``, the indices ``(Q, slots)`` of the nearest of them
    (``-1`` past the count).

    Example:
        >>> from torchgeo_cg.points._search_grid import build_grid
        >>> from torchgeo_cg.engine import warp_status
        >>> r = torch.tensor([[[1.0, 0.0], [3.0, 0.0], [-1.0, 0.0]]])
        >>> g = build_grid(r, torch.tensor([3]), 1.0, torch.tensor([1.5]))
        >>> q = torch.tensor([[0.0, 0.0], [2.9, 0.0]])
        >>> if warp_status()[0] == "ok":
        ...     c, i = warp_radius(g, q, torch.tensor([0, 0]), torch.tensor([1.5]), 2)
        ...     print(c.tolist(), i.tolist())
        ... else:
        ...     print([2, 1], [[0, 2], [1, -1]])
        [2, 1] [[0, 2], [1, -1]]
    """
    Q, D = q_qd.shape
    device = q_qd.device
    counts = torch.zeros(Q, dtype=torch.long, device=device)
    best = torch.empty(Q, slots, dtype=q_qd.dtype, device=device)
    best_i = torch.full((Q, slots), -1, dtype=torch.long, device=device)
    if Q == 0:
        return counts, best_i
    stride = torch.zeros(grid.stride_bd.shape[0], 3, dtype=torch.long, device=device)
    stride[:, :D] = grid.stride_bd
    dims = torch.ones_like(stride)
    dims[:, :D] = grid.dims_bd
    keys = grid.keys_c if grid.keys_c is not None else stride.new_zeros(1)
    radius_b = radius_b.to(q_qd.dtype)
    args = [to_warp(q_qd), to_warp(b_q.long()), to_warp(radius_b * radius_b),
            to_warp(radius_b), to_warp(grid.points_dt), to_warp(grid.index_t.long()),
            to_warp(grid.start_c.long()), to_warp(grid.count_c.long()), to_warp(keys),
            int(grid.keys_c is not None), to_warp(grid.lo_bd), to_warp(grid.h_b),
            to_warp(grid.slack_b), to_warp(dims), to_warp(grid.base_b.long()),
            to_warp(stride), D, slots, MAX_RING, None, to_warp(counts), to_warp(best),
            to_warp(best_i)]
    rows = torch.arange(Q, device=device)
    launch_rows(_kernels(), rows, args, len(args) - 4, device)  # on torch's CPU threads
    return counts, best_i
