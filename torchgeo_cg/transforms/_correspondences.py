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
from torchgeo_cg.core.numerics import working_dtype


def check_choice(value: str, choices, name: str) -> str:
    if value not in choices:
        raise ValueError(f"{name}: expected one of {sorted(choices)}, got {value!r}")
    return value


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


class HomographyFit(NamedTuple):
    """Result of :func:`find_homography_dlt`.

    Attributes:
        matrix: ``(*, 3, 3)`` ``dst_from_src``, scaled so ``matrix[..., 2, 2] = 1``
            (or to unit Frobenius norm where ``|h33|`` is tiny).
        rank_ok: ``(*)`` bool, False for degenerate problems (fewer than 4 points
            with positive weight, collinear/coincident points, or a singular fit).
        condition: ``(*)`` estimated condition of the normalized DLT system
            ``σ_max / σ_8``, the largest singular value of the (trace-normalized)
            DLT matrix over its second smallest; the estimate lies between 1 and 3
            times the true ratio (exact for problems solved by ``eigh`` or SVD).
            Large means ill-posed (the solution is not unique to working
            precision); always finite.
    """

    matrix: torch.Tensor
    rank_ok: torch.Tensor
    condition: torch.Tensor


def check_points_nonempty(points: torch.Tensor, name: str) -> None:
    """ShapeError naming ``name`` when ``points`` (*, N, 2) has N = 0 (nothing to fit)."""
    if points.shape[-2] == 0:
        raise ShapeError(
            f"{name}: expected (*, N, 2) with N >= 1 (a transform of zero points is "
            f"undefined), got {tuple(points.shape)}"
        )


def check_pair(src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None):
    """Validate a correspondence set; returns ``weights`` cast to ``src``'s dtype (or None)."""
    sizes = check_shape(src, ["*", "N", "2"], "src")
    check_float(src, "src")
    check_shape(dst, ["*", "N", "2"], "dst", sizes={"N": sizes["N"]})
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


def effective_weights(points: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    """(*, N) non-negative weights; an all-zero (or absent) set becomes all ones."""
    if weights is None:
        return torch.ones_like(points[..., 0])
    w = torch.where(weights < 0, torch.zeros_like(weights), weights)  # NaN stays NaN
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
