"""Warp kernel of the exact k-nearest-neighbour search on a uniform grid of sorted cells.

The grid is the torch search's (:func:`~torchgeo_cg.points._search_grid.build_grid`: the
references binned by cell, sorted by cell key, a dense or sparse table of cell starts);
one thread per query scans Chebyshev rings of cells around the query's cell (in each
ring the cells nearer the query first), skips cells whose box lies farther than its
current k-th distance, and keeps a sorted top-k by (squared distance, index). It stops
once the k-th distance is below the distance to any unvisited cell (shrunk by the grid's
rounding margin), or once the rings cover the grid. For ``k > 1`` the queries run in the
order of their cells. Squared distances are summed coordinate by coordinate in the input
dtype without fused multiply-adds, as the torch search does, so both rank (and tie)
identically.

Queries that need more than ``max_ring`` rings (far from every reference) are left to the
caller (flag ``-2``); the torch search finishes them.

Convention:
    No ``from __future__ import annotations``: Warp reads the annotations of the builder.
"""

from typing import Any

import torch

from torchgeo_cg.engine import launch_rows, register_kernels, to_warp
from torchgeo_cg.points._grid_funcs import grid_funcs
from torchgeo_cg.points._search_grid import (
    MAX_RING,
    GridIndex,
    build_grid,
    grid_knn_indices,
)

__all__: list[str] = []

#: Rings a kernel thread scans before it leaves its query to the torch search.
KERNEL_RINGS = 24
#: References per occupied cell of the kernel's grid, at least: coarser than the torch
#: search's for small k (a thread pays per cell visited, the torch search per candidate).
KERNEL_PER_CELL = 8.0
#: Rings a thread scans on a level before it leaves its query to the next, coarser one:
#: a query far from every reference crosses many empty fine cells.
LEVEL_RINGS = 1
#: References per occupied cell, from one level to the next.
LEVEL_FACTOR = 8.0


def kernel_grids(reference_bmd: torch.Tensor, reference_lengths_b: torch.Tensor, k: int,
                 levels: int = 1) -> list[GridIndex]:
    """The kernel's grids of the references for ``k`` neighbours, finest first: level
    ``i`` holds :data:`LEVEL_FACTOR` ``** i`` times as many references per cell.

    Example:
        >>> grids = kernel_grids(torch.rand(1, 4000, 3), torch.tensor([4000]), 1, levels=2)
        >>> bool(grids[1].h_b[0] > grids[0].h_b[0])
        True
    """
    per_cell = kernel_per_cell(k)
    return [build_grid(reference_bmd, reference_lengths_b, per_cell * LEVEL_FACTOR ** i)
            for i in range(levels)]  # loop over levels


def kernel_per_cell(k: int) -> float:
    """Target references per occupied cell of the kernel's grid for ``k`` neighbours.

    About ``0.6 (k + 1)``, at least :data:`KERNEL_PER_CELL`: finer cells than the torch
    search's for larger k (a thread inserts fewer candidates into its top-k).

    Example:
        >>> kernel_per_cell(1), kernel_per_cell(20)
        (8.0, 12.6)
    """
    return max(KERNEL_PER_CELL, 0.6 * (k + 1))


def _ring_funcs(wp):
    """Warp functions: the cell scan of one grid cell into a running top-k."""
    funcs = grid_funcs()
    sq_dist, insert = funcs.sq_dist, funcs.insert

    @wp.func
    def scan_cell(pts: wp.array2d(dtype=Any), index: wp.array(dtype=wp.int64),
                  start: wp.int64, count: wp.int64, qx: Any, qy: Any, qz: Any, dim: int,
                  row: int, k: int, found: int, best: wp.array2d(dtype=Any),
                  best_i: wp.array2d(dtype=wp.int64)):
        """Merge the references ``start .. start + count`` into row ``row``'s top-k;
        returns the new number found."""
        n = found
        kth = best[row, k - 1]  # read only once n == k
        for t in range(int(start), int(start + count)):
            d2 = sq_dist(pts[0, t], pts[1, t], pts[dim - 1, t], qx, qy, qz, dim)
            if n == k and d2 > kth:
                continue
            j = index[t]
            if n == k:
                if d2 == kth and j > best_i[row, k - 1]:
                    continue
                n = k - 1
            n = insert(best, best_i, row, n, d2, j)  # sorted by (distance, index)
            if n == k:
                kth = best[row, k - 1]
        return n

    return scan_cell


