"""Closed-form, batched least-squares estimation of transforms from point correspondences.

- :func:`find_affine`: linear least squares (6 dof).
- :func:`find_similarity`: Umeyama (1991), rotation + uniform scale + translation.
- :func:`find_euclidean`: rotation + translation (Kabsch / Umeyama without scale).
- :func:`find_translation`: the weighted mean offset.

Convention:
    - Column vectors: the returned ``dst_from_src`` maps ``dst = M @ [x, y, 1]^T``, as
      :func:`transform_points` applies it.
    - Points are ``(x, y)``; every function is batched over leading dims ``(*)``.
    - ``weights`` (optional, ``(*, N)``, non-negative) multiply each
      correspondence's *squared* residual; a weight of 0 removes a point.
    - float16/bfloat16 inputs are computed in float32 and returned in their dtype.
    - Degenerate input (too few points, collinear or coincident points) never
      gives NaN or inf: the affine family falls back to the minimum-norm
      least-squares solution.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.numerics import cast_back
from torchgeo_cg.transforms._correspondences import (
    check_pair,
    effective_weights,
    point_norm,
    to_working,
    weighted_mean,
)

__all__ = [
    "find_affine",
    "find_similarity",
    "find_euclidean",
    "find_translation",
]


def _centered_stats(src, dst, weights):
    """Weighted centroids (*, 2) and centered points (*, N, 2) of both sets, weights (*, N)."""
    w = effective_weights(src, weights)
    cs, cd = weighted_mean(src, w), weighted_mean(dst, w)
    return w, cs, cd, src - cs[..., None, :], dst - cd[..., None, :]


def _affine_from(lin: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """(*, 2, 2) linear part and (*, 2) translation -> (*, 3, 3)."""
    top = torch.cat([lin, t[..., None]], dim=-1)  # (*, 2, 3)
    bottom = torch.zeros_like(top[..., :1, :])
    bottom = torch.cat([bottom[..., :2], torch.ones_like(bottom[..., 2:])], dim=-1)
    return torch.cat([top, bottom], dim=-2)


def find_affine(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Least-squares affine ``dst_from_src``: minimizes ``Σ w ‖A p + t - q‖²``, batched.

    Closed form: ``A = (Σ w q̃ p̃ᵀ)(Σ w p̃ p̃ᵀ)⁺`` on centered points, ``t = q̄ - A p̄``.

    Convention:
        Column vectors; result ``[[a, b, tx], [c, d, ty], [0, 0, 1]]``. For
        collinear ``src`` the covariance is rank 1 and its pseudo-inverse
        ``C / tr(C)²`` gives the minimum-norm solution; coincident ``src`` give
        ``A = 0``. Always finite; differentiable.

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        >>> find_affine(src, src @ torch.tensor([[2.0, 0.0], [1.0, 1.0]]) + 1.0)
        tensor([[2., 1., 1.],
                [0., 1., 1.],
                [0., 0., 1.]])
    """
    weights = check_pair(src, dst, weights)
    low = src.dtype
    src, dst, weights = to_working(src, dst, weights)
    w, cs, cd, ps, qs = _centered_stats(src, dst, weights)
    cov_pp = ps.mT @ (ps * w[..., None])  # (*, 2, 2) Σ w p̃ p̃ᵀ
    cov_qp = qs.mT @ (ps * w[..., None])  # (*, 2, 2) Σ w q̃ p̃ᵀ
    a, b, d = cov_pp[..., 0, 0], cov_pp[..., 0, 1], cov_pp[..., 1, 1]
    det = a * d - b * b
    tr = a + d
    full = det.abs() > 1e-10 * tr * tr  # full rank, relative to scale
    rank1 = ~full & (tr > 0)
    det_safe = torch.where(full, det, torch.ones_like(det))
    tr2_safe = torch.where(rank1, tr * tr, torch.ones_like(tr))
    adj = torch.stack([d, -b, -b, a], dim=-1).unflatten(-1, (2, 2))
    inv_full = adj / det_safe[..., None, None]
    inv_rank1 = cov_pp / tr2_safe[..., None, None]  # pseudo-inverse of a rank-1 PSD matrix
    pinv = torch.where(full[..., None, None], inv_full,
                       torch.where(rank1[..., None, None], inv_rank1, torch.zeros_like(inv_full)))
    pinv = torch.where(torch.isnan(tr)[..., None, None], tr[..., None, None], pinv)  # NaN kept
    lin = cov_qp @ pinv  # (*, 2, 2)
    t = cd - (lin @ cs[..., None]).squeeze(-1)
    return cast_back(_affine_from(lin, t), low)


