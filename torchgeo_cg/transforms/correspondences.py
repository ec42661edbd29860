"""Hartley normalization of a point set and the transfer error of a transform on correspondences.

Convention:
    Column vectors, ``p' = M @ [x, y, 1]^T`` with the perspective divide. ``weights``
    (optional, ``(*, N)``, non-negative) are relative: a zero weight removes a point, an
    all-zero set counts every point.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.check import check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import check_same_dtype
from torchgeo_cg.core.numerics import cast_back
from torchgeo_cg.transforms._correspondences import (
    HartleyNormalization,
    check_pair,
    check_points_nonempty,
    effective_weights,
    hartley_weighted,
    to_working,
)
from torchgeo_cg.transforms.homogeneous import inverse, transform_points

__all__ = [
    "HartleyNormalization",
    "hartley_normalize",
    "reprojection_error",
]


def hartley_normalize(points: torch.Tensor, weights: torch.Tensor | None = None):
    """Hartley's isotropic normalization: centroid to 0, mean distance to ``sqrt(2)``.

    Convention:
        ``transform`` maps input points to normalized ones, ``p_n = T @ p``
        (column vectors), ``T = S(s) @ T(-c)``. Zero-weight points do not count;
        an all-zero weight set counts every point. Coincident points (mean
        distance 0) get ``s = 1``: no NaN, forward or backward. ``weights``
        follow the dtype of ``points`` (as in the ``find_*`` functions).

    Args:
        points: ``(*, N, 2)`` float points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        :class:`HartleyNormalization` ``(points (*, N, 2), transform (*, 3, 3),
        centroid (*, 2), scale (*))``.

    Example:
        >>> pts = torch.tensor([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
        >>> out = hartley_normalize(pts)
        >>> out.points
        tensor([[-1., -1.],
                [ 1., -1.],
                [ 1.,  1.],
                [-1.,  1.]])
        >>> out.transform
        tensor([[ 1.,  0., -1.],
                [ 0.,  1., -1.],
                [ 0.,  0.,  1.]])
    """
    check_shape(points, ["*", "N", "2"], "points")
    check_float(points, "points")
    check_points_nonempty(points, "points")
    if weights is not None:
        check_shape(weights, ["*", "N"], "weights", sizes={"N": points.shape[-2]})
        check_float(weights, "weights")
        check_broadcastable({"points": points.shape[:-2], "weights": weights.shape[:-1]})
        weights = weights.to(points.dtype)  # weights follow the points, as in check_pair
    low = points.dtype
    points, weights = to_working(points, weights)
    out = hartley_weighted(points, effective_weights(points, weights))
    return HartleyNormalization(*(cast_back(t, low) for t in out))


def reprojection_error(
    matrix: torch.Tensor,
    src: torch.Tensor,
    dst: torch.Tensor,
    weights: torch.Tensor | None = None,
    symmetric: bool = False,
) -> torch.Tensor:
    """Weighted mean squared transfer error ``Σ w ‖π(M p) - q‖² / Σ w``, batched.

    With ``symmetric=True`` the backward transfer ``Σ w ‖π(M⁻¹ q) - p‖² / Σ w``
    is added (symmetric transfer error).

    Convention:
        Column vectors with the perspective divide of :func:`transform_points`;
        units are the input units squared (pixels²).

    Args:
        matrix: ``(*, 3, 3)`` ``dst_from_src``.
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.
        symmetric: add the backward transfer error.

    Returns:
        ``(*)`` errors.

    Example:
        >>> from torchgeo_cg.transforms import translation
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
        >>> reprojection_error(translation(torch.tensor([1.0, 0.0])), src, src)
        tensor(1.)
    """
    weights = check_pair(src, dst, weights)
    check_shape(matrix, ["*", "3", "3"], "matrix")
    check_same_dtype({"src": src, "matrix": check_float(matrix, "matrix")})
    low = src.dtype
    matrix, src, dst, weights = to_working(matrix, src, dst, weights)
    w = effective_weights(src, weights)
    fwd = (transform_points(matrix, src) - dst).square().sum(-1)
    err = (fwd * w).sum(-1) / w.sum(-1)
    if symmetric:
        bwd = (transform_points(inverse(matrix), dst) - src).square().sum(-1)
        err = err + (bwd * w).sum(-1) / w.sum(-1)
    return cast_back(err, low)
