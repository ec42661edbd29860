"""Exact k-nearest-neighbour indices on the CPU with a uniform grid of sorted cells.

No quadratic distance matrix is formed. The references of every batch item are binned
into a uniform grid (cell size ``h``, chosen so that an occupied cell holds about
``k + 1`` points; the size adapts to point sets on surfaces or curves), sorted by cell
key, and indexed by a dense table of cell starts (``bincount`` + ``cumsum``) or, for
sparse grids, by ``searchsorted`` on the occupied keys. For ``k = 1`` every query first
scans the ``2^D`` cells around its nearest cell corner, which contain the ball out to
the block's walls (at least half a cell); queries whose nearest point lies in that ball
are done. The others scan rings of cells around their own cell (clamped to the grid):
the ``3^D`` block, then the shells at Chebyshev radius 2, 3, ...; the candidates of all
active queries are expanded at once (segment ids by scatter + cumsum) and merged into a
running top-k.

Proof of exactness: after the rings up to radius ``r`` a point in any unvisited cell is
at distance at least ``b = sqrt(out^2 + (r h + delta)^2)`` from the query, where ``out``
is the query's distance to the grid box and ``delta`` its distance to the walls of its
own cell along the axes where it lies inside the box. A query stops once its k-th
distance is below ``b`` (shrunk by a rounding margin relative to the coordinates), or
once the rings cover the whole grid. Queries still running after ``MAX_RING`` rings
(far outside the grid, or in huge empty regions) continue on a grid about twice as
coarse, from scratch, so the number of rounds stays logarithmic in the spread of the
data; there, and in rings past the first, cells whose box lies farther than the best
k-th distance found so far (an upper bound on the true one) are skipped.

Convention:
    - Squared Euclidean distances; ties broken by the smaller reference index, so the
      result equals :func:`~torchgeo_cg.points._search_brute.brute_knn_indices`.
    - Inputs must be finite (the caller masks non-finite rows).
"""

from __future__ import annotations

from typing import NamedTuple

import torch

__all__: list[str] = []

#: Rings scanned on one grid before the remaining queries move to a coarser grid.
MAX_RING = 3
#: Largest number of (query, cell) pairs expanded at once.
CHUNK_PAIRS = 1 << 14
#: Target number of references per occupied cell for k = 1 (scaled with k).
PER_CELL = 2.0
_BIG = torch.iinfo(torch.long).max


class GridIndex(NamedTuple):
    """References sorted by cell, for every item ``b`` of a flattened batch.

    The grid of item ``b`` has ``dims_bd[b]`` cells per axis, surrounded by ``MAX_RING``
    empty cells on every side so that ring offsets never leave it; the key of padded
    cell ``c`` is ``base_b[b] + sum_a c_a * stride_bd[b, a]``.

    Attributes:
        lo_bd, h_b, dims_bd, base_b, stride_bd: origin, cell size, cells per axis (without
            the border), key offset and key strides of each batch item.
        points_dt: references sorted by key, coordinates first ``(D, T)``.
        index_t: their row in their batch item ``(T,)``.
        start_c, count_c: first sorted reference and count of each key (dense table), or
            of each occupied key listed in ``keys_c`` (sparse).
        keys_c: ``None`` for the dense table, else the sorted occupied keys.
        slack_b: rounding margin of the distance bounds.
    """

    lo_bd: torch.Tensor
    h_b: torch.Tensor
    dims_bd: torch.Tensor
    base_b: torch.Tensor
    stride_bd: torch.Tensor
    points_dt: torch.Tensor
    index_t: torch.Tensor
    start_c: torch.Tensor
    count_c: torch.Tensor
    keys_c: torch.Tensor | None
    slack_b: torch.Tensor


def grid_per_cell(k: int) -> float:
    """Target references per occupied cell of the finest grid for ``k`` neighbours.

    Example:
        >>> grid_per_cell(1), grid_per_cell(3)
        (2.0, 4.0)
    """
    return PER_CELL * (k + 1) / 2


