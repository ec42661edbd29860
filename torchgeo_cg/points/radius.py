"""Radius search: every reference point within a distance of each query, nearest first.

Convention:
    - Within means ``|q - r| <= radius`` (the boundary is inside), decided on squared
      distances summed coordinate by coordinate on coordinates divided by a power of two
      (exact), so ``s * query``, ``s * reference``, ``s * radius`` give the same answer.
    - ``idx`` is sorted by distance, ties to the smaller reference index, padded with
      ``-1``; ``dists`` are squared distances recomputed in torch from ``idx``
      (differentiable in both clouds, as :func:`torchgeo_cg.points.knn`), padded with 0.
    - ``counts`` is the true number within the radius; with ``max_neighbors=K`` the
      result holds exactly the ``K`` nearest and ``overflow = counts > K``; with ``None``
      ``K`` is the largest count.
    - Non-finite points: a query with a NaN/inf coordinate has no neighbour (count 0,
      ``dists`` NaN); a reference with one is never a neighbour.
    - No ``N x M`` buffer: the Warp kernel scans a grid of cells of about the radius; the
      torch path runs the exact k-nearest search for a growing ``k``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_broadcastable, check_float, check_shape
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.engine import kernel_ready, resolve_backend
from torchgeo_cg.points._radius_kernels import warp_radius
from torchgeo_cg.points._search import (
    check_lengths,
    check_positive,
    compact_finite,
    find_neighbours,
    gather_d2,
    search_scale,
)
from torchgeo_cg.points._search_grid import build_grid

__all__ = ["RadiusResult", "radius_search"]


class RadiusResult(NamedTuple):
    """Result of :func:`radius_search`.

    Attributes:
        idx: ``(*, N, K)`` long reference indices, nearest first, ``-1`` padding.
        dists: ``(*, N, K)`` squared distances, 0 at padding (NaN for non-finite queries).
        counts: ``(*, N)`` long, the true number of references within the radius.
        overflow: ``(*, N)`` bool, ``counts > K`` (the result was cut).
    """

    idx: torch.Tensor
    dists: torch.Tensor
    counts: torch.Tensor
    overflow: torch.Tensor


def _torch_radius(q, r, ql, rl, radius_b, slots):
    """Counts ``(B, N)`` and the nearest ``slots`` within the radius by knn, doubling
    ``k`` until no query has all its ``k`` neighbours inside."""
    B, N, D = q.shape
    M = r.shape[1]
    r2_b = radius_b * radius_b
    k = min(max(slots or 0, 16), max(M, 1))
    while True:
        idx = find_neighbours(q, r, k, ql, rl)
        inside = (idx >= 0) & (gather_d2(q, r, idx) <= r2_b[:, None, None])
        counts = inside.sum(-1)
        if k >= M or not bool((counts == k).any()):
            break
        k = min(2 * k, M)
    K = slots if slots is not None else int(counts.max()) if counts.numel() else 0
    idx = idx.masked_fill(~inside, -1)[..., :K]
    if idx.shape[-1] < K:
        idx = torch.cat([idx, idx.new_full((B, N, K - idx.shape[-1]), -1)], -1)
    return counts, idx


def _warp_radius(q, r, ql, rl, radius_b, slots):
    B, N, D = q.shape
    valid = (torch.arange(N, device=q.device) < ql[:, None]) & (rl > 0)[:, None]
    qb, qn = valid.nonzero(as_tuple=True)
    if qb.numel() == 0:
        K = slots or 0
        return (torch.zeros(B, N, dtype=torch.long, device=q.device),
                torch.full((B, N, K), -1, dtype=torch.long, device=q.device))
    grid = build_grid(r, rl, 1.0, radius_b)
    rows = qb * N + qn
    q_qd = q.reshape(B * N, D).index_select(0, rows)
    counts = torch.zeros(B * N, dtype=torch.long, device=q.device)
    c, _ = warp_radius(grid, q_qd, qb, radius_b, 0) if slots is None else (None, None)
    K = slots if slots is not None else int(c.max()) if c.numel() else 0
    c, idx_q = warp_radius(grid, q_qd, qb, radius_b, K)
    counts[rows] = c
    idx = torch.full((B * N, K), -1, dtype=torch.long, device=q.device)
    idx[rows] = idx_q
    return counts.reshape(B, N), idx.reshape(B, N, K)


def radius_search(
    query: torch.Tensor,
    ref: torch.Tensor,
    radius: float,
    *,
    max_neighbors: int | None = None,
    query_lengths: torch.Tensor | None = None,
    ref_lengths: torch.Tensor | None = None,
    backend: str = "auto",
) -> RadiusResult:
    """The reference points within ``radius`` of every query point, nearest first.

    Convention:
        See the module docstring: ``|q - r| <= radius``; sorted by distance, ties to the
        smaller index; exactly the ``K`` nearest when cut; squared distances.

    Args:
        query: ``(*, N, D)`` floating point, ``D`` in {2, 3}.
        ref: ``(*, M, D)``, same dtype; batch dims broadcast with ``query``'s.
        radius: the search radius, ``> 0``.
        max_neighbors: ``K``, the most neighbours kept per query (``>= 1``); None: the
            largest count.
        query_lengths: ``(*,)`` integer, valid query rows per batch item (default ``N``).
        ref_lengths: ``(*,)`` integer, valid reference rows (default ``M``).
        backend: ``"auto"``, ``"torch"`` or ``"warp"``; identical results.

    Returns:
        :class:`RadiusResult` ``(idx, dists, counts, overflow)``.

    Raises:
        ShapeError: bad shapes (names the argument).
        ValueError: ``radius <= 0`` or ``max_neighbors < 1``.

    Example:
        >>> q = torch.tensor([[0.0, 0.0], [2.9, 0.0]])
        >>> r = torch.tensor([[1.0, 0.0], [3.0, 0.0], [-1.0, 0.0]])
        >>> res = radius_search(q, r, 1.0)
        >>> res.idx
        tensor([[ 0,  2],
                [ 1, -1]])
        >>> res.counts, res.overflow
        (tensor([2, 1]), tensor([False, False]))
        >>> res.dists
        tensor([[1.0000, 1.0000],
                [0.0100, 0.0000]])
    """
    check_float(query, "query")
    check_float(ref, "ref")
    sq = check_shape(query, ["*", "N", "D"], "query")
    sr = check_shape(ref, ["*", "M", "D"], "ref", {"D": sq["D"]})
    if sq["D"] not in (2, 3):
        raise ValueError(f"query: expected D in {{2, 3}}, got D={sq['D']}")
    if query.dtype != ref.dtype:
        raise TypeError(f"ref: expected dtype {query.dtype} (of query), got {ref.dtype}")
    radius = check_positive(radius, "radius")
    if max_neighbors is not None:
        max_neighbors = int(check_positive(max_neighbors, "max_neighbors", integer=True))
    batch = check_broadcastable({"query": sq["*"], "ref": sr["*"]})
    backend = resolve_backend(backend, query.device)
    if not kernel_ready(query, ref):  # under torch.func or tracing: torch path
        backend = "torch"
    ql = check_lengths(query_lengths, batch, sq["N"], "query_lengths", query.device)
    rl = check_lengths(ref_lengths, batch, sr["M"], "ref_lengths", query.device)
    dtype = query.dtype
    wd = working_dtype(dtype)
    N, D, M = sq["N"], sq["D"], sr["M"]
    B = math.prod(batch)
    q = query.to(wd).expand(*batch, N, D).reshape(B, N, D)
    r = ref.to(wd).expand(*batch, M, D).reshape(B, M, D)
    ql_b, rl_b = ql.reshape(-1), rl.reshape(-1)
    with torch.no_grad():
        q_ok = torch.isfinite(q).all(-1)
        qc = torch.where(q_ok[..., None], q.detach(), 0.0)
        rc, rl_c, keep = compact_finite(r.detach(), rl_b)
        scale = search_scale(qc, rc, ql_b, rl_c)
        radius_b = (torch.tensor(radius, dtype=wd, device=q.device) / scale).reshape(B)
        qs, rs = qc / scale, rc / scale
        search = _warp_radius if backend == "warp" else _torch_radius
        counts, idx = search(qs, rs, ql_b, rl_c, radius_b, max_neighbors)
        counts = counts.masked_fill(~q_ok, 0)
        idx = idx.masked_fill(~q_ok[..., None], -1)
        idx = torch.where(idx >= 0, keep.gather(1, idx.clamp_min(0).flatten(1)).view_as(idx), -1)
    K = idx.shape[-1]
    found = idx >= 0
    near = torch.gather(r if M else r.new_zeros(B, 1, D), 1,
                        idx.clamp_min(0).flatten(1)[..., None].expand(-1, -1, D))
    d2 = (q[:, :, None, :] - near.reshape(B, N, K, D)).square().sum(-1)
    d2 = torch.where(found, d2, torch.zeros_like(d2))
    d2 = torch.where(q_ok[..., None], d2, torch.full_like(d2, float("nan")))
    overflow = counts > K
    return RadiusResult(idx.reshape(*batch, N, K), cast_back(d2.reshape(*batch, N, K), dtype),
                        counts.reshape(*batch, N), overflow.reshape(*batch, N))
