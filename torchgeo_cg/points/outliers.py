"""Outlier removal: boolean inlier masks equal to Open3D's ``remove_statistical_outlier``
and ``remove_radius_outlier`` index sets.

Convention:
    - The neighbours of a point are found in its own cloud and include the point itself
      (as Open3D's KD-tree search returns it); the decisions are made in float64 on
      squared distances recomputed from the found indices.
    - Statistical (Open3D's rules): ``m_i`` is the mean distance from point ``i`` to its
      ``k`` nearest points (fewer when the cloud is smaller); the cloud's mean ``mu`` is
      over the points with ``m_i > 0``, divided by the number of points; the standard
      deviation ``sigma`` sums ``(m_i - mu)^2`` over the same points with Bessel's
      correction (``n - 1``); a point is an inlier when ``0 < m_i < mu + std_ratio *
      sigma`` (strict). A point whose ``k`` neighbours all coincide with it
      (``m_i = 0``) is therefore not an inlier, and a cloud of one point has none.
    - Radius (Open3D's rule): a point is an inlier when more than ``min_neighbors``
      points (itself included) lie strictly within ``radius`` (``|p - q| < radius``).
    - Non-finite points are never inliers and never neighbours; rows past ``lengths`` are
      padding (False); each cloud of a batch is judged alone.
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.engine import kernel_ready, resolve_backend
from torchgeo_cg.points._outlier_kernels import warp_radius_inliers
from torchgeo_cg.points._search import (
    check_lengths,
    check_positive,
    compact_finite,
    gather_d2,
    self_knn,
)

__all__ = ["remove_radius_outliers", "remove_statistical_outliers"]


def _prepare(points, lengths, name="points"):
    check_float(points, name)
    s = check_shape(points, ["*", "N", "D"], name)
    batch, N, D = s["*"], s["N"], s["D"]
    len_ = check_lengths(lengths, batch, N, "lengths", points.device)
    B = math.prod(batch)
    p = points.detach().to(torch.float64).reshape(B, N, D)
    return p, len_.reshape(B), batch


def remove_statistical_outliers(
    points: torch.Tensor, k: int, std_ratio: float, *, lengths: torch.Tensor | None = None,
    backend: str = "auto",
) -> torch.Tensor:
    """Inlier mask of Open3D's statistical outlier removal (``nb_neighbors=k``).

    Convention:
        See the module docstring: ``k`` neighbours including the point itself, mean over
        the points with a positive mean distance, Bessel's correction, strict test.

    Args:
        points: ``(*, N, D)`` floating point.
        k: neighbours per point (itself included), ``>= 1``.
        std_ratio: the threshold in standard deviations, ``>= 0``.
        lengths: ``(*,)`` integer, valid rows per cloud (default ``N``).
        backend: the neighbour search's (``"auto"``, ``"torch"``, ``"warp"``).

    Returns:
        ``(*, N)`` bool, True for inliers.

    Raises:
        ShapeError: bad shape (names ``points``).
        ValueError: ``k < 1`` or ``std_ratio < 0``.

    Example:
        >>> p = torch.tensor([[0.0, 0.0], [0.1, 0.0], [0.0, 0.1], [0.1, 0.1], [5.0, 5.0]])
        >>> remove_statistical_outliers(p, 3, 1.0)
        tensor([ True,  True,  True,  True, False])
    """
    check_positive(k, "k", integer=True)
    if isinstance(std_ratio, bool) or not isinstance(std_ratio, (int, float)) or not (
            math.isfinite(std_ratio) and std_ratio >= 0):
        raise ValueError(f"std_ratio: expected a finite number >= 0, got {std_ratio!r}")
    p, len_b, batch = _prepare(points, lengths)
    backend = resolve_backend(backend, points.device)
    N = p.shape[1]
    if N == 0:
        return torch.zeros(*batch, 0, dtype=torch.bool, device=points.device)
    idx, ok = self_knn(p, len_b, k, backend)
    found = idx >= 0
    dist = gather_d2(p, p, idx).sqrt_().masked_fill_(~found, 0.0)
    mean = dist.sum(-1) / found.sum(-1).clamp_min(1)  # m_i, Open3D's order: sorted
    counted = ok  # every point with a neighbour (itself): Open3D's valid_distances
    n = counted.sum(-1, keepdim=True).to(torch.float64)
    positive = counted & (mean > 0)
    mu = mean.masked_fill(~positive, 0.0).sum(-1, keepdim=True) / n
    sq = (mean - mu).square().masked_fill(~positive, 0.0).sum(-1, keepdim=True)
    sigma = (sq / (n - 1)).sqrt()  # n = 1: 0/0, NaN: no inlier, as Open3D
    inlier = positive & (mean < mu + std_ratio * sigma)
    return inlier.reshape(*batch, N)


def remove_radius_outliers(
    points: torch.Tensor, radius: float, min_neighbors: int, *,
    lengths: torch.Tensor | None = None, backend: str = "auto",
) -> torch.Tensor:
    """Inlier mask of Open3D's radius outlier removal (``nb_points=min_neighbors``).

    Convention:
        See the module docstring: an inlier has more than ``min_neighbors`` points,
        itself included, strictly within ``radius``.

    Args:
        points: ``(*, N, D)`` floating point.
        radius: the radius, ``> 0``.
        min_neighbors: Open3D's ``nb_points``, ``>= 0``.
        lengths: ``(*,)`` integer, valid rows per cloud (default ``N``).
        backend: the neighbour search's (``"auto"``, ``"torch"``, ``"warp"``).

    Returns:
        ``(*, N)`` bool, True for inliers.

    Raises:
        ShapeError: bad shape (names ``points``).
        ValueError: ``radius <= 0`` or ``min_neighbors < 0``.

    Example:
        >>> p = torch.tensor([[0.0, 0.0], [0.1, 0.0], [0.0, 0.1], [5.0, 5.0]])
        >>> remove_radius_outliers(p, 0.5, 2)
        tensor([ True,  True,  True, False])
    """
    radius = check_positive(radius, "radius")
    if isinstance(min_neighbors, bool) or not isinstance(min_neighbors, int) or (
            min_neighbors < 0):
        raise ValueError(f"min_neighbors: expected an int >= 0, got {min_neighbors!r}")
    p, len_b, batch = _prepare(points, lengths)
    backend = resolve_backend(backend, points.device)
    N = p.shape[1]
    k = min_neighbors + 1
    if N == 0:
        return torch.zeros(*batch, 0, dtype=torch.bool, device=points.device)
    if backend == "warp" and p.shape[-1] in (2, 3) and kernel_ready(p):
        packed, count, _ = compact_finite(p, len_b)
        ok = torch.isfinite(p).all(-1) & (torch.arange(N, device=p.device) < len_b[:, None])
        return warp_radius_inliers(p, ok, packed, count, radius, k).reshape(*batch, N)
    idx, ok = self_knn(p, len_b, k, backend)
    kth = idx[..., -1:]
    d2 = gather_d2(p, p, kth)[..., 0]
    inlier = ok & (kth[..., 0] >= 0) & (d2 < radius * radius)
    return inlier.reshape(*batch, N)
