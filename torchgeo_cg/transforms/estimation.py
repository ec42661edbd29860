"""Closed-form, batched least-squares estimation of 2D and 3D transforms from correspondences.

- :func:`find_affine`: linear least squares (6 dof in 2D, 12 in 3D).
- :func:`find_similarity`: Umeyama (1991), rotation + uniform scale + translation.
- :func:`find_euclidean`: rotation + translation (Kabsch / Umeyama without scale).
- :func:`find_translation`: the weighted mean offset.

Each returns a :class:`TransformFit` ``(matrix, rank_ok, condition)``.

Convention:
    - Column vectors: the returned ``dst_from_src`` maps ``dst = M @ [p, 1]^T``, as
      :func:`transform_points` applies it: ``(*, 3, 3)`` for ``(*, N, 2)`` points,
      ``(*, 4, 4)`` for ``(*, N, 3)`` points.
    - Every function is batched over leading dims ``(*)``.
    - ``weights`` (optional, ``(*, N)``, non-negative) multiply each
      correspondence's *squared* residual; a weight of 0 removes a point (this is
      how padded, ragged batches are fitted). Weights are relative: any positive
      scale of them gives the same fit.
    - float16/bfloat16 inputs are computed in float32 and returned in their dtype.
    - Degenerate input (too few points, collinear or coincident points, coplanar
      where the model needs more) never gives NaN or inf; ``rank_ok`` is False.
    - 3D rotations come from Horn's quaternion form (see ``_horn.py``): the same
      optimum as the SVD of Kabsch and Umeyama, with gradients that stay finite
      and correct when singular values repeat (a tetrahedron, a square, a cube).
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.numerics import cast_back
from torchgeo_cg.transforms._closed_3d import affine_3d, rigid_3d, rigid_moments, translation_fit
from torchgeo_cg.transforms._correspondences import (
    TransformFit,
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
    """(*, D, D) linear part and (*, D) translation -> (*, D + 1, D + 1)."""
    top = torch.cat([lin, t[..., None]], dim=-1)  # (*, D, D + 1)
    bottom = torch.zeros_like(top[..., :1, :])
    bottom = torch.cat([bottom[..., :-1], torch.ones_like(bottom[..., -1:])], dim=-1)
    return torch.cat([top, bottom], dim=-2)


def _big(like: torch.Tensor) -> torch.Tensor:
    return torch.full_like(like, torch.finfo(like.dtype).max)


def _fit(matrix, rank_ok, condition, low) -> TransformFit:
    return TransformFit(cast_back(matrix, low), rank_ok, cast_back(condition, low))


def find_affine(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> TransformFit:
    """Least-squares affine ``dst_from_src``: minimizes ``Σ w ‖A p + t - q‖²``, batched.

    Closed form: ``A = (Σ w q̃ p̃ᵀ)(Σ w p̃ p̃ᵀ)⁻¹`` on centered points, ``t = q̄ - A p̄``.

    Convention:
        Column vectors; 2D result ``[[a, b, tx], [c, d, ty], [0, 0, 1]]``, 3D
        ``[[A, t], [0, 1]]``. Degenerate ``src`` (collinear in 2D, coplanar in 3D,
        coincident) is flagged by ``rank_ok``; in 2D the minimum-norm solution
        is returned (pseudo-inverse ``C / tr(C)²`` of a rank-1 covariance,
        ``A = 0`` for coincident points), in 3D a damped one (``C + δI`` with
        ``δ = sqrt(eps) tr C``). Always finite; differentiable.

    Args:
        src: ``(*, N, 2)`` or ``(*, N, 3)`` source points.
        dst: ``(*, N, D)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        :class:`TransformFit` ``(matrix (*, D + 1, D + 1), rank_ok (*), condition (*))``.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        >>> find_affine(src, src @ torch.tensor([[2.0, 0.0], [1.0, 1.0]]) + 1.0).matrix
        tensor([[2., 1., 1.],
                [0., 1., 1.],
                [0., 0., 1.]])
    """
    weights = check_pair(src, dst, weights, dims=(2, 3))
    low = src.dtype
    src, dst, weights = to_working(src, dst, weights)
    w, cs, cd, ps, qs = _centered_stats(src, dst, weights)
    if src.shape[-1] == 3:
        return _fit(*affine_3d(cs, cd, ps, qs, w, low), low)
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
    # λ_max / λ_min = λ_max² / det, λ_max = tr/2 + |((a - d)/2, b)|
    lam = tr / 2 + point_norm((a - d) / 2, b)
    condition = torch.where(full, (lam * lam / det_safe).detach().abs(), _big(tr))
    return _fit(_affine_from(lin, t), full, condition, low)


def _rotation_scale(src, dst, weights):
    """2D Umeyama terms: centroids, Σ w p̃·q̃, Σ w p̃×q̃, Σ w ‖p̃‖², Σ w ‖p̃‖ ‖q̃‖."""
    w, cs, cd, ps, qs = _centered_stats(src, dst, weights)
    dot = ((ps * qs).sum(-1) * w).sum(-1)  # (*)
    cross = ((ps[..., 0] * qs[..., 1] - ps[..., 1] * qs[..., 0]) * w).sum(-1)  # (*)
    var = (ps.square().sum(-1) * w).sum(-1)  # (*)
    with torch.no_grad():
        bound = (point_norm(ps[..., 0], ps[..., 1]) * point_norm(qs[..., 0], qs[..., 1])
                 * w).sum(-1)
    return cs, cd, dot, cross, var, bound


def _from_cos_sin(cos, sin, cs, cd):
    lin = torch.stack([cos, -sin, sin, cos], dim=-1).unflatten(-1, (2, 2))
    return _affine_from(lin, cd - (lin @ cs[..., None]).squeeze(-1))


def _angle_condition(length, bound):
    """``Σ w |p̃||q̃| / |(dot, cross)|`` >= 1 where the angle is defined, else the largest."""
    ok = length > 0
    return ok, torch.where(ok, bound / torch.where(ok, length, torch.ones_like(length)).detach(),
                           _big(length))


def find_similarity(
    src: torch.Tensor,
    dst: torch.Tensor,
    weights: torch.Tensor | None = None,
    *,
    allow_reflection: bool = False,
) -> TransformFit:
    """Least-squares similarity ``dst_from_src`` (Umeyama 1991), batched, 2D or 3D.

    Minimizes ``Σ w ‖s R p + t - q‖²`` over rotations ``R`` (det +1 unless
    ``allow_reflection``), scales ``s >= 0`` and ``t``. In 2D Umeyama's SVD
    reduces to ``s cos θ = Σ w p̃·q̃ / Σ w ‖p̃‖²`` and
    ``s sin θ = Σ w p̃×q̃ / Σ w ‖p̃‖²``; in 3D ``R`` is Horn's quaternion
    solution and ``s = max tr(R S) / Σ w ‖p̃‖²``.

    Convention:
        Column vectors; 2D ``[[s cos θ, -s sin θ, tx], [s sin θ, s cos θ, ty],
        [0, 0, 1]]`` with θ counter-clockwise, 3D ``[[s R, t], [0, 1]]``.
        ``allow_reflection`` (3D only) lets ``R`` be any orthogonal matrix.
        Coincident ``src`` give ``s = 0``; collinear 3D points (and coplanar
        ones with ``allow_reflection``) leave ``R`` undetermined: ``rank_ok``
        False. Always finite; differentiable, also when singular values repeat.

    Args:
        src: ``(*, N, 2)`` or ``(*, N, 3)`` source points.
        dst: ``(*, N, D)`` destination points.
        weights: optional ``(*, N)`` non-negative weights (0 ignores a point).
        allow_reflection: allow ``det R = -1`` (3D; ignored in 2D).

    Returns:
        :class:`TransformFit` ``(matrix (*, D + 1, D + 1), rank_ok (*), condition (*))``.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        >>> dst = torch.tensor([[1.0, 1.0], [1.0, 3.0], [-1.0, 1.0]])  # R(90°)·S(2) then T(1, 1)
        >>> find_similarity(src, dst).matrix.round(decimals=6) + 0.0
        tensor([[ 0., -2.,  1.],
                [ 2.,  0.,  1.],
                [ 0.,  0.,  1.]])
    """
    weights = check_pair(src, dst, weights, dims=(2, 3))
    low = src.dtype
    if src.shape[-1] == 3:
        uniform = weights is None
        src, dst, weights = to_working(src, dst, weights)
        moments = rigid_moments(src, dst, effective_weights(src, weights), uniform)
        return _fit(*rigid_3d(*moments, True, allow_reflection, low), low)
    cs, cd, dot, cross, var, bound = _rotation_scale(*to_working(src, dst, weights))
    ok = var != 0  # NaN passes through
    var_safe = torch.where(ok, var, torch.ones_like(var))
    zero = torch.zeros_like(var)
    matrix = _from_cos_sin(torch.where(ok, dot / var_safe, zero),
                           torch.where(ok, cross / var_safe, zero), cs, cd)
    rank_ok, condition = _angle_condition(point_norm(dot, cross), bound)
    return _fit(matrix, rank_ok & ok, condition, low)


def find_euclidean(
    src: torch.Tensor,
    dst: torch.Tensor,
    weights: torch.Tensor | None = None,
    *,
    allow_reflection: bool = False,
) -> TransformFit:
    """Least-squares rigid motion ``dst_from_src`` (rotation + translation), batched, 2D or 3D.

    Minimizes ``Σ w ‖R p + t - q‖²``. In 2D ``θ = atan2(Σ w p̃×q̃, Σ w p̃·q̃)``;
    in 3D the Kabsch rotation, computed as the top eigenvector of Horn's 4x4
    matrix of ``S = Σ w p̃ q̃ᵀ`` (the same optimum as the SVD).

    Convention:
        Column vectors; 2D θ counter-clockwise; 3D ``[[R, t], [0, 1]]``, ``det R = +1``
        unless ``allow_reflection`` (3D only), which admits ``det R = -1``
        where that fits better. Where the rotation is undefined (coincident
        points; collinear ones in 3D; coplanar ones in 3D with
        ``allow_reflection``) ``rank_ok`` is False and the matrix is finite.
        Differentiable; in 3D the gradient is exact and finite also for
        symmetric sets (repeated singular values of ``S``).

    Args:
        src: ``(*, N, 2)`` or ``(*, N, 3)`` source points.
        dst: ``(*, N, D)`` destination points.
        weights: optional ``(*, N)`` non-negative weights (0 ignores a point).
        allow_reflection: allow ``det R = -1`` (3D; ignored in 2D).

    Returns:
        :class:`TransformFit` ``(matrix (*, D + 1, D + 1), rank_ok (*), condition (*))``.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        >>> fit = find_euclidean(src, src.flip(-1) * torch.tensor([-1.0, 1.0]))
        >>> fit.matrix.round(decimals=6) + 0.0
        tensor([[ 0., -1.,  0.],
                [ 1.,  0.,  0.],
                [ 0.,  0.,  1.]])
        >>> cube = torch.tensor([[x, y, z] for x in (0.0, 1) for y in (0.0, 1) for z in (0.0, 1)])
        >>> find_euclidean(cube, cube + torch.tensor([1.0, 2.0, 3.0])).matrix[:3, 3]
        tensor([1., 2., 3.])
    """
    weights = check_pair(src, dst, weights, dims=(2, 3))
    low = src.dtype
    if src.shape[-1] == 3:
        uniform = weights is None
        src, dst, weights = to_working(src, dst, weights)
        moments = rigid_moments(src, dst, effective_weights(src, weights), uniform)
        return _fit(*rigid_3d(*moments, False, allow_reflection, low), low)
    cs, cd, dot, cross, _, bound = _rotation_scale(*to_working(src, dst, weights))
    length = point_norm(dot, cross)  # scale-free: only exactly (0, 0) is undefined
    ok = length != 0  # NaN passes through
    length_safe = torch.where(ok, length, torch.ones_like(length))
    cos = torch.where(ok, dot / length_safe, torch.ones_like(dot))
    sin = torch.where(ok, cross / length_safe, torch.zeros_like(dot))
    rank_ok, condition = _angle_condition(length, bound)
    return _fit(_from_cos_sin(cos, sin, cs, cd), rank_ok, condition, low)


def find_translation(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> TransformFit:
    """Least-squares translation ``dst_from_src``: ``t = Σ w (q - p) / Σ w``, batched.

    Convention:
        Column vectors; ``[[1, 0, tx], [0, 1, ty], [0, 0, 1]]`` in 2D,
        ``[[I, t], [0, 1]]`` in 3D. Always determined: ``rank_ok`` True,
        ``condition`` 1 (NaN input gives NaN).

    Args:
        src: ``(*, N, 2)`` or ``(*, N, 3)`` source points.
        dst: ``(*, N, D)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        :class:`TransformFit` ``(matrix (*, D + 1, D + 1), rank_ok (*), condition (*))``.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
        >>> find_translation(src, src + torch.tensor([5.0, 1.0])).matrix
        tensor([[1., 0., 5.],
                [0., 1., 1.],
                [0., 0., 1.]])
    """
    weights = check_pair(src, dst, weights, dims=(2, 3))
    low = src.dtype
    src, dst, weights = to_working(src, dst, weights)
    w = effective_weights(src, weights)
    t = weighted_mean(dst - src, w)
    size = src.shape[-1]
    eye = torch.eye(size, dtype=src.dtype, device=src.device).expand(*t.shape[:-1], size, size)
    return _fit(*translation_fit(_affine_from(eye, t), t), low)