def _cell_funcs(wp):
    """Warp functions: cells of a query, their gaps, the near-first order."""

    @wp.func
    def cell_of(q: Any, lo: Any, h: Any) -> int:
        c = wp.floor((q - lo) / h)
        c = wp.clamp(c, type(q)(-1.0e9), type(q)(1.0e9))
        return int(c)

    @wp.func
    def gap(q: Any, lo: Any, h: Any, c: int, slack: Any):
        """Distance from ``q`` to cell ``c``'s slab along one axis, less ``slack``."""
        a = lo + type(q)(c) * h
        g = wp.max(wp.max(a - q, q - (a + h)), type(q)(0.0))
        return wp.max(g - slack, type(q)(0.0))

    @wp.func
    def wall_of(q: Any, lo: Any, h: Any, c: int):
        """Distance from ``q`` to the nearer wall of cell ``c`` along one axis."""
        a = lo + type(h)(c) * h
        return wp.min(q - a, a + h - q)

    @wp.func
    def side(q: Any, lo: Any, h: Any, c: int) -> int:
        """+1 when ``q`` lies in the upper half of cell ``c`` along one axis, else -1."""
        a = lo + type(h)(c) * h
        if q - a >= a + h - q:
            return 1
        return -1

    @wp.func
    def near(c: int, i: int, s: int) -> int:
        """The ``i``-th cell of the sequence ``c, c + s, c - s, c + 2s, c - 2s, ...``."""
        m = (i + 1) // 2
        if i % 2 == 1:
            return c + m * s
        return c - m * s

    return cell_of, gap, wall_of, side, near