def ring_offsets(r: int, d: int, device=None) -> torch.Tensor:
    """Integer cell offsets ``(S, d)``: the ``(2r+1)^d`` block for ``r <= 1``, else the shell.

    Example:
        >>> ring_offsets(2, 1)
        tensor([[-2],
                [ 2]])
        >>> ring_offsets(1, 2).shape
        torch.Size([9, 2])
    """
    axis = torch.arange(-r, r + 1, device=device)
    block = torch.cartesian_prod(*([axis] * d)).reshape(-1, d)
    if r <= 1:
        return block
    return block[block.abs().amax(-1) == r]


def _grid_keys(points_td, batch_t, lo_bd, extent_bd, h_b, cap):
    """Sorted cell keys of the points and the padded grid layout for cell sizes ``h_b``."""
    D = lo_bd.shape[1]
    dims_bd = (extent_bd / h_b[:, None]).floor().long().clamp(0, int(cap) - 1) + 1
    padded_bd = dims_bd + 2 * MAX_RING
    stride_bd = torch.ones_like(dims_bd)
    for a in range(D - 2, -1, -1):  # loop over coordinates
        stride_bd[:, a] = stride_bd[:, a + 1] * padded_bd[:, a + 1]
    cells_b = padded_bd.prod(-1)
    base_b = torch.cumsum(cells_b, 0) - cells_b
    cell_td = ((points_td - lo_bd[batch_t]) / h_b[batch_t, None]).floor().long()
    cell_td = torch.minimum(cell_td.clamp_min(0), dims_bd[batch_t] - 1) + MAX_RING
    key_t = base_b[batch_t] + (cell_td * stride_bd[batch_t]).sum(-1)
    return key_t, dims_bd, stride_bd, base_b, int(cells_b.sum())


def _occupied(key_t, batch_t, base_b, total: int) -> torch.Tensor:
    """Number of occupied cells of each batch item (unsorted keys)."""
    B = base_b.shape[0]
    if total <= 32 * key_t.numel() + 4096:  # dense: one bincount over the cells
        used_c = torch.bincount(key_t, minlength=total) > 0
        ends = torch.cat([base_b[1:], base_b.new_tensor([total])])
        cum = torch.cat([used_c.new_zeros(1, dtype=torch.long), used_c.long().cumsum(0)])
        return cum[ends] - cum[base_b]
    key_s, order_t = torch.sort(key_t)
    run_t = torch.ones_like(key_s, dtype=torch.bool)
    run_t[1:] = key_s[1:] != key_s[:-1]
    return torch.bincount(batch_t[order_t][run_t], minlength=B)


