"""Shared internals of transform estimation: argument checks, weights, Hartley normalization.

Every estimator (closed forms, DLT, RANSAC, iterative fitting) validates a correspondence set
with :func:`check_pair`, prepares its weights with :func:`effective_weights` and normalizes
with :func:`hartley_weighted`; the result types they share live here too.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape
from torchgeo_cg.core.numerics import power_of_two_scale, working_dtype


class HartleyNormalization(NamedTuple):
    """Result of :func:`hartley_normalize`.

    Attributes:
        points: ``(*, N, 2)`` normalized points, ``T @ p``.
        transform: ``(*, 3, 3)`` the similarity ``T`` (``normalized_from_input``).
        centroid: ``(*, 2)`` the (weighted) centroid removed.
        scale: ``(*)`` the isotropic scale applied after centering.
    """

    points: torch.Tensor
    transform: torch.Tensor
    centroid: torch.Tensor
    scale: torch.Tensor


class TransformFit(NamedTuple):
    """Result of the closed-form estimators (:func:`find_homography_dlt`, :func:`find_affine`,
    :func:`find_similarity`, :func:`find_euclidean`, :func:`find_translation`).

    Attributes:
        matrix: ``(*, 3, 3)`` (2D) or ``(*, 4, 4)`` (3D) ``dst_from_src``; a
            homography is scaled so ``matrix[..., 2, 2] = 1`` (or to unit Frobenius
            norm where ``|h33|`` is tiny).
        rank_ok: ``(*)`` bool, False for degenerate problems, where the model is
            not determined by the points (too few points with positive weight,
            collinear or coincident points, coplanar points where the model needs
            more, a singular fit). The matrix is finite there, never NaN.
        condition: ``(*)`` the conditioning of the problem, ``>= 1``, always finite
            (the dtype's largest value stands for an infinite one); large means
            ill-posed. Homography: ``σ_max / σ_8`` of the normalized DLT matrix
            (estimated within a factor 3). Affine: ``λ_max / λ_min`` of the source
            covariance. Euclidean and similarity in 3D: the spread of Horn's
            4x4 matrix over the gap of its chosen eigenvalue; in 2D
            ``Σ w |p̃||q̃| / |Σ w (p̃·q̃, p̃×q̃)|``. Translation: 1.

    Example:
        >>> from torchgeo_cg.transforms import find_euclidean
        >>> src = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0],
        ...                     [0.0, 0.0, 3.0]])
        >>> fit = find_euclidean(src, src + torch.tensor([1.0, 2.0, 3.0]))
        >>> fit.matrix[:3, 3], fit.rank_ok
        (tensor([1.0000, 2.0000, 3.0000]), tensor(True))
        >>> find_euclidean(src[:2], src[:2]).rank_ok  # two points leave a spin free
        tensor(False)
    """

    matrix: torch.Tensor
    rank_ok: torch.Tensor
    condition: torch.Tensor


def check_points_nonempty(points: torch.Tensor, name: str) -> None:
    """ShapeError naming ``name`` when ``points`` (*, N, D) has N = 0 (nothing to fit)."""
    if points.shape[-2] == 0:
        raise ShapeError(
            f"{name}: expected (*, N, {points.shape[-1]}) with N >= 1 (a transform of zero "
            f"points is undefined), got {tuple(points.shape)}"
        )


def check_pair(src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None,
               dims: tuple[int, ...] = (2,)):
    """Validate a correspondence set of dimension in ``dims``; returns ``weights`` cast to
    ``src``'s dtype (or None)."""
    check_shape(src, ["*", "N", "D"], "src")
    if src.shape[-1] not in dims:
        options = " or ".join(f"(*, N, {d})" for d in dims)
        raise ShapeError(f"src: expected shape {options}, got {tuple(src.shape)}")
    sizes = check_shape(src, ["*", "N", str(src.shape[-1])], "src")
    check_float(src, "src")
    check_shape(dst, ["*", "N", str(src.shape[-1])], "dst", sizes={"N": sizes["N"]})
    check_float(dst, "dst")
    if src.shape != dst.shape:
        raise ShapeError(
            f"dst: expected the shape of src {tuple(src.shape)}, got {tuple(dst.shape)}"
        )
    check_points_nonempty(src, "src")
    if src.dtype != dst.dtype or src.device != dst.device:
        raise TypeError(
            f"dst: expected dtype {src.dtype} on {src.device} like src, "
            f"got {dst.dtype} on {dst.device}"
        )
    if weights is not None:
        check_shape(weights, ["*", "N"], "weights", sizes={"N": sizes["N"]})
        check_float(weights, "weights")
        if weights.shape != src.shape[:-1]:
            raise ShapeError(
                f"weights: expected shape {tuple(src.shape[:-1])}, got {tuple(weights.shape)}"
            )
        weights = weights.to(src.dtype)
    return weights


