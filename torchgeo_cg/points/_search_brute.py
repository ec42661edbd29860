"""Exact k-nearest-neighbour indices by chunked brute force (small inputs, CUDA, D > 3).

Convention:
    - Squared Euclidean distances ``|q - r|^2`` computed as sums of squared differences
      (not the ``|q|^2 - 2 q.r + |r|^2`` expansion, which cancels catastrophically).
    - Ties are broken by the smaller reference index, so the result is deterministic.
    - Reference rows at or past ``reference_lengths`` are never returned; when a batch
      item has fewer than ``k`` references the missing neighbours get index ``-1``.
"""

from __future__ import annotations

import torch

__all__: list[str] = []

#: Largest number of (query, reference, coordinate) products held at once.
CHUNK_ELEMENTS = 1 << 22


def brute_knn_indices(
    query_bnd: torch.Tensor, reference_bmd: torch.Tensor, k: int, reference_lengths_b: torch.Tensor
) -> torch.Tensor:
    """Indices ``(B, N, k)`` of the ``k`` nearest references of every query, ``-1`` if none.

    Convention:
        See the module docstring; no gradient (indices only).

    Args:
        query_bnd: ``(B, N, D)`` finite queries.
        reference_bmd: ``(B, M, D)`` finite references.
        k: number of neighbours, ``>= 1``.
        reference_lengths_b: ``(B,)`` long, valid references per batch item.

    Returns:
        ``(B, N, k)`` long.

    Example:
        >>> q = torch.tensor([[[0.0, 0.0], [2.9, 0.0]]])
        >>> r = torch.tensor([[[1.0, 0.0], [3.0, 0.0], [-1.0, 0.0]]])
        >>> brute_knn_indices(q, r, 2, torch.tensor([3]))
        tensor([[[0, 2],
                 [1, 0]]])
    """
    B, N, D = query_bnd.shape
    M = reference_bmd.shape[1]
    out_bnk = query_bnd.new_full((B, N, k), -1, dtype=torch.long)
    if N == 0 or M == 0:
        return out_bnk
    kk = min(k, M)
    valid_bm = torch.arange(M, device=query_bnd.device) < reference_lengths_b[:, None]
    step = max(1, CHUNK_ELEMENTS // max(1, B * M * D))
    with torch.no_grad():
        for start in range(0, N, step):  # loop over memory chunks, not points
            q = query_bnd[:, start : start + step]
            d2_bnm = (q[:, :, None, :] - reference_bmd[:, None, :, :]).square().sum(-1)
            d2_bnm = d2_bnm.masked_fill(~valid_bm[:, None, :], float("inf"))
            if kk == 1:
                d2_bnk, idx_bnk = d2_bnm.min(dim=-1, keepdim=True)  # first minimum on ties
            else:
                d2_bnm, order = torch.sort(d2_bnm, dim=-1, stable=True)
                d2_bnk, idx_bnk = d2_bnm[..., :kk], order[..., :kk]
            out_bnk[:, start : start + step, :kk] = idx_bnk.masked_fill(d2_bnk.isinf(), -1)
    return out_bnk
