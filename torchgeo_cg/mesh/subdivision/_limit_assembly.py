"""The limit stencils' sparse matrices, assembled from patches without sorting the entries.

Convention:
    Every point lies in one *patch*: a face of some refinement level whose limit is a
    fixed linear map ``C_p (S, K_p)`` from ``S`` slot weights to the patch's ``K_p``
    control-vertex columns ``cols_p`` (increasing). The point's three rows (position,
    ``d/du``, ``d/dv``) are ``W (3, S) @ C_p`` over those columns, so once each row's
    offset is known (a cumulative sum of the patches' ``K_p``) its entries are already
    in CSR order. The transpose is placed by counting too: for each column, the runs of
    points of each patch holding it, runs ordered by patch and points within a run by
    row. So each row of the transpose lists its entries grouped by patch, not sorted;
    the sparse products the stencils feed (forward, backward and double backward) do
    not depend on that order. The three matrices share their index tensors: the pattern
    is the union of their nonzeros, so a derivative may hold explicit zeros (a box-spline
    basis function ``u^4 / 12`` has no ``v`` derivative); entries zero in all three
    (points on a patch's knot lines) are dropped, the order kept.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import torch

from torchgeo_cg.mesh.subdivision._stencil_build import StencilMatrix, index_dtype

_CHUNK = 1 << 13  # points per batched product: the gathered patch matrices stay in cache


class Patches(NamedTuple):
    """Linear maps of one level's patches: ``C (P, S, K)`` from slot weights to columns
    ``cols (P, K)`` (increasing in the first ``size (P,)`` entries, then padding)."""

    C: torch.Tensor
    cols: torch.Tensor
    size: torch.Tensor


class PointBlock(NamedTuple):
    """Points ``sample (n,)`` (their rows) in patches ``patch (n,)`` of ``patches``, at
    coordinates ``params (n, P)``; ``weights(params[i])`` gives the slot weights ``(m, 3,
    S)`` of the position and the two derivatives (called on chunks of points, so the
    weights of all points never exist at once)."""

    sample: torch.Tensor
    patch: torch.Tensor
    params: torch.Tensor
    weights: Callable[[torch.Tensor], torch.Tensor]
    patches: Patches


def _offsets(counts: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    out = torch.zeros(counts.numel() + 1, dtype=dtype, device=counts.device)
    out[1:] = torch.cumsum(counts, 0)
    return out


def _run_starts(blocks, num_cols: int):
    """Where each (patch, slot column) run of points starts in the transpose, per block
    ``(P_b, K_b)``, and the transpose's row offsets' counts ``(num_cols,)``."""
    dev = blocks[0].sample.device
    cols, lens, shapes = [], [], []
    for b in blocks:  # a loop over levels
        P, K = b.patches.cols.shape
        valid = torch.arange(K, device=dev) < b.patches.size[:, None]
        npts = torch.bincount(b.patch, minlength=P)
        cols.append(b.patches.cols[valid])
        lens.append(npts[:, None].expand(P, K)[valid])
        shapes.append(valid)
    col, length = torch.cat(cols), torch.cat(lens)
    order = torch.sort(col, stable=True).indices  # runs by column, then by patch
    sorted_len = length[order]
    start = torch.empty_like(length)
    start[order] = torch.cumsum(sorted_len, 0) - sorted_len
    counts = torch.zeros(num_cols, dtype=torch.long, device=dev).index_add_(0, col, length)
    starts, at = [], 0
    for valid in shapes:
        s = torch.zeros(valid.shape, dtype=torch.long, device=dev)
        n = int(valid.sum())
        s[valid] = start[at:at + n]
        starts.append(s)
        at += n
    return starts, counts


def assemble_limit_stencils(blocks: list[PointBlock], num_rows: int, num_cols: int,
                            dtype: torch.dtype, device) -> tuple[StencilMatrix, ...]:
    """The three ``(num_rows, num_cols)`` stencil matrices (position, ``du``, ``dv``) of
    the points in ``blocks`` (each row in exactly one block; module docstring)."""
    blocks = [b for b in blocks if b.sample.numel()]
    if not blocks:
        empty = _empty(num_rows, num_cols, dtype, device)
        return empty, empty, empty
    row_len = torch.zeros(num_rows, dtype=torch.long, device=device)
    for b in blocks:  # a loop over levels
        row_len[b.sample] = b.patches.size[b.patch]
    nnz = int(row_len.sum())
    index = index_dtype(num_rows, num_cols, nnz)
    crow = _offsets(row_len, index)
    starts, col_len = _run_starts(blocks, num_cols)
    crow_t = _offsets(col_len, index)
    col = torch.empty(nnz + 1, dtype=index, device=device)  # entry nnz: a sink for padding
    row_t = torch.empty(nnz + 1, dtype=index, device=device)
    w = torch.empty(3, nnz + 1, dtype=dtype, device=device)
    w_t = torch.empty(3, nnz + 1, dtype=dtype, device=device)
    for b, start in zip(blocks, starts):  # a loop over levels
        _place(b, start, crow, nnz, col, row_t, w, w_t)
    col, row_t, w, w_t = col[:nnz], row_t[:nnz], w[:, :nnz], w_t[:, :nnz]
    keep, keep_t = (w != 0).any(0), (w_t != 0).any(0)
    if not bool(keep.all()):  # points on knot lines: entries zero in all three matrices
        crow, col, w = _kept_offsets(crow, keep), col[keep], w[:, keep]
        crow_t, row_t, w_t = _kept_offsets(crow_t, keep_t), row_t[keep_t], w_t[:, keep_t]
    return tuple(StencilMatrix(crow, col, w[i], crow_t, row_t, w_t[i]) for i in range(3))


def _place(b: PointBlock, start, crow, nnz, col, row_t, w, w_t) -> None:
    """Write the entries of block ``b``: rows at ``crow[row] + k``, transposed entries at
    their run's start plus the point's rank among the patch's points. Points go by patch
    size, then patch, then row, so that a chunk's products and writes cover its patches'
    columns with little padding; the chunks reuse one workspace (fresh memory per chunk
    would fault its pages in every time)."""
    dev = b.sample.device
    C, size = b.patches.C, b.patches.size
    P, S, K = C.shape
    patch_order = torch.sort(size, stable=True).indices
    patch_rank = torch.empty_like(patch_order)
    patch_rank[patch_order] = torch.arange(P, device=dev)
    order = torch.sort(patch_rank[b.patch], stable=True).indices
    npts = torch.bincount(b.patch, minlength=P)[patch_order]
    first = torch.empty_like(npts)
    first[patch_order] = torch.cumsum(npts, 0) - npts  # a patch's first place in ``order``
    k = torch.arange(K, device=dev)
    sink = torch.tensor(nnz, device=dev)
    n_ws = min(_CHUNK, order.numel())
    C_ws, values_ws = C.new_empty(n_ws * S * K), C.new_empty(n_ws * 3 * K)
    for lo in range(0, order.numel(), _CHUNK):  # bounded memory: chunks of points
        idx = order[lo:lo + _CHUNK]
        n = idx.numel()
        f, r = b.patch[idx], b.sample[idx]
        kc = int(size[f[-1]])  # the chunk's widest patch: sizes increase along ``order``
        rank = torch.arange(lo, lo + n, device=dev) - first[f]
        valid = k[:kc] < size[f][:, None]
        dest = torch.where(valid, crow[r].long()[:, None] + k[:kc], sink).flatten()
        dest_t = torch.where(valid, start[f, :kc] + rank[:, None], sink).flatten()
        C_f = torch.index_select(C[:, :, :kc], 0, f, out=C_ws[:n * S * kc].view(n, S, kc))
        values = torch.bmm(b.weights(b.params[idx]), C_f,
                           out=values_ws[:n * 3 * kc].view(n, 3, kc))
        col.index_copy_(0, dest, b.patches.cols[f, :kc].flatten().to(col.dtype))
        row_t.index_copy_(0, dest_t, r.to(row_t.dtype)[:, None].expand(-1, kc).flatten())
        for i in range(3):  # position, d/du, d/dv
            flat = values[:, i].flatten()
            w[i].index_copy_(0, dest, flat)
            w_t[i].index_copy_(0, dest_t, flat)


def _kept_offsets(crow: torch.Tensor, keep: torch.Tensor) -> torch.Tensor:
    kept_before = torch.zeros(keep.numel() + 1, dtype=crow.dtype, device=crow.device)
    kept_before[1:] = torch.cumsum(keep, 0)
    return kept_before[crow.long()]


def _empty(num_rows, num_cols, dtype, device) -> StencilMatrix:
    index = index_dtype(num_rows, num_cols)
    zero = torch.zeros(0, dtype=index, device=device)
    empty_w = torch.zeros(0, dtype=dtype, device=device)
    return StencilMatrix(torch.zeros(num_rows + 1, dtype=index, device=device), zero, empty_w,
                         torch.zeros(num_cols + 1, dtype=index, device=device), zero, empty_w)