def _build(wp):
    """The kNN kernel, with overloads for float32 and float64."""
    scan_cell = _ring_funcs(wp)
    cell_of, gap, wall_of, side, near = _cell_funcs(wp)
    sq_dist, lookup = grid_funcs().sq_dist, grid_funcs().lookup

    @wp.kernel
    def knn_grid(query: wp.array2d(dtype=Any), q_batch: wp.array(dtype=wp.int64),
                 pts: wp.array2d(dtype=Any), index: wp.array(dtype=wp.int64),
                 start: wp.array(dtype=wp.int64), count: wp.array(dtype=wp.int64),
                 keys: wp.array(dtype=wp.int64), sparse: int,
                 lo: wp.array2d(dtype=Any), h_b: wp.array(dtype=Any),
                 slack_b: wp.array(dtype=Any), dims: wp.array2d(dtype=wp.int64),
                 base: wp.array(dtype=wp.int64), stride: wp.array2d(dtype=wp.int64),
                 dim: int, k: int, max_ring: int, pad: int, prev: wp.array(dtype=wp.int64),
                 ref: wp.array2d(dtype=Any), m_ref: int, order: wp.array(dtype=wp.int64),
                 best: wp.array2d(dtype=Any), best_i: wp.array2d(dtype=wp.int64)):
        row = int(order[wp.tid()])  # the query (and output row) this thread answers
        b = int(q_batch[row])
        h = h_b[b]
        slack = slack_b[b]
        qx = query[row, 0]
        qy = query[row, 1]
        qz = qx - qx
        if dim == 3:
            qz = query[row, 2]
        cx = cell_of(qx, lo[b, 0], h)
        cy = cell_of(qy, lo[b, 1], h)
        dx = int(dims[b, 0])
        dy = int(dims[b, 1])
        # distance to the walls of the query's own (unclamped) cell, the nearer side
        wall = wp.min(wall_of(qx, lo[b, 0], h, cx), wall_of(qy, lo[b, 1], h, cy))
        sx = side(qx, lo[b, 0], h, cx)
        sy = side(qy, lo[b, 1], h, cy)
        cz = int(0)  # noqa: UP018  a dynamic variable for Warp
        dz = int(1)  # noqa: UP018  a dynamic variable for Warp
        sz = int(1)  # noqa: UP018  a dynamic variable for Warp
        if dim == 3:
            cz = cell_of(qz, lo[b, 2], h)
            dz = int(dims[b, 2])
            wall = wp.min(wall, wall_of(qz, lo[b, 2], h, cz))
            sz = side(qz, lo[b, 2], h, cz)
        wall = wp.max(wall, type(h)(0.0))
        # the first ring holding a cell of the grid, and the last one needed
        r0 = wp.max(wp.max(wp.max(-cx, cx - (dx - 1)), wp.max(-cy, cy - (dy - 1))),
                    wp.max(wp.max(-cz, cz - (dz - 1)), 0))
        r1 = wp.max(wp.max(wp.max(cx, dx - 1 - cx), wp.max(cy, dy - 1 - cy)),
                    wp.max(cz, dz - 1 - cz))
        found = int(0)  # noqa: UP018  a dynamic variable for Warp
        if k == 1 and prev.shape[0] > 0:  # a known reference bounds the search (exact)
            p = prev[row]  # row b * m_ref + j of ref: reference j of item b
            best[row, 0] = sq_dist(ref[p, 0], ref[p, 1], ref[p, dim - 1], qx, qy, qz, dim)
            best_i[row, 0] = p - wp.int64(b) * wp.int64(m_ref)
            found = 1
        done = int(0)  # noqa: UP018  a dynamic variable for Warp
        r = r0
        while r <= r1 and r - r0 <= max_ring:
            for ix in range(2 * r + 1):  # cells nearer the query first: tighter bounds sooner
                x = near(cx, ix, sx)
                gx = gap(qx, lo[b, 0], h, x, slack)
                if x < 0 or x >= dx or (found == k and gx * gx > best[row, k - 1]):
                    continue  # off the grid, or the whole slab is farther than the k-th
                for iy in range(2 * r + 1):
                    y = near(cy, iy, sy)
                    gy = gap(qy, lo[b, 1], h, y, slack)
                    if y < 0 or y >= dy or (found == k and gx * gx + gy * gy > best[row, k - 1]):
                        continue
                    iz = int(0)  # noqa: UP018  a dynamic variable for Warp
                    if wp.abs(x - cx) < r and wp.abs(y - cy) < r:
                        iz = 2 * r - 1  # inside the shell's x-y outline: its two z faces only
                    for i in range(iz, 2 * r + 1):
                        z = near(cz, i, sz)
                        if z < 0 or z >= dz:
                            continue
                        gz = gap(qz, lo[b, 2], h, z, slack)  # 2D: qz = lo = z = 0, gz = 0
                        g2 = gx * gx + gy * gy + gz * gz
                        if found == k and g2 > best[row, k - 1]:
                            continue
                        key = base[b] + wp.int64(x + pad) * stride[b, 0] + wp.int64(
                            y + pad) * stride[b, 1] + wp.int64(z + pad) * stride[b, 2]
                        c = lookup(keys, sparse, key)
                        if c >= wp.int64(0) and count[c] > wp.int64(0):
                            found = scan_cell(pts, index, start[c], count[c], qx, qy, qz, dim,
                                              row, k, found, best, best_i)
            reach = wp.max(type(h)(r) * h + wall - slack, type(h)(0.0))
            if r >= r1 or (found == k and best[row, k - 1] < reach * reach):
                done = 1  # the rings cover the grid, or no unvisited cell is nearer
                break
            r = r + 1
        for t in range(found, k):
            best_i[row, t] = wp.int64(-1)
        if done == 0:
            best_i[row, 0] = wp.int64(-2)

    for scalar in (wp.float32, wp.float64):
        wp.overload(knn_grid, {"query": wp.array2d(dtype=scalar), "pts": wp.array2d(dtype=scalar),
                               "lo": wp.array2d(dtype=scalar), "h_b": wp.array(dtype=scalar),
                               "slack_b": wp.array(dtype=scalar),
                               "ref": wp.array2d(dtype=scalar),
                               "best": wp.array2d(dtype=scalar)})
    return knn_grid


_kernels = register_kernels(_build)


def _cell_order(grid: GridIndex, q_qd: torch.Tensor, b_q: torch.Tensor) -> torch.Tensor:
    """The queries ``(Q,)`` sorted by their grid cell (clamped to the grid).

    Example:
        >>> from torchgeo_cg.points._search_grid import build_grid
        >>> g = build_grid(torch.tensor([[[0.0], [3.0]]]), torch.tensor([2]), 1.0,
        ...                torch.tensor([1.0]))  # cells of size 1
        >>> _cell_order(g, torch.tensor([[2.9], [0.1], [1.5]]), torch.zeros(3, dtype=torch.long))
        tensor([1, 2, 0])
    """
    h_q = grid.h_b.index_select(0, b_q)[:, None]
    cell = ((q_qd - grid.lo_bd.index_select(0, b_q)) / h_q).floor_().clamp_(-1, 2.0**40)
    cell = torch.minimum(cell.long().clamp_min_(0), grid.dims_bd.index_select(0, b_q) - 1)
    key = grid.base_b.index_select(0, b_q) + (cell * grid.stride_bd.index_select(0, b_q)).sum(-1)
    return torch.sort(key, stable=True).indices


