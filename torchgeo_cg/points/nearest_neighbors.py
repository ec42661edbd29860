"""k nearest neighbours between point clouds, batched, ragged and differentiable.

The neighbours are *found* without gradients by an exact search: with
``backend="warp"`` (the default where NVIDIA Warp loads) a compiled kernel on a uniform
grid (:mod:`torchgeo_cg.points._knn_kernels`, CPU and CUDA, ``D`` in {2, 3}); with
``backend="torch"`` a uniform grid of sorted cells on the CPU for ``D <= 3``
(:mod:`torchgeo_cg.points._search_grid`, no quadratic distance matrix), or chunked
brute force for small inputs, on CUDA and for ``D > 3``
(:mod:`torchgeo_cg.points._search_brute`). The distances are then *computed* from the
found indices with differentiable torch ops, so gradients flow to both point
sets (the neighbour assignment is piecewise constant, as in PyTorch3D's ``knn_points``).

Convention:
    - ``dists`` are squared Euclidean distances ``|q - r|^2``, as in PyTorch3D.
    - ``query`` and ``reference`` share one float dtype (a ``TypeError`` naming both
      otherwise); float16/bfloat16 are searched and computed in float32 and the
      distances returned in the input dtype (saturating at its largest value).
    - Neighbours are sorted by distance; ties go to the smaller reference index.
    - Ragged batches: rows at or past ``query_lengths`` / ``reference_lengths`` are
      padding. Padded query rows and missing neighbours (``k`` larger than the
      number of valid references) get ``idx = -1`` and ``dists = 0`` (no gradient).
    - Non-finite input: a query with a NaN/inf coordinate, or every query of a batch
      item whose valid references contain one, gets ``idx = -1`` and ``dists = NaN``.
    - Scale-free: the search runs on the coordinates divided by a power of two per batch
      item (exact), so the neighbours of ``s * query`` among ``s * reference`` are the
      same for every finite ``s``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_broadcastable, check_float, check_shape
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.engine import kernel_ready, resolve_backend
from torchgeo_cg.points._search import check_lengths, find_neighbours, search_scale

__all__ = ["KNNResult", "knn"]

class KNNResult(NamedTuple):
    """Result of :func:`knn`.

    Attributes:
        dists: ``(*, N, k)`` squared distances, ascending (0 at padded entries).
        idx: ``(*, N, k)`` long indices into the reference rows (``-1`` at padded entries).
    """

    dists: torch.Tensor
    idx: torch.Tensor


def _prepare(query, reference, k, query_lengths, reference_lengths):
    check_float(query, "query")
    check_float(reference, "reference")
    sq = check_shape(query, ["*", "N", "D"], "query")
    sr = check_shape(reference, ["*", "M", "D"], "reference", {"D": sq["D"]})
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise ValueError(f"k: expected a positive int, got {k!r}")
    if query.dtype != reference.dtype:
        raise TypeError(f"reference: expected dtype {query.dtype} (of query), "
                        f"got {reference.dtype}")
    batch = check_broadcastable({"query": sq["*"], "reference": sr["*"]})
    query = query.expand(*batch, *query.shape[-2:])
    reference = reference.expand(*batch, *reference.shape[-2:])
    ql = check_lengths(query_lengths, batch, sq["N"], "query_lengths", query.device)
    rl = check_lengths(reference_lengths, batch, sr["M"], "reference_lengths", query.device)
    return query, reference, ql, rl, batch


def knn(
    query: torch.Tensor,
    reference: torch.Tensor,
    k: int = 1,
    query_lengths: torch.Tensor | None = None,
    reference_lengths: torch.Tensor | None = None,
    *,
    backend: str = "auto",
) -> KNNResult:
    """The ``k`` nearest reference points of every query point, exact.

    Convention:
        See the module docstring: squared distances, ascending, ties to the smaller
        index; padding gives ``idx = -1``, ``dists = 0``. Differentiable w.r.t.
        ``query`` and ``reference`` (the indices are constants).

    Args:
        query: ``(*, N, D)`` floating point.
        reference: ``(*, M, D)``, same dtype; batch dims broadcast with ``query``'s.
        k: number of neighbours, ``>= 1`` (may exceed ``M``: the rest is padding).
        query_lengths: ``(*,)`` integer, valid query rows per batch item (default ``N``).
        reference_lengths: ``(*,)`` integer, valid reference rows (default ``M``).
        backend: ``"auto"``, ``"torch"`` or ``"warp"`` (the compiled kernel, for ``D`` in
            {2, 3}; see :func:`torchgeo_cg.engine.resolve_backend`). Both give identical
            indices and distances.

    Returns:
        :class:`KNNResult` ``(dists (*, N, k), idx (*, N, k))``.

    Example:
        >>> q = torch.tensor([[0.0, 0.0], [2.9, 0.0]])
        >>> r = torch.tensor([[1.0, 0.0], [3.0, 0.0], [-1.0, 0.0]])
        >>> res = knn(q, r, k=2)
        >>> res.idx
        tensor([[0, 2],
                [1, 0]])
        >>> res.dists
        tensor([[1.0000, 1.0000],
                [0.0100, 3.6100]])
    """
    query, reference, ql, rl, batch = _prepare(query, reference, k, query_lengths,
                                               reference_lengths)
    backend = resolve_backend(backend, query.device)
    if not kernel_ready(query, reference):  # under torch.func or tracing: torch path
        backend = "torch"
    dtype = query.dtype  # float16/bfloat16: searched and computed in float32
    query, reference = query.to(working_dtype(dtype)), reference.to(working_dtype(dtype))
    N, D = query.shape[-2:]
    M = reference.shape[-2]
    B = math.prod(batch)
    q_bnd = query.reshape(B, N, D)
    r_bmd = reference.reshape(B, M, D)
    ql_b, rl_b = ql.reshape(-1), rl.reshape(-1)
    with torch.no_grad():
        q_ok_bn = torch.isfinite(q_bnd).all(-1)
        r_valid_bm = torch.arange(M, device=r_bmd.device) < rl_b[:, None]
        r_ok_b = (torch.isfinite(r_bmd).all(-1) | ~r_valid_bm).all(-1)
        q_clean = torch.where(q_ok_bn[..., None], q_bnd.detach(), torch.zeros_like(q_bnd))
        r_clean = torch.where(torch.isfinite(r_bmd), r_bmd.detach(), torch.zeros_like(r_bmd))
        scale_b11 = search_scale(q_clean, r_clean, ql_b, rl_b)  # exact: a power of two
        idx_bnk = find_neighbours(q_clean / scale_b11, r_clean / scale_b11, k, ql_b, rl_b,
                                  backend)
        bad_bn = (~q_ok_bn | ~r_ok_b[:, None]) & (torch.arange(N, device=q_bnd.device)
                                                   < ql_b[:, None])
        idx_bnk = idx_bnk.masked_fill(bad_bn[..., None], -1)
    found_bnk = idx_bnk >= 0
    if M == 0:  # nothing to gather from: every neighbour is padding
        r_bmd = r_bmd.new_zeros(r_bmd.shape[0], 1, D)
    near_bnkd = torch.gather(r_bmd, 1, idx_bnk.clamp_min(0).flatten(1)[..., None]
                             .expand(-1, -1, D)).reshape(*idx_bnk.shape, D)
    d2_bnk = (q_bnd[:, :, None, :] - near_bnkd).square().sum(-1)
    d2_bnk = torch.where(found_bnk, d2_bnk, torch.zeros_like(d2_bnk))
    d2_bnk = torch.where(bad_bn[..., None], torch.full_like(d2_bnk, float("nan")), d2_bnk)
    return KNNResult(cast_back(d2_bnk.reshape(*batch, N, k), dtype),
                     idx_bnk.reshape(*batch, N, k))