def _rotation_scale(src, dst, weights):
    """2D Umeyama terms: centroids, Σ w p̃·q̃, Σ w p̃×q̃, Σ w ‖p̃‖²."""
    w, cs, cd, ps, qs = _centered_stats(src, dst, weights)
    dot = ((ps * qs).sum(-1) * w).sum(-1)  # (*)
    cross = ((ps[..., 0] * qs[..., 1] - ps[..., 1] * qs[..., 0]) * w).sum(-1)  # (*)
    var = (ps.square().sum(-1) * w).sum(-1)  # (*)
    return cs, cd, dot, cross, var


def _from_cos_sin(cos, sin, cs, cd):
    lin = torch.stack([cos, -sin, sin, cos], dim=-1).unflatten(-1, (2, 2))
    return _affine_from(lin, cd - (lin @ cs[..., None]).squeeze(-1))


def find_similarity(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Least-squares similarity ``dst_from_src`` (Umeyama 1991), batched.

    Minimizes ``Σ w ‖s R p + t - q‖²`` over rotations ``R`` (det +1, no
    reflection), scales ``s >= 0`` and ``t``. In 2D Umeyama's SVD reduces to
    ``s cos θ = Σ w p̃·q̃ / Σ w ‖p̃‖²`` and ``s sin θ = Σ w p̃×q̃ / Σ w ‖p̃‖²``.

    Convention:
        Column vectors; ``[[s cos θ, -s sin θ, tx], [s sin θ, s cos θ, ty], [0, 0, 1]]``
        with θ counter-clockwise. Coincident ``src`` give ``s = 0``. Always
        finite; differentiable.

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        >>> dst = torch.tensor([[1.0, 1.0], [1.0, 3.0], [-1.0, 1.0]])  # R(90°)·S(2) then T(1, 1)
        >>> find_similarity(src, dst).round(decimals=6) + 0.0
        tensor([[ 0., -2.,  1.],
                [ 2.,  0.,  1.],
                [ 0.,  0.,  1.]])
    """
    weights = check_pair(src, dst, weights)
    low = src.dtype
    cs, cd, dot, cross, var = _rotation_scale(*to_working(src, dst, weights))
    ok = var != 0  # NaN passes through
    var_safe = torch.where(ok, var, torch.ones_like(var))
    zero = torch.zeros_like(var)
    return cast_back(_from_cos_sin(torch.where(ok, dot / var_safe, zero),
                                   torch.where(ok, cross / var_safe, zero), cs, cd), low)


def find_euclidean(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Least-squares rigid motion ``dst_from_src`` (rotation + translation), batched.

    Minimizes ``Σ w ‖R p + t - q‖²``: ``θ = atan2(Σ w p̃×q̃, Σ w p̃·q̃)`` (the 2D
    Kabsch / Umeyama solution without scale).

    Convention:
        Column vectors; θ counter-clockwise. Where the angle is undefined
        (coincident points) ``R = I``. Always finite; differentiable.

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        >>> find_euclidean(src, src.flip(-1) * torch.tensor([-1.0, 1.0])).round(decimals=6) + 0.0
        tensor([[ 0., -1.,  0.],
                [ 1.,  0.,  0.],
                [ 0.,  0.,  1.]])
    """
    weights = check_pair(src, dst, weights)
    low = src.dtype
    cs, cd, dot, cross, _ = _rotation_scale(*to_working(src, dst, weights))
    length = point_norm(dot, cross)  # scale-free: only exactly (0, 0) is undefined
    ok = length != 0  # NaN passes through
    length_safe = torch.where(ok, length, torch.ones_like(length))
    cos = torch.where(ok, dot / length_safe, torch.ones_like(dot))
    sin = torch.where(ok, cross / length_safe, torch.zeros_like(dot))
    return cast_back(_from_cos_sin(cos, sin, cs, cd), low)


def find_translation(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Least-squares translation ``dst_from_src``: ``t = Σ w (q - p) / Σ w``, batched.

    Convention:
        Column vectors; ``[[1, 0, tx], [0, 1, ty], [0, 0, 1]]``.

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
        >>> find_translation(src, src + torch.tensor([5.0, 1.0]))
        tensor([[1., 0., 5.],
                [0., 1., 1.],
                [0., 0., 1.]])
    """
    weights = check_pair(src, dst, weights)
    low = src.dtype
    src, dst, weights = to_working(src, dst, weights)
    w = effective_weights(src, weights)
    t = weighted_mean(dst - src, w)
    eye = torch.eye(2, dtype=src.dtype, device=src.device).expand(*t.shape[:-1], 2, 2)
    return cast_back(_affine_from(eye, t), low)