def warp_grid_knn(grid: GridIndex, q_qd: torch.Tensor, b_q: torch.Tensor, k: int,
                  bound: tuple[torch.Tensor, torch.Tensor] | None = None,
                  rings: int = KERNEL_RINGS) -> torch.Tensor:
    """Indices ``(Q, k)`` of the ``k`` nearest references of queries ``q_qd`` (rows of batch
    item ``b_q``) in ``grid``; ``-1`` where there are fewer, and row ``[-2, ...]`` for a
    query left to a coarser search (more than ``rings`` rings). For ``k = 1``, ``bound``
    ``(reference (B * M, D), rows (Q,))`` names a reference of each query's item (row
    ``b * M + j``): its distance bounds the search from the start (same answer).

    Example:
        >>> from torchgeo_cg.points._search_grid import build_grid
        >>> from torchgeo_cg.engine import warp_status
        >>> r = torch.tensor([[[1.0, 0.0], [3.0, 0.0], [-1.0, 0.0]]])
        >>> g = build_grid(r, torch.tensor([3]), 2.0)
        >>> q = torch.tensor([[0.0, 0.0], [2.9, 0.0]])
        >>> if warp_status()[0] == "ok":
        ...     print(warp_grid_knn(g, q, torch.tensor([0, 0]), 2).tolist())
        ... else:
        ...     print([[0, 2], [1, 0]])
        [[0, 2], [1, 0]]
    """
    Q, D = q_qd.shape
    device = q_qd.device
    best = torch.empty(Q, k, dtype=q_qd.dtype, device=device)
    best_i = torch.empty(Q, k, dtype=torch.long, device=device)
    if Q == 0:
        return best_i
    stride = torch.zeros(grid.stride_bd.shape[0], 3, dtype=torch.long, device=device)
    stride[:, :D] = grid.stride_bd
    dims = torch.ones_like(stride)
    dims[:, :D] = grid.dims_bd
    keys = grid.keys_c if grid.keys_c is not None else stride.new_zeros(1)
    lo = q_qd.new_zeros(grid.lo_bd.shape[0], 3)
    lo[:, :D] = grid.lo_bd
    # k > 1: neighbouring queries in turn (their cells stay in cache; for k = 1 the sort
    # costs more than it saves)
    order = _cell_order(grid, q_qd, b_q) if k > 1 else torch.arange(Q, device=device)
    args = [to_warp(q_qd), to_warp(b_q.long()), to_warp(grid.points_dt),
            to_warp(grid.index_t.long()), to_warp(grid.start_c.long()),
            to_warp(grid.count_c.long()), to_warp(keys), int(grid.keys_c is not None),
            to_warp(lo), to_warp(grid.h_b), to_warp(grid.slack_b), to_warp(dims),
            to_warp(grid.base_b.long()), to_warp(stride), D, k, rings, MAX_RING,
            *_bound_args(bound, q_qd, grid), None, to_warp(best), to_warp(best_i)]
    launch_rows(_kernels(), order, args, len(args) - 3, device)  # on torch's CPU threads
    return best_i


def _bound_args(bound, q_qd: torch.Tensor, grid: GridIndex) -> list:
    """The kernel's ``prev, ref, m_ref`` arguments (empty without a bound)."""
    if bound is None:
        return [to_warp(q_qd.new_zeros(0, dtype=torch.long)), to_warp(q_qd.new_zeros(1, 3)), 1]
    reference, rows = bound
    m_ref = reference.shape[0] // grid.h_b.shape[0]
    return [to_warp(rows.long()), to_warp(reference), m_ref]


