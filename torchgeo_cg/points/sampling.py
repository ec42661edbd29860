"""Farthest point sampling, exact, batched and ragged.

Convention:
    - Greedy: the first pick is ``start``; each next pick is the valid point whose
      squared distance to the picks so far is largest (the 2-approximation of the
      k-center problem, as PyTorch3D's ``sample_farthest_points``).
    - Ties go to the smaller index. A point is never picked twice while
      ``k <= lengths``: picked points are excluded, so coincident points are taken in
      index order once only they remain.
    - Ragged batches: rows at or past ``lengths`` are padding and never picked. Picks
      past the number of valid points get ``indices = -1`` and zero points.
    - A point with a NaN coordinate has NaN distances; ``argmax`` takes NaN as the
      largest, so it is picked (and NaN shows in the output) once it is reached.
    - Scale-free: the distances are compared, never thresholded, so the picks of
      ``s * points`` are those of ``points``.
    - The sampled points are gathered from ``points`` and carry its gradient.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.core.numerics import working_dtype
from torchgeo_cg.engine import kernel_ready, resolve_backend
from torchgeo_cg.points._fps_kernels import warp_fps
from torchgeo_cg.points._search import check_lengths

__all__ = ["SampleResult", "farthest_point_sampling"]


class SampleResult(NamedTuple):
    """Result of :func:`farthest_point_sampling`.

    Attributes:
        points: ``(*, k, D)`` the picked points, in pick order (zero where padded).
        indices: ``(*, k)`` long, their rows in ``points`` (``-1`` where padded).

    Example:
        >>> pts = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.1, 0.0], [3.0, 0.0]])
        >>> picked = farthest_point_sampling(pts, 2)
        >>> picked.indices, picked.points
        (tensor([0, 3]), tensor([[0., 0.],
                [3., 0.]]))
    """

    points: torch.Tensor
    indices: torch.Tensor


def _check_k_start(k, start) -> None:
    if isinstance(k, bool) or not isinstance(k, int) or k < 0:
        raise ValueError(f"k: expected a non-negative int, got {k!r}")
    if isinstance(start, bool) or not isinstance(start, int) or start < 0:
        raise ValueError(f"start: expected a non-negative int, got {start!r}")


def _pick_indices(p_bnd: torch.Tensor, len_b: torch.Tensor, k: int, start: int) -> torch.Tensor:
    """Greedy picks ``(B, k)`` (``-1`` past the valid points)."""
    B, N, _ = p_bnd.shape
    rows = torch.arange(B, device=p_bnd.device)
    valid_bn = torch.arange(N, device=p_bnd.device) < len_b[:, None]
    # -inf: padding, -1: picked (below every distance, so never picked again)
    best_bn = torch.where(valid_bn, float("inf"), float("-inf")).to(p_bnd.dtype)
    out_bk = torch.full((B, k), -1, dtype=torch.long, device=p_bnd.device)
    pick_b = torch.full((B,), start, dtype=torch.long, device=p_bnd.device)
    for i in range(k):  # loop over the picks, not the points
        ok_b = i < len_b
        out_bk[:, i] = torch.where(ok_b, pick_b, -1)
        safe_b = pick_b.clamp_max(N - 1)
        last_bd = p_bnd[rows, safe_b]
        d2_bn = (p_bnd - last_bd[:, None, :]).square().sum(-1)
        best_bn = torch.minimum(best_bn, d2_bn)  # NaN propagates: NaN is picked next
        best_bn[rows, safe_b] = torch.where(ok_b, -1.0, best_bn[rows, safe_b])
        best_bn = torch.where(valid_bn, best_bn, float("-inf"))
        pick_b = best_bn.argmax(-1)
    return out_bk


def farthest_point_sampling(
    points: torch.Tensor, k: int, lengths: torch.Tensor | None = None, start: int = 0,
    *, backend: str = "auto",
) -> SampleResult:
    """Pick ``k`` points of every cloud, each the farthest from those picked before.

    Convention:
        See the module docstring: greedy from ``start``, ties to the smaller index, no
        duplicates while ``k <= lengths``, padding ``-1``. Exact (no random start, no
        approximation). Differentiable w.r.t. ``points`` through the gather (the picks
        are constants).

    Args:
        points: ``(*, N, D)`` floating point.
        k: number of picks, ``>= 0`` (may exceed ``N``: the rest is padding).
        lengths: ``(*,)`` integer, valid rows per cloud (default ``N``).
        start: index of the first pick, ``< lengths`` of every non-empty cloud.
        backend: ``"auto"``, ``"torch"`` or ``"warp"`` (a compiled loop, one thread per
            cloud; see :func:`torchgeo_cg.engine.resolve_backend`); identical picks.

    Returns:
        :class:`SampleResult` ``(points (*, k, D), indices (*, k))``.

    Example:
        >>> p = torch.tensor([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [3.0, 1.0]])
        >>> farthest_point_sampling(p, 3).indices
        tensor([0, 3, 1])
        >>> farthest_point_sampling(p[None], 3, lengths=torch.tensor([2])).indices
        tensor([[ 0,  1, -1]])
    """
    check_float(points, "points")
    s = check_shape(points, ["*", "N", "D"], "points")
    _check_k_start(k, start)
    batch, N, D = s["*"], s["N"], s["D"]
    len_ = check_lengths(lengths, batch, N, "lengths", points.device)
    if len_.numel() and bool(((len_ > 0) & (len_ <= start)).any()):
        raise ValueError(f"start: expected an index below every non-zero length, got {start} "
                         f"with lengths down to {int(len_[len_ > 0].min())}")
    backend = resolve_backend(backend, points.device)
    B = math.prod(batch)
    p_bnd = points.reshape(B, N, D)
    if N == 0 or k == 0:
        return SampleResult(points.new_zeros(*batch, k, D),
                            torch.full((*batch, k), -1, dtype=torch.long, device=points.device))
    with torch.no_grad():
        p_work = p_bnd.detach().to(working_dtype(points.dtype)).contiguous()
        kernel = (backend == "warp" and D in (2, 3) and kernel_ready(p_work)
                  and bool(torch.isfinite(p_work).all()))
        pick = warp_fps if kernel else _pick_indices  # NaN rules: the torch loop
        idx_bk = pick(p_work, len_.reshape(B), k, start)
    picked = torch.gather(p_bnd, 1, idx_bk.clamp_min(0)[..., None].expand(B, k, D))
    picked = torch.where((idx_bk >= 0)[..., None], picked, torch.zeros_like(picked))
    return SampleResult(picked.reshape(*batch, k, D), idx_bk.reshape(*batch, k))
