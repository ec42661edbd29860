"""Least-squares B-spline surfaces through a grid of points.

Convention:
    - ``points`` is a grid ``(*, R, S, D)``: row ``r`` runs along ``u``, column ``s``
      along ``v`` (the layout of a control grid).
    - Parameters: ``u_r`` is the mean over the columns of each column's parameters
      (uniform, chord or centripetal, :func:`~torchgeo_cg.curves.fit_parameters`),
      ``v_s`` likewise over the rows (Piegl & Tiller section 9.2.5); computed without
      gradients. Knots: given, or averaged from the parameters (eq. 9.69).
    - The fit minimises ``sum_rs |S(u_r, v_s) - x_rs|^2``. The problem separates:
      ``C = A_u^+ X (A_v^+)^T`` with the collocation matrices ``A_u (R, m + 1)``,
      ``A_v (S, n + 1)`` and their pseudo-inverses (float64, then cast back), so it is
      exact least squares and differentiable with respect to the points.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape
from torchgeo_cg.core.numerics import safe_sqrt
from torchgeo_cg.curves.bspline_fitting import averaged_knots, collocation_matrix
from torchgeo_cg.curves.fitting import fit_parameters
from torchgeo_cg.curves.knots import check_bspline_knots
from torchgeo_cg.surfaces._degree import check_surface_degree

__all__ = ["SurfaceFit", "fit_bspline_surface"]


class SurfaceFit(NamedTuple):
    """Result of :func:`fit_bspline_surface`.

    Attributes:
        control_grid: ``(*, m + 1, n + 1, D)``.
        knots_u: ``(*, m + p + 2)``.
        knots_v: ``(*, n + q + 2)``.
        u: ``(*, R)`` row parameters.
        v: ``(*, S)`` column parameters.
        rms: ``(*)`` root-mean-square residual over the grid.

    Example:
        >>> g = torch.stack(torch.meshgrid(torch.linspace(0, 1, 4), torch.linspace(0, 1, 3),
        ...                                indexing="ij"), -1)
        >>> fit = fit_bspline_surface(g, 1, (2, 2))
        >>> fit.control_grid.shape, float(fit.rms) < 1e-6
        (torch.Size([2, 2, 2]), True)
    """

    control_grid: torch.Tensor
    knots_u: torch.Tensor
    knots_v: torch.Tensor
    u: torch.Tensor
    v: torch.Tensor
    rms: torch.Tensor


def _pair(value, name):
    pair = value if isinstance(value, (tuple, list)) else (value, value)
    if len(pair) != 2 or any(isinstance(x, bool) or not isinstance(x, int) for x in pair):
        raise ValueError(f"{name}: expected an int or a pair of ints, got {value!r}")
    return pair


def _uniform(x: torch.Tensor) -> torch.Tensor:
    return torch.linspace(0, 1, x.shape[-1], dtype=x.dtype, device=x.device).expand_as(x)


def fit_bspline_surface(points: torch.Tensor, degree, num_control_points=None,
                        knots_u: torch.Tensor | None = None, knots_v: torch.Tensor | None = None,
                        parametrization: str = "chord") -> SurfaceFit:
    """Fit a B-spline surface of ``degree`` to a grid of points by least squares.

    Convention:
        See the module docstring. Give ``num_control_points`` (an int or ``(m + 1,
        n + 1)``) or both knot vectors (full, on ``[0, 1]``).

    Args:
        points: ``(*, R, S, D)`` grid, ``R >= m + 1``, ``S >= n + 1``.
        degree: ``p`` or ``(p, q)``.
        num_control_points: ``m + 1`` and ``n + 1``.
        knots_u, knots_v: knots instead of ``num_control_points``.
        parametrization: ``"uniform"``, ``"chord"`` or ``"centripetal"``.

    Returns:
        :class:`SurfaceFit`.

    Example:
        >>> u, v = torch.meshgrid(torch.linspace(0, 1, 6, dtype=torch.float64),
        ...                       torch.linspace(0, 1, 5, dtype=torch.float64), indexing="ij")
        >>> saddle = torch.stack([u, v, u * v], -1)  # bilinear: exact with degree 1
        >>> fit = fit_bspline_surface(saddle, 1, (2, 2), parametrization="uniform")
        >>> fit.control_grid[..., 2].round(decimals=12) + 0.0
        tensor([[0., 0.],
                [0., 1.]], dtype=torch.float64)
    """
    p, q = check_surface_degree(degree)
    check_float(points, "points", low_precision=False)
    sizes = check_shape(points, ["*", "R", "S", "D"], "points")
    if (num_control_points is None) == (knots_u is None or knots_v is None):
        raise ValueError("num_control_points, knots_u, knots_v: give num_control_points or "
                         "both knot vectors")
    if num_control_points is not None:
        rows, cols = _pair(num_control_points, "num_control_points")
    else:
        rows, cols = knots_u.shape[-1] - p - 1, knots_v.shape[-1] - q - 1
    if rows < p + 1 or cols < q + 1 or sizes["R"] < rows or sizes["S"] < cols:
        raise ShapeError(f"points: a ({rows}, {cols}) control grid of degree ({p}, {q}) needs "
                         f"a grid of at least that size, got shape {tuple(points.shape)}")
    u = fit_parameters(points.transpose(-3, -2), parametrization).mean(-2)  # (*, R)
    v = fit_parameters(points, parametrization).mean(-2)  # (*, S)
    if num_control_points is not None:
        knots_u = averaged_knots(u, rows, p)
        knots_v = averaged_knots(v, cols, q)
    else:
        check_bspline_knots(knots_u, rows, p, "knots_u")
        check_bspline_knots(knots_v, cols, q, "knots_v")
    knots_u, knots_v = knots_u.to(points.dtype), knots_v.to(points.dtype)
    # a grid with a NaN point has NaN parameters and knots: solve it on uniform ones
    # (finite system), its NaN points then make its control grid NaN
    bad = ~torch.isfinite(points).flatten(-3).all(-1)[..., None]  # (*, 1)
    u_s, v_s = torch.where(bad, _uniform(u), u), torch.where(bad, _uniform(v), v)
    if num_control_points is not None:
        knots_u = torch.where(bad, averaged_knots(_uniform(u), rows, p), knots_u)
        knots_v = torch.where(bad, averaged_knots(_uniform(v), cols, q), knots_v)
    a_u = collocation_matrix(u_s.double(), p, knots_u.double())  # (*, R, m + 1)
    a_v = collocation_matrix(v_s.double(), q, knots_v.double())  # (*, S, n + 1)
    grid = torch.einsum("...ar,...rsd,...bs->...abd", torch.linalg.pinv(a_u), points.double(),
                        torch.linalg.pinv(a_v))
    fitted = torch.einsum("...ra,...abd,...sb->...rsd", a_u, grid, a_v)
    rms = safe_sqrt((fitted - points.double()).square().sum(-1).mean((-2, -1)), eps=0.0)
    return SurfaceFit(grid.to(points.dtype), knots_u, knots_v, u, v, rms.to(points.dtype))