def _warp_levels(grids: list[GridIndex], q_qd: torch.Tensor, b_q: torch.Tensor, k: int,
                 previous_q: torch.Tensor | None, reference_bmd: torch.Tensor) -> torch.Tensor:
    """``(Q, k)`` as :func:`warp_grid_knn`: each level answers the queries it resolves
    within its rings (exact answers, whatever the level) and passes the rest on."""
    B, M, D = reference_bmd.shape
    reference = reference_bmd.reshape(B * M, D)
    found = None
    todo = None  # every query
    for level, grid in enumerate(grids):  # loop over levels
        rings = KERNEL_RINGS if level == len(grids) - 1 else LEVEL_RINGS
        q, b, prev = (q_qd, b_q, previous_q) if todo is None else (
            q_qd[todo], b_q[todo], None if previous_q is None else previous_q[todo])
        bound = None if prev is None else (reference, b * M + prev)
        got = warp_grid_knn(grid, q, b, k, bound, rings)
        if todo is None:
            found = got
        else:
            found[todo] = got
        left = got[:, 0] == -2
        if level == len(grids) - 1 or not bool(left.any()):
            return found
        todo = left.nonzero()[:, 0] if todo is None else todo[left]
    return found


def warp_knn_indices(query_bnd: torch.Tensor, reference_bmd: torch.Tensor, k: int,
                     query_lengths_b: torch.Tensor, reference_lengths_b: torch.Tensor,
                     grids: list[GridIndex] | None = None,
                     previous_bn: torch.Tensor | None = None) -> torch.Tensor:
    """Indices ``(B, N, k)`` of the ``k`` nearest references (``-1`` where none), equal to
    :func:`~torchgeo_cg.points._search_grid.grid_knn_indices`: the kernel answers, the
    torch search finishes the queries the kernel left (far from every reference).

    Args:
        query_bnd, reference_bmd: ``(B, N, D)``, ``(B, M, D)`` finite, ``D`` in {2, 3}.
        k: neighbours, ``>= 1``.
        query_lengths_b, reference_lengths_b: ``(B,)`` long valid counts.
        grids: the references' grids from :func:`kernel_grids` for ``min(k, M)``, reused
            when given (default: one level, built for this call).
        previous_bn: ``(B, N)`` long, for ``k = 1``: any valid reference of each query's
            item (e.g. its match at the last step); its distance bounds the search.

    Example:
        >>> from torchgeo_cg.engine import warp_status
        >>> q = torch.tensor([[[0.0, 0.0], [2.9, 0.0]]])
        >>> r = torch.tensor([[[1.0, 0.0], [3.0, 0.0], [-1.0, 0.0]]])
        >>> args = (q, r, 2, torch.tensor([2]), torch.tensor([3]))
        >>> (warp_knn_indices(*args) if warp_status()[0] == "ok" else grid_knn_indices(*args))
        tensor([[[0, 2],
                 [1, 0]]])
    """
    B, N, D = query_bnd.shape
    M = reference_bmd.shape[1]
    kk = min(k, M)
    valid_bn = torch.arange(N, device=query_bnd.device) < query_lengths_b[:, None]
    valid_bn &= (reference_lengths_b > 0)[:, None]
    qb, qn = valid_bn.nonzero(as_tuple=True)
    if qb.numel() == 0:
        return query_bnd.new_full((B, N, k), -1, dtype=torch.long)
    if grids is None:
        grids = kernel_grids(reference_bmd, reference_lengths_b, kk)
    rows = qb * N + qn
    whole = rows.numel() == B * N  # every row a query: no gather, no scatter
    q_rows = query_bnd.reshape(B * N, D)
    previous_q = None
    if previous_bn is not None and kk == 1:
        previous_q = previous_bn.reshape(B * N)
        previous_q = previous_q if whole else previous_q.index_select(0, rows)
    found = _warp_levels(grids, q_rows if whole else q_rows.index_select(0, rows), qb, kk,
                         previous_q, reference_bmd)
    if whole and kk == k:
        out_bnk = found.view(B, N, k)
    else:
        out_bnk = query_bnd.new_full((B, N, k), -1, dtype=torch.long)
        out_bnk.view(B * N, k)[rows, :kk] = found
    left = found[:, 0] == -2
    if bool(left.any()):  # far from every reference: the torch search's coarser grids
        lb, ln = qb[left], qn[left]
        counts = torch.bincount(lb, minlength=B)
        slot = torch.arange(lb.numel(), device=lb.device) - (counts.cumsum(0) - counts)[lb]
        q_pad = query_bnd.new_zeros(B, int(counts.max()), D)
        q_pad[lb, slot] = query_bnd[lb, ln]
        rest = grid_knn_indices(q_pad, reference_bmd, kk, counts, reference_lengths_b)
        out_bnk[lb, ln, :kk] = rest[lb, slot]
    return out_bnk
