"""Least-squares Bezier fitting (report section 1.2; glyph outlines as in section 1.1).

Convention:
    - Points ``(*, M, D)`` are samples along one curve each, in order.
    - Parameters are assigned before solving: ``"uniform"`` (``k / (M - 1)``),
      ``"chord"`` (cumulative chord length, normalised to ``[0, 1]``) or
      ``"centripetal"`` (cumulative square-root chord length). A curve whose
      points all coincide falls back to uniform parameters.
    - The fit minimises ``sum_k |B(t_k) - x_k|^2`` over the control points; it is a
      batched linear least-squares problem solved in float64 (upcast, then cast
      back) and is differentiable with respect to the points. Chord and
      centripetal parameters are computed without gradients (treated as
      constants), so the gradient is the one at fixed parameters.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape
from torchgeo_cg.core.numerics import safe_norm
from torchgeo_cg.curves.bernstein import _check_degree, bernstein_basis

__all__ = ["BezierFit", "fit_parameters", "fit_bezier"]

_METHODS = ("uniform", "chord", "centripetal")


class BezierFit(NamedTuple):
    """Result of :func:`fit_bezier`.

    Attributes:
        control_points: ``(*, n + 1, D)``.
        t: ``(*, M)`` the parameters used.
        rms: ``(*)`` root-mean-square distance between ``B(t_k)`` and the points.

    Example:
        >>> fit = fit_bezier(torch.tensor([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]), 1)
        >>> fit.control_points.round(decimals=6) + 0.0, fit.t
        (tensor([[0.0000, 0.0000],
                [2.0000, 2.0000]]), tensor([0.0000, 0.5000, 1.0000]))
    """

    control_points: torch.Tensor
    t: torch.Tensor
    rms: torch.Tensor


def fit_parameters(points: torch.Tensor, parametrization: str = "chord") -> torch.Tensor:
    """Parameters in ``[0, 1]`` for ordered samples ``(*, M, D)``.

    Convention:
        See the module docstring; ``t_0 = 0`` and ``t_{M-1} = 1``.

    Args:
        points: ``(*, M, D)``, ``M >= 2``.
        parametrization: ``"uniform"``, ``"chord"`` or ``"centripetal"``.

    Returns:
        ``(*, M)`` non-decreasing parameters (computed without gradients).

    Example:
        >>> fit_parameters(torch.tensor([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]]))
        tensor([0.0000, 0.3333, 1.0000])
    """
    check_float(points, "points")
    sizes = check_shape(points, ["*", "M", "D"], "points")
    if sizes["M"] < 2:
        raise ShapeError(f"points: expected at least 2 points, got shape {tuple(points.shape)}")
    if parametrization not in _METHODS:
        raise ValueError(f"parametrization: expected one of {_METHODS}, got {parametrization!r}")
    m = sizes["M"]
    with torch.no_grad():
        uniform = torch.linspace(0, 1, m, dtype=points.dtype, device=points.device)
        uniform = uniform.expand(*points.shape[:-2], m)
        if parametrization == "uniform":
            return uniform.clone()
        step = safe_norm(points[..., 1:, :] - points[..., :-1, :], dim=-1)  # (*, M - 1)
        if parametrization == "centripetal":
            step = step.sqrt()
        cumulative = torch.cat([torch.zeros_like(step[..., :1]), step.cumsum(-1)], dim=-1)
        total = cumulative[..., -1:]
        ok = total > 0
        t = cumulative / torch.where(ok, total, torch.ones_like(total))
        return torch.where(ok, t, uniform)


def fit_bezier(points: torch.Tensor, degree: int, parametrization: str = "chord") -> BezierFit:
    """Fit one Bezier curve of ``degree`` to each ordered point set by least squares.

    Convention:
        See the module docstring. ``M >= degree + 1`` points are needed for a
        unique solution; fewer raise :class:`ShapeError`.

    Args:
        points: ``(*, M, D)``.
        degree: ``n >= 0``.
        parametrization: ``"uniform"``, ``"chord"`` or ``"centripetal"``.

    Returns:
        :class:`BezierFit` ``(control_points (*, n + 1, D), t (*, M), rms (*))``.

    Example:
        >>> t = torch.linspace(0, 1, 9, dtype=torch.float64)
        >>> parabola = torch.stack([t, t * t], dim=-1)
        >>> fit = fit_bezier(parabola, 2, parametrization="uniform")
        >>> fit.control_points.round(decimals=6) + 0.0
        tensor([[0.0000, 0.0000],
                [0.5000, 0.0000],
                [1.0000, 1.0000]], dtype=torch.float64)
        >>> bool(fit.rms < 1e-12)
        True
    """
    degree = _check_degree(degree)
    t = fit_parameters(points, parametrization)
    m = points.shape[-2]
    if m < degree + 1:
        raise ShapeError(
            f"points: fitting degree {degree} needs at least degree + 1 = {degree + 1} points, "
            f"got {m} (shape {tuple(points.shape)})"
        )
    basis = bernstein_basis(t, degree)  # (*, M, n + 1)
    solution = torch.linalg.lstsq(basis.double(), points.double()).solution  # (*, n + 1, D)
    control_points = solution.to(points.dtype)
    residual = torch.matmul(basis, control_points) - points
    rms = safe_norm(residual.flatten(-2), dim=-1) / m**0.5
    return BezierFit(control_points, t, rms)
