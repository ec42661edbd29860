"""Chamfer distance between point clouds, batched, ragged and differentiable.

Convention:
    - ``a_to_b[i] = min_j |a_i - b_j|^2`` (``squared=True``) or ``min_j |a_i - b_j|``, and
      ``b_to_a`` likewise; padded rows (past ``a_lengths`` / ``b_lengths``) hold 0, and so
      does every row of an item whose other cloud is empty.
    - The loss of one batch item is ``mean_i a_to_b[i] + mean_j b_to_a[j]`` over its
      valid rows (an empty cloud contributes 0), as in PyTorch3D's default
      ``point_reduction="mean"``. ``reduction="mean"`` averages it over the batch,
      ``"sum"`` adds every valid ``a_to_b`` and ``b_to_a`` entry of the batch (no
      division), ``"none"`` returns the per-item losses ``(*,)``.
    - ``a`` and ``b`` share one float dtype (a ``TypeError`` naming both otherwise);
      float16/bfloat16 are computed in float32 and returned in the input dtype.
    - Both directions are found in one exact :func:`~torchgeo_cg.points.nearest_neighbors.knn` call.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from torchgeo_cg.core.check import check_broadcastable, check_choice, check_float, check_shape
from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.core.numerics import cast_back, safe_norm, working_dtype
from torchgeo_cg.points._search import check_lengths
from torchgeo_cg.points.nearest_neighbors import knn

__all__ = ["ChamferResult", "chamfer_distance", "ChamferDistance"]

_REDUCTIONS = ("mean", "sum", "none")


class ChamferResult(NamedTuple):
    """Result of :func:`chamfer_distance`.

    Attributes:
        loss: ``()`` for ``"mean"``/``"sum"``, ``(*,)`` for ``"none"``.
        a_to_b: ``(*, N)`` distance of each point of ``a`` to ``b``.
        b_to_a: ``(*, M)`` distance of each point of ``b`` to ``a``.
    """

    loss: torch.Tensor
    a_to_b: torch.Tensor
    b_to_a: torch.Tensor


def _pad_rows(x: torch.Tensor, rows: int) -> torch.Tensor:
    if x.shape[-2] == rows:
        return x
    pad = x.new_zeros(*x.shape[:-2], rows - x.shape[-2], x.shape[-1])
    return torch.cat([x, pad], dim=-2)


def _both_ways(a, b, al, bl, squared: bool):
    """Nearest-neighbour (squared) distances a -> b and b -> a from one knn call.

    Distances (``squared=False``) are the norms of the differences (overflow- and
    underflow-safe), not square roots of squares, which lose range at extreme scales."""
    N, M = a.shape[-2], b.shape[-2]
    L = max(N, M)
    query = torch.stack([_pad_rows(a, L), _pad_rows(b, L)])
    reference = torch.stack([_pad_rows(b, L), _pad_rows(a, L)])
    lengths_q = torch.stack([al, bl])
    lengths_r = torch.stack([bl, al])
    found = knn(query, reference, 1, lengths_q, lengths_r)
    d = found.dists[..., 0]
    if not squared:  # where idx = -1, d is 0 (padding) or NaN (non-finite input)
        idx = found.idx[..., 0]
        near = torch.gather(reference, -2, idx.clamp_min(0)[..., None].expand_as(query))
        d = torch.where(idx >= 0, safe_norm(query - near, dim=-1), d)
    return d[0, ..., :N], d[1, ..., :M]


def chamfer_distance(
    a: torch.Tensor,
    b: torch.Tensor,
    a_lengths: torch.Tensor | None = None,
    b_lengths: torch.Tensor | None = None,
    reduction: str = "mean",
    squared: bool = True,
) -> ChamferResult:
    """Symmetric Chamfer distance between point clouds ``a`` and ``b``, exact.

    Convention:
        See the module docstring. Differentiable w.r.t. ``a`` and ``b``; with
        ``squared=False`` the gradient of a zero distance is 0 (not NaN).

    Args:
        a: ``(*, N, D)`` floating point.
        b: ``(*, M, D)``, same dtype; batch dims broadcast with ``a``'s.
        a_lengths: ``(*,)`` integer valid rows of ``a`` (default ``N``).
        b_lengths: ``(*,)`` integer valid rows of ``b`` (default ``M``).
        reduction: ``"mean"``, ``"sum"`` or ``"none"``.
        squared: squared distances (default, as PyTorch3D) or distances.

    Returns:
        :class:`ChamferResult` ``(loss, a_to_b (*, N), b_to_a (*, M))``.

    Example:
        >>> a = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
        >>> b = torch.tensor([[0.0, 0.5], [1.0, 0.0], [3.0, 0.0]])
        >>> res = chamfer_distance(a, b)
        >>> res.a_to_b, res.b_to_a
        (tensor([0.2500, 0.0000]), tensor([0.2500, 0.0000, 4.0000]))
        >>> res.loss
        tensor(1.5417)
    """
    check_choice(reduction, _REDUCTIONS, "reduction")
    check_float(a, "a")
    check_float(b, "b")
    sa = check_shape(a, ["*", "N", "D"], "a")
    sb = check_shape(b, ["*", "M", "D"], "b", {"D": sa["D"]})
    if a.dtype != b.dtype:
        raise TypeError(f"b: expected dtype {a.dtype} (of a), got {b.dtype}")
    batch = check_broadcastable({"a": sa["*"], "b": sb["*"]})
    a = a.expand(*batch, *a.shape[-2:])
    b = b.expand(*batch, *b.shape[-2:])
    al = check_lengths(a_lengths, batch, sa["N"], "a_lengths", a.device)
    bl = check_lengths(b_lengths, batch, sb["M"], "b_lengths", a.device)
    dtype = a.dtype  # float16/bfloat16: computed in float32, returned in the input dtype
    a_to_b, b_to_a = _both_ways(a.to(working_dtype(dtype)), b.to(working_dtype(dtype)), al, bl,
                                squared)
    if reduction == "sum":
        loss = a_to_b.sum() + b_to_a.sum()
    else:
        per_item = (a_to_b.sum(-1) / al.clamp_min(1).to(a_to_b)
                    + b_to_a.sum(-1) / bl.clamp_min(1).to(b_to_a))
        loss = per_item if reduction == "none" else per_item.sum() / max(per_item.numel(), 1)
    return ChamferResult(*(cast_back(x, dtype) for x in (loss, a_to_b, b_to_a)))


class ChamferDistance(nn.Module):
    """Module form of :func:`chamfer_distance` with the same defaults.

    Example:
        >>> ChamferDistance()(torch.zeros(1, 3), torch.ones(2, 3)).loss
        tensor(6.)
    """

    def __init__(self, reduction: str = "mean", squared: bool = True):
        super().__init__()
        check_choice(reduction, _REDUCTIONS, "reduction")
        self.reduction = reduction
        self.squared = bool(squared)

    def forward(self, a, b, a_lengths=None, b_lengths=None) -> ChamferResult:
        check_module_dtype(self, a, "a")
        return chamfer_distance(a, b, a_lengths, b_lengths, self.reduction, self.squared)