def _layout(points_td, batch_t, lo_bd, extent_bd, count_b, per_cell):
    """Cell size per batch item (about ``per_cell`` points per occupied cell) and keys."""
    B, D = lo_bd.shape
    cap = float(2 ** (44 // D))
    h_b = extent_bd.amax(-1) * (per_cell / count_b.clamp_min(1)) ** (1.0 / D)
    attempt = 0
    while True:  # refine for points on surfaces/curves (occupancy above target)
        h_b = torch.maximum(h_b, (extent_bd / (cap - 1)).amax(-1))
        h_b = torch.where(h_b > 0, h_b, torch.ones_like(h_b))
        key_t, dims_bd, stride_bd, base_b, total = _grid_keys(points_td, batch_t, lo_bd,
                                                              extent_bd, h_b, cap)
        ratio_b = count_b / _occupied(key_t, batch_t, base_b, total).clamp_min(1) / per_cell
        attempt += 1
        if attempt == 4 or bool((ratio_b <= 1.5).all()):
            key_t, order_t = torch.sort(key_t, stable=True)  # stable: index order in a cell
            return h_b, (key_t, order_t, dims_bd, stride_bd, base_b, total)
        h_b = torch.where(ratio_b > 1.5, h_b * ratio_b.clamp_min(1) ** -0.5, h_b)


def _fixed_layout(points_td, batch_t, lo_bd, extent_bd, h_b):
    """Keys for given cell sizes (raised where the grid would exceed its cap)."""
    cap = float(2 ** (44 // lo_bd.shape[1]))
    h_b = torch.maximum(h_b, (extent_bd / (cap - 1)).amax(-1))
    h_b = torch.where(h_b > 0, h_b, torch.ones_like(h_b))
    key_t, dims_bd, stride_bd, base_b, total = _grid_keys(points_td, batch_t, lo_bd,
                                                          extent_bd, h_b, cap)
    key_t, order_t = torch.sort(key_t, stable=True)
    return h_b, (key_t, order_t, dims_bd, stride_bd, base_b, total)


def build_grid(
    reference_bmd: torch.Tensor, reference_lengths_b: torch.Tensor, per_cell: float,
    cell_b: torch.Tensor | None = None,
) -> GridIndex:
    """Bin the valid references of each batch item into a uniform grid (see module); with
    ``cell_b`` ``(B,)`` the cell size of each item is given (at least the grid's cap
    allows) instead of chosen for ``per_cell`` references per occupied cell.

    Example:
        >>> g = build_grid(torch.rand(2, 100, 3), torch.tensor([100, 50]), 2.0)
        >>> g.points_dt.shape, g.index_t.shape
        (torch.Size([3, 150]), torch.Size([150]))
    """
    B, M, D = reference_bmd.shape
    dev = reference_bmd.device
    valid_bm = torch.arange(M, device=dev) < reference_lengths_b[:, None]
    batch_t, index_t = valid_bm.nonzero(as_tuple=True)
    points_td = reference_bmd.reshape(B * M, D).index_select(0, batch_t * M + index_t)
    inf = float("inf")
    lo_bd = reference_bmd.masked_fill(~valid_bm[..., None], inf).amin(1)
    hi_bd = reference_bmd.masked_fill(~valid_bm[..., None], -inf).amax(1)
    empty_b = reference_lengths_b == 0
    lo_bd = torch.where(empty_b[:, None], torch.zeros_like(lo_bd), lo_bd)
    hi_bd = torch.where(empty_b[:, None], torch.zeros_like(hi_bd), hi_bd)
    extent_bd = hi_bd - lo_bd
    if cell_b is None:
        h_b, layout = _layout(points_td, batch_t, lo_bd, extent_bd,
                              reference_lengths_b.to(lo_bd), per_cell)
    else:
        h_b, layout = _fixed_layout(points_td, batch_t, lo_bd, extent_bd, cell_b.to(lo_bd))
    key_t, order_t, dims_bd, stride_bd, base_b, total = layout
    if total <= 32 * key_t.numel() + 4096:
        count_c = torch.bincount(key_t, minlength=total)
        keys_c = None
    else:
        keys_c, count_c = torch.unique_consecutive(key_t, return_counts=True)
    start_c = torch.cumsum(count_c, 0) - count_c
    eps = torch.finfo(reference_bmd.dtype).eps
    slack_b = 16 * eps * (lo_bd.abs().amax(-1) + extent_bd.amax(-1) + h_b)
    points_dt = points_td.index_select(0, order_t).t().contiguous()
    return GridIndex(lo_bd, h_b, dims_bd, base_b, stride_bd, points_dt,
                     index_t.index_select(0, order_t), start_c, count_c, keys_c, slack_b)


def _cell_ranges(grid: GridIndex, key_q, b_q, offsets_sd):
    """Start and count ``(Q * S,)`` of the cells at ``offsets`` from each query's cell."""
    delta_bs = (offsets_sd[None, :, :] * grid.stride_bd[:, None, :]).sum(-1)
    key_qs = (key_q[:, None] + delta_bs.index_select(0, b_q)).reshape(-1)
    if grid.keys_c is None:
        return grid.start_c.index_select(0, key_qs), grid.count_c.index_select(0, key_qs)
    pos_qs = torch.searchsorted(grid.keys_c, key_qs).clamp_max(grid.keys_c.numel() - 1)
    hit_qs = grid.keys_c.index_select(0, pos_qs) == key_qs
    count_qs = grid.count_c.index_select(0, pos_qs)
    return grid.start_c.index_select(0, pos_qs), torch.where(hit_qs, count_qs, 0)


def _prune(grid: GridIndex, q_qd, b_q, cell_qd, offsets_sd, limit_q, count_p):
    """Zero the counts of cells whose box is farther than ``sqrt(limit_q)`` from the query.

    Only the occupied (query, cell) pairs are tested: most cells of a ring are empty.
    """
    S = offsets_sd.shape[0]
    pair = count_p.nonzero()[:, 0]
    row, col = pair // S, pair % S
    b = b_q.index_select(0, row)
    h = grid.h_b.index_select(0, b)[:, None]
    slack = grid.slack_b.index_select(0, b)[:, None]
    lo = grid.lo_bd.index_select(0, b) + (cell_qd.index_select(0, row)
                                          + offsets_sd.index_select(0, col)) * h - slack
    q = q_qd.index_select(0, row)
    gap = (lo - q).clamp_min(0) + (q - lo - h - 2 * slack).clamp_min(0)
    far = gap.square().sum(-1) > limit_q.index_select(0, row)
    return count_p.index_put((pair[far],), torch.zeros((), dtype=count_p.dtype,
                                                       device=count_p.device))


def segment_ids(count_p: torch.Tensor, total: int) -> torch.Tensor:
    """For counts ``(P,)`` summing to ``total``, the segment of each of the ``total`` slots.

    Equals ``repeat_interleave(arange(P), count_p)`` (much faster on the CPU: one
    scatter and one cumsum).

    Example:
        >>> segment_ids(torch.tensor([2, 0, 1, 3]), 6)
        tensor([0, 0, 2, 3, 3, 3])
    """
    first_p = torch.cumsum(count_p, 0) - count_p
    step_t = torch.zeros(total + 1, dtype=count_p.dtype, device=count_p.device)
    step_t.index_add_(0, first_p, torch.ones_like(count_p))  # +1 where a segment starts
    step_t[0] -= 1
    return torch.cumsum(step_t[:total], 0)


def _candidates(grid: GridIndex, q_dq, key_q, b_q, offsets_sd, cell_qd=None, limit_q=None):
    """Candidates (query row, squared distance, reference index) and counts per query.

    With ``limit_q`` (a squared upper bound on each query's k-th distance), cells whose
    box lies farther are skipped; they cannot hold a k-nearest neighbour.
    """
    start_p, count_p = _cell_ranges(grid, key_q, b_q, offsets_sd)
    if limit_q is not None:
        count_p = _prune(grid, q_dq.t(), b_q, cell_qd, offsets_sd, limit_q, count_p)
    return _expand(grid, q_dq, start_p, count_p, offsets_sd.shape[0])


def _expand(grid: GridIndex, q_dq, start_p, count_p, S: int):
    """Candidates of ``S`` cell ranges per query (``start_p``, ``count_p``: ``(Q * S,)``)."""
    count_q = count_p.view(-1, S).sum(-1)
    total = int(count_q.sum())
    pair_c = segment_ids(count_p, total)
    shift_p = start_p - (torch.cumsum(count_p, 0) - count_p)
    pos_c = torch.arange(total, device=q_dq.device) + shift_p.index_select(0, pair_c)
    Q = count_q.numel()
    row_p = torch.arange(Q, device=q_dq.device)[:, None].expand(Q, S).reshape(-1)
    row_c = row_p.index_select(0, pair_c)
    d2_c = None
    for a in range(q_dq.shape[0]):  # loop over coordinates
        diff = grid.points_dt[a].index_select(0, pos_c) - q_dq[a].index_select(0, row_c)
        d2_c = diff * diff if d2_c is None else d2_c + diff * diff
    return row_c, d2_c, grid.index_t.index_select(0, pos_c), count_q


def _merge_one(best_d, best_i, row_c, d2_c, j_c):
    """k = 1: smallest distance, then smallest index."""
    if d2_c.dtype == torch.float32:  # pack (distance bits, index) into one sortable int64
        packed = (d2_c.view(torch.int32).long() << 32) | j_c
        init = (best_d.view(torch.int32).long() << 32) | best_i.clamp_max(2**31 - 1)
        best = init.scatter_reduce(0, row_c, packed, reduce="amin")
        return (best >> 32).int().view(torch.float32), best & (2**32 - 1)
    new_d = best_d.scatter_reduce(0, row_c, d2_c, reduce="amin")
    tie_c = d2_c == new_d.index_select(0, row_c)
    keep = torch.where(best_d == new_d, best_i, torch.full_like(best_i, _BIG))
    new_i = keep.scatter_reduce(0, row_c[tie_c], j_c[tie_c], reduce="amin")
    return new_d, new_i


def _merge_k(best_qk, idx_qk, row_c, d2_c, j_c, count_q):
    """k > 1: pad candidates per query, then order by (distance, index)."""
    Q, k = best_qk.shape
    width = int(count_q.max()) if Q else 0
    first_q = torch.cumsum(count_q, 0) - count_q
    col_c = torch.arange(row_c.numel(), device=row_c.device) - first_q.index_select(0, row_c)
    d_qw = best_qk.new_full((Q, width), float("inf"))
    i_qw = idx_qk.new_full((Q, width), _BIG)
    d_qw[row_c, col_c] = d2_c
    i_qw[row_c, col_c] = j_c
    d_qw, i_qw = torch.cat([best_qk, d_qw], 1), torch.cat([idx_qk, i_qw], 1)
    order = torch.sort(i_qw, dim=1, stable=True).indices
    d_qw, i_qw = d_qw.gather(1, order), i_qw.gather(1, order)
    order = torch.sort(d_qw, dim=1, stable=True).indices[:, :k]
    return d_qw.gather(1, order), i_qw.gather(1, order)


def _query_cells(grid: GridIndex, q_qd, b_q):
    """Cell (clamped to the grid, without border) and padded key of every query."""
    h_q = grid.h_b.index_select(0, b_q)
    lo_qd = grid.lo_bd.index_select(0, b_q)
    cell_qd = ((q_qd - lo_qd) / h_q[:, None]).floor().clamp(-1, 2.0**50).long()
    cell_qd = torch.minimum(cell_qd.clamp_min(0), grid.dims_bd.index_select(0, b_q) - 1)
    stride_qd = grid.stride_bd.index_select(0, b_q)
    key_q = grid.base_b.index_select(0, b_q) + ((cell_qd + MAX_RING) * stride_qd).sum(-1)
    return cell_qd, key_q


def _stop_bound(grid: GridIndex, q_qd, b_q, cell_qd, r):
    """Squared lower bound on the distance to any cell beyond ring ``r``, and 'all seen'."""
    lo_qd, h_q = grid.lo_bd.index_select(0, b_q), grid.h_b.index_select(0, b_q)
    dims_qd = grid.dims_bd.index_select(0, b_q)
    hi_qd = lo_qd + dims_qd * h_q[:, None]
    out_q = ((lo_qd - q_qd).clamp_min(0) + (q_qd - hi_qd).clamp_min(0)).square().sum(-1)
    wall_lo = lo_qd + cell_qd * h_q[:, None]
    inside_qd = (q_qd >= lo_qd) & (q_qd <= hi_qd)
    wall_qd = torch.minimum(q_qd - wall_lo, wall_lo + h_q[:, None] - q_qd).clamp_min(0)
    delta_q = torch.where(inside_qd, wall_qd, h_q[:, None]).amin(-1)
    reach_q = (r * h_q + delta_q - grid.slack_b.index_select(0, b_q)).clamp_min(0)
    return out_q + reach_q.square(), r >= dims_qd.amax(-1) - 1


def _scan_ring(grid, q_qd, key_q, b_q, cell_qd, best_qk, idx_qk, ub_q, active, r):
    """Merge the candidates of ring ``r`` into the running best of the active queries."""
    offsets_sd = ring_offsets(r, q_qd.shape[1], q_qd.device)
    step = max(1, CHUNK_PAIRS // offsets_sd.shape[0])
    k = best_qk.shape[1]
    for s in range(0, active.numel(), step):  # loop over memory chunks
        a = active[s : s + step]
        q_dq = q_qd.index_select(0, a).t()
        limit = torch.minimum(ub_q.index_select(0, a), best_qk[:, -1].index_select(0, a))
        prune = not bool(torch.isinf(limit).all())
        row_c, d2_c, j_c, count_q = _candidates(
            grid, q_dq, key_q.index_select(0, a), b_q.index_select(0, a), offsets_sd,
            cell_qd.index_select(0, a) if prune else None, limit if prune else None)
        if k == 1:
            d, i = _merge_one(best_qk.index_select(0, a)[:, 0], idx_qk.index_select(0, a)[:, 0],
                              row_c, d2_c, j_c)
            best_qk[a, 0], idx_qk[a, 0] = d, i
        else:
            best_qk[a], idx_qk[a] = _merge_k(best_qk[a], idx_qk[a], row_c, d2_c, j_c, count_q)


def _octant_pass(grid: GridIndex, q_qd, b_q, cell_qd, key_q, best_qk, idx_qk):
    """k = 1 first pass: the ``2^D`` cells around the query's nearest cell corner.

    Along each axis the block spans the query's cell and the neighbour on the nearer
    side, so it contains the ball of radius ``delta`` = the query's distance to the
    block's walls (at least half a cell). Returns the queries proven done.
    """
    Q, D = q_qd.shape
    h_q = grid.h_b.index_select(0, b_q)[:, None]
    lo_qd = grid.lo_bd.index_select(0, b_q) + cell_qd * h_q
    upper_qd = q_qd - lo_qd >= 0.5 * h_q  # the nearer neighbour is above on that axis
    side_qd = torch.where(upper_qd, 1, -1)
    corner_sd = torch.cartesian_prod(*([torch.tensor([0, 1], device=q_qd.device)] * D))
    corner_sd = corner_sd.reshape(-1, D)  # (2^D, D), also the sign patterns as bits
    S = corner_sd.shape[0]
    # key offsets of the 2^D cells for each sign pattern and batch item: (B * 2^D, 2^D)
    sign_pd = 2 * corner_sd - 1
    table = ((corner_sd[None, None] * sign_pd[None, :, None, :])
             * grid.stride_bd[:, None, None, :]).sum(-1).reshape(-1, S)
    pattern_q = (upper_qd.long() * (2 ** torch.arange(D - 1, -1, -1, device=q_qd.device))).sum(-1)
    delta_qs = table.index_select(0, b_q * S + pattern_q)
    step = max(1, CHUNK_PAIRS // S)
    for s in range(0, Q, step):  # loop over memory chunks
        key_p = (key_q[s : s + step, None] + delta_qs[s : s + step]).reshape(-1)
        row_c, d2_c, j_c, _ = _expand(grid, q_qd[s : s + step].t(),
                                      grid.start_c.index_select(0, key_p),
                                      grid.count_c.index_select(0, key_p), S)
        d, i = _merge_one(best_qk[s : s + step, 0], idx_qk[s : s + step, 0], row_c, d2_c, j_c)
        best_qk[s : s + step, 0], idx_qk[s : s + step, 0] = d, i
    low_qd = lo_qd + torch.where(side_qd < 0, -h_q, 0.0)
    high_qd = lo_qd + torch.where(side_qd > 0, 2 * h_q, h_q)
    delta_q = torch.minimum(q_qd - low_qd, high_qd - q_qd).amin(-1)
    inside_q = ((q_qd >= grid.lo_bd.index_select(0, b_q))
                & (q_qd <= grid.lo_bd.index_select(0, b_q)
                   + grid.dims_bd.index_select(0, b_q) * h_q)).all(-1)
    reach_q = (delta_q - grid.slack_b.index_select(0, b_q)).clamp_min(0)
    return inside_q & (best_qk[:, 0] < reach_q.square())


def _search_level(grid: GridIndex, q_qd, b_q, k, ub_q):
    """Rings 1..MAX_RING on one grid; returns the best ``(Q, k)`` and a 'proven' mask.

    ``ub_q``: squared upper bounds on the k-th distances from coarser work (``inf``: none).
    """
    Q = q_qd.shape[0]
    cell_qd, key_q = _query_cells(grid, q_qd, b_q)
    best_qk = q_qd.new_full((Q, k), float("inf"))
    idx_qk = torch.full((Q, k), _BIG if k > 1 else 2**31 - 1, dtype=torch.long,
                        device=q_qd.device)
    done_q = torch.zeros(Q, dtype=torch.bool, device=q_qd.device)
    active = torch.arange(Q, device=q_qd.device)
    if k == 1 and grid.keys_c is None:
        done_q = _octant_pass(grid, q_qd, b_q, cell_qd, key_q, best_qk, idx_qk)
        active = active[~done_q]
    for r in range(1, MAX_RING + 1):  # loop over rings
        _scan_ring(grid, q_qd, key_q, b_q, cell_qd, best_qk, idx_qk, ub_q, active, r)
        bound_q, whole_q = _stop_bound(grid, q_qd[active], b_q[active], cell_qd[active], r)
        stop = whole_q | (best_qk[:, -1].index_select(0, active) < bound_q)
        done_q[active[stop]] = True
        active = active[~stop]
        if active.numel() == 0:
            break
    return best_qk, idx_qk, done_q


def grid_knn_indices(
    query_bnd: torch.Tensor,
    reference_bmd: torch.Tensor,
    k: int,
    query_lengths_b: torch.Tensor,
    reference_lengths_b: torch.Tensor,
    grids: list[GridIndex] | None = None,
) -> torch.Tensor:
    """Indices ``(B, N, k)`` of the ``k`` nearest references, ``-1`` where there are none.

    Convention:
        See the module docstring; no gradient (indices only); ``D <= 3`` is efficient.

    Args:
        query_bnd: ``(B, N, D)`` finite queries, float32 or float64.
        reference_bmd: ``(B, M, D)`` finite references, same dtype.
        k: neighbours, ``>= 1``.
        query_lengths_b, reference_lengths_b: ``(B,)`` long valid counts.
        grids: a cache of the references' grids, finest first, reused across calls
            with the same references and ``k`` (an empty list to start; the levels a
            call needs are built and appended). ``None``: built for this call only.

    Returns:
        ``(B, N, k)`` long.

    Example:
        >>> q = torch.tensor([[[0.0, 0.0], [2.9, 0.0]]])
        >>> r = torch.tensor([[[1.0, 0.0], [3.0, 0.0], [-1.0, 0.0]]])
        >>> grid_knn_indices(q, r, 2, torch.tensor([2]), torch.tensor([3]))
        tensor([[[0, 2],
                 [1, 0]]])
    """
    B, N, D = query_bnd.shape
    out_bnk = query_bnd.new_full((B, N, k), -1, dtype=torch.long)
    with torch.no_grad():
        valid_bn = torch.arange(N, device=query_bnd.device) < query_lengths_b[:, None]
        valid_bn &= (reference_lengths_b > 0)[:, None]
        qb, qn = valid_bn.nonzero(as_tuple=True)
        if qb.numel() == 0:
            return out_bnk
        q_qd = query_bnd.reshape(B * N, D).index_select(0, qb * N + qn)
        kk = min(k, reference_bmd.shape[1])
        per_cell = grid_per_cell(kk)
        pending = torch.arange(qb.numel(), device=query_bnd.device)
        ub_q = q_qd.new_full((qb.numel(),), float("inf"))
        out_flat = out_bnk.view(B * N, k)
        for level in range(200):  # loop over grid levels (each coarser)
            if grids is not None and level < len(grids):
                grid = grids[level]
            else:
                grid = build_grid(reference_bmd, reference_lengths_b, per_cell)
                if grids is not None:
                    grids.append(grid)
            best_qk, idx_qk, done_q = _search_level(grid, q_qd[pending], qb[pending], kk,
                                                    ub_q[pending])
            idx_qk = torch.where(best_qk.isinf(), torch.full_like(idx_qk, -1), idx_qk)
            rows = pending[done_q]
            out_flat[qb[rows] * N + qn[rows], :kk] = idx_qk[done_q]
            ub_q[pending] = torch.minimum(ub_q[pending], best_qk[:, -1])
            pending = pending[~done_q]
            if pending.numel() == 0:
                break
            per_cell *= 2.0**D
    return out_bnk