def to_working(*tensors: torch.Tensor | None) -> tuple:
    """The tensors in their working dtype (float16/bfloat16 -> float32); None stays None."""
    return tuple(None if t is None else t.to(working_dtype(t.dtype)) for t in tensors)


def pow2_normalize(w: torch.Tensor, dim: int) -> torch.Tensor:
    """Non-negative weights scaled by a power of two so their largest is in [0.5, 1).

    Weights are relative: the scaling is exact
    (:func:`~torchgeo_cg.core.power_of_two_scale`), so every fit is the same for any
    positive scale of the weights (1e-300 or 1e300 included), with no overflow.
    Negative weights count as 0; NaN stays NaN; an all-zero set is left as it is.
    """
    w = torch.where(w < 0, torch.zeros_like(w), w)  # NaN stays NaN
    if w.shape[dim] == 0:
        return w
    return w / power_of_two_scale(w.detach().amax(dim, keepdim=True))


def effective_weights(points: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    """(*, N) non-negative weights, scaled exactly to a largest in [0.5, 1); an all-zero
    (or absent) set becomes all ones."""
    if weights is None:
        return torch.ones_like(points[..., 0])
    w = pow2_normalize(weights, -1)
    total = w.sum(-1, keepdim=True)
    return torch.where(total == 0, torch.ones_like(w), w)


def weighted_mean(x: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Weighted mean over the N axis: x (*, N, D), w (*, N) with positive sum -> (*, D)."""
    return (x * w[..., None]).sum(-2) / w.sum(-1, keepdim=True)


def similarity_matrix(scale: torch.Tensor, centroid: torch.Tensor) -> torch.Tensor:
    """[[s, 0, -s cx], [0, s, -s cy], [0, 0, 1]] from (*) scale and (*, 2) centroid."""
    one, zero = torch.ones_like(scale), torch.zeros_like(scale)
    rows = [scale, zero, -scale * centroid[..., 0], zero, scale, -scale * centroid[..., 1],
            zero, zero, one]
    return torch.stack(rows, dim=-1).unflatten(-1, (3, 3))


def point_norm(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """``hypot(x, y)`` without overflow or underflow, zero gradient at the origin, NaN kept."""
    nonzero = (x != 0) | (y != 0)
    one = torch.ones_like(x)
    return torch.where(nonzero, torch.hypot(torch.where(nonzero, x, one),
                                            torch.where(nonzero, y, one)), torch.zeros_like(x))


def hartley_weighted(points: torch.Tensor, w: torch.Tensor) -> HartleyNormalization:
    """:func:`hartley_normalize` with prepared weights w (*, N), non-negative, positive sum."""
    centroid = weighted_mean(points, w)  # (*, 2)
    centered = points - centroid[..., None, :]  # (*, N, 2)
    radius = (point_norm(centered[..., 0], centered[..., 1]) * w).sum(-1) / w.sum(-1)  # (*)
    ok = radius > 0  # only coincident points leave the scale undefined
    radius_safe = torch.where(ok, radius, torch.ones_like(radius))
    scale = torch.where(ok, math.sqrt(2.0) / radius_safe, torch.ones_like(radius))
    return HartleyNormalization(
        centered * scale[..., None, None], similarity_matrix(scale, centroid), centroid, scale
    )


def hartley_last(points: torch.Tensor, w: torch.Tensor):
    """Batch-last Hartley normalization: points (2, N, B), w (N, B) -> (points, centroid (2, B),
    scale (B,)), with the same conventions as :func:`_hartley`."""
    w_sum = w.sum(0)  # (B,)
    centroid = (points * w).sum(1) / w_sum  # (2, B)
    centered = points - centroid[:, None]  # (2, N, B)
    radius = (point_norm(centered[0], centered[1]) * w).sum(0) / w_sum  # (B,)
    ok = radius > 0
    radius_safe = torch.where(ok, radius, torch.ones_like(radius))
    scale = torch.where(ok, math.sqrt(2.0) / radius_safe, torch.ones_like(radius))
    return centered * scale, centroid, scale
