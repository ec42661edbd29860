"""B-spline interpolation and least-squares fitting.

Convention:
    - :func:`interpolate_bspline` is scipy's ``make_interp_spline(x, y, k)`` with its
      default knots: ``k = 0``: ``[x, x_last]``; odd ``k``: not-a-knot (de Boor
      XIII(12)), ``k + 1`` end knots and the sites ``x[(k+1)/2 : -(k+1)/2]``; even ``k``:
      the midpoints of the sites, trimmed the same way. The collocation system
      ``A c = y`` is solved in float64 (upcast, then cast back).
    - :func:`fit_bspline` minimises ``sum_k w_k |C(t_k) - x_k|^2`` over the control
      points, with parameters ``t_k`` from the points (uniform, chord or centripetal,
      see :func:`~torchgeo_cg.curves.fit_parameters`, computed without gradients) and
      either given knots or, for ``num_control_points``, the averaged knots of Piegl &
      Tiller eq. 9.69 (each span holds parameters, so the system is regular). Ragged
      batches as :func:`~torchgeo_cg.curves.fit_bezier` (list, nested or padded with
      ``lengths``). ``periodic=True`` fits a closed curve: the parameters run over the
      closed polygon (the last point joins the first), ``t`` in ``[0, 1)``, uniform
      periodic knots by default.
    - Both are differentiable with respect to the points (and weights).
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.check import (
    ShapeError,
    check_broadcastable,
    check_choice,
    check_float,
    check_shape,
)
from torchgeo_cg.core.numerics import safe_norm, safe_sqrt
from torchgeo_cg.curves._basis import find_spans, local_basis
from torchgeo_cg.curves._bspline_core import prepare_bspline
from torchgeo_cg.curves._knot_checks import check_knots
from torchgeo_cg.curves._strokes import as_padded_strokes, stroke_parameters
from torchgeo_cg.curves.bernstein import check_degree
from torchgeo_cg.curves.bspline import BSplineControls
from torchgeo_cg.curves.knots import check_bspline_knots

__all__ = ["BSplineFit", "interpolate_bspline", "fit_bspline", "collocation_matrix",
           "averaged_knots"]

_METHODS = ("uniform", "chord", "centripetal")


class BSplineFit(NamedTuple):
    """Result of :func:`fit_bspline`.

    Attributes:
        control_points: ``(*, n + 1, D)``.
        knots: ``(*, n + p + 2)`` (periodic: ``(*, n + 2)`` breakpoints), as
            :func:`~torchgeo_cg.curves.bspline` takes them.
        t: ``(*, M)`` parameters used (padded rows: 0).
        rms: ``(*)`` (weighted) root-mean-square residual.

    Example:
        >>> fit = fit_bspline(torch.tensor([[0.0], [1.0], [2.0]]), 1, 2)
        >>> fit.control_points.flatten(), fit.knots
        (tensor([0., 2.]), tensor([0., 0., 1., 1.]))
    """

    control_points: torch.Tensor
    knots: torch.Tensor
    t: torch.Tensor
    rms: torch.Tensor


def collocation_matrix(t: torch.Tensor, degree: int, knots: torch.Tensor,
                       periodic: bool = False) -> torch.Tensor:
    """The dense basis matrix ``A[..., k, i] = N_i(t_k)`` ``(*, M, n + 1)``.

    Args:
        t: ``(M,)`` or ``(*, M)``.
        degree: ``p``.
        knots: full knots ``(*, n + p + 2)``, or periodic breakpoints ``(*, n + 2)``.
        periodic: wrap the columns of a closed curve (``n + 1`` distinct points).

    Example:
        >>> collocation_matrix(torch.tensor([0.0, 0.5, 1.0]), 1, torch.tensor([0.0, 0.0, 1.0, 1.0]))
        tensor([[1.0000, 0.0000],
                [0.5000, 0.5000],
                [0.0000, 1.0000]])
    """
    count = knots.shape[-1] - (1 if periodic else degree + 1)
    zeros = t.new_zeros(*knots.shape[:-1], count, 1)
    _, t, full = prepare_bspline(zeros, t, degree, knots, periodic)
    return _collocation(t, degree, full, count, periodic)


def _collocation(t, degree: int, full: torch.Tensor, count: int, periodic: bool):
    """:func:`collocation_matrix` on full knots, unvalidated (NaN strokes stay NaN)."""
    if full.dim() > 1 or t.dim() > 1:
        batch = torch.broadcast_shapes(full.shape[:-1], t.shape[:-1])
        full, t = full.expand(*batch, full.shape[-1]), t.expand(*batch, t.shape[-1])
    spans = find_spans(full, t, degree)
    basis = local_basis(full, t, spans, degree, 0)[0]  # (*, M, p + 1)
    columns = spans[..., None] - degree + torch.arange(degree + 1, device=t.device)
    if periodic:
        columns = columns % count
    out = basis.new_zeros(*basis.shape[:-1], count)
    return out.scatter_add(-1, columns, basis)


def _default_interp_knots(x: torch.Tensor, degree: int) -> torch.Tensor:
    if degree == 0:
        return torch.cat([x, x[..., -1:]], -1)
    half = (degree + 1) // 2 if degree % 2 else degree // 2
    sites = x if degree % 2 else 0.5 * (x[..., 1:] + x[..., :-1])
    inner = sites[..., half:sites.shape[-1] - half]
    ends = [x[..., :1]] * (degree + 1), [x[..., -1:]] * (degree + 1)
    return torch.cat([*ends[0], inner, *ends[1]], -1)


def interpolate_bspline(x: torch.Tensor, points: torch.Tensor, degree: int = 3) -> BSplineControls:
    """The B-spline of ``degree`` through ``points`` at sites ``x`` (scipy ``make_interp_spline``).

    Convention:
        See the module docstring (scipy's default knots, no boundary conditions).

    Args:
        x: ``(M,)`` or ``(*, M)`` strictly increasing sites, ``M >= degree + 1``.
        points: ``(*, M, D)`` values.
        degree: ``k >= 0``.

    Returns:
        :class:`~torchgeo_cg.curves.BSplineControls` ``(control_points (*, M, D),
        knots (*, M + k + 1))``: ``bspline(control_points, x, k, knots)`` is ``points``.

    Example:
        >>> x = torch.tensor([0.0, 1.0, 2.0, 3.0], dtype=torch.float64)
        >>> spline = interpolate_bspline(x, (x ** 3)[:, None])
        >>> spline.control_points.flatten()  # a cubic is reproduced exactly
        tensor([ 0.,  0.,  0., 27.], dtype=torch.float64)
    """
    degree = check_degree(degree)
    sizes = check_knots(x, "x")
    check_float(points, "points", low_precision=False)
    check_shape(points, ["*", sizes["K"], "D"], "points")
    check_broadcastable({"x": x.shape[:-1], "points": points.shape[:-2]})
    if sizes["K"] < degree + 1:
        raise ShapeError(f"x: degree {degree} needs at least {degree + 1} sites, got shape "
                         f"{tuple(x.shape)}")
    dtype = torch.promote_types(x.dtype, points.dtype)
    knots = _default_interp_knots(x.to(dtype), degree)
    if degree == 0:  # piecewise constant: c = y (scipy's rule; the last site is a knot)
        return BSplineControls(points.to(dtype), knots)
    a = collocation_matrix(x.to(torch.float64), degree, knots.to(torch.float64))
    control = torch.linalg.solve(a, points.to(torch.float64))
    return BSplineControls(control.to(dtype), knots)


def _design(t, degree: int, knots, count: int, periodic: bool) -> torch.Tensor:
    """The fit's collocation matrix; knots from NaN parameters are not validated."""
    if periodic:
        period = knots[..., -1:] - knots[..., :1]
        g = torch.arange(-degree, count + degree + 1, device=knots.device)
        wraps = torch.div(g, count, rounding_mode="floor")
        knots = knots[..., g - wraps * count] + wraps.to(knots.dtype) * period
    return _collocation(t, degree, knots, count, periodic)


def averaged_knots(t: torch.Tensor, num_control_points: int, degree: int,
                   valid: torch.Tensor | None = None) -> torch.Tensor:
    """Clamped knots on ``[0, 1]`` averaged from parameters (Piegl & Tiller eq. 9.69).

    Every knot span then holds parameters, so a least-squares fit is regular.

    Args:
        t: ``(*, M)`` non-decreasing parameters in ``[0, 1]`` (valid ones first).
        num_control_points: ``n + 1 <= M``.
        degree: ``p``.
        valid: ``(*, M)`` bool, the valid parameters (default: all).

    Returns:
        ``(*, n + p + 2)`` knots.

    Example:
        >>> averaged_knots(torch.tensor([0.0, 0.1, 0.2, 0.9, 1.0]), 4, 2)
        tensor([0.0000, 0.0000, 0.0000, 0.1500, 1.0000, 1.0000, 1.0000])
    """
    check_float(t, "t", low_precision=False)
    check_shape(t, ["*", "M"], "t")
    count = check_degree(num_control_points, "num_control_points")
    degree = check_degree(degree)
    if valid is None:
        valid = torch.ones_like(t, dtype=torch.bool)
    if count < degree + 1 or count > t.shape[-1]:
        raise ShapeError(f"t: {count} control points of degree {degree} need between "
                         f"{degree + 1} and {t.shape[-1]} parameters, got shape {tuple(t.shape)}")
    m = valid.sum(-1, keepdim=True)  # (*, 1) valid points
    j = torch.arange(1, count - degree, device=t.device, dtype=t.dtype)  # interior knots
    d = m.to(t.dtype) / (count - degree)
    jd = j * d
    i = jd.floor().long().clamp(1, t.shape[-1] - 1)
    alpha = jd - i.to(t.dtype)
    inner = (1 - alpha) * t.gather(-1, i - 1) + alpha * t.gather(-1, i)
    inner = inner + 0 * torch.where(valid, t, 0.0).sum(-1, keepdim=True)  # NaN in, NaN out
    return torch.cat([t.new_zeros(*inner.shape[:-1], degree + 1), inner,
                      t.new_ones(*inner.shape[:-1], degree + 1)], -1)


def _closed_parameters(points, valid, parametrization: str) -> torch.Tensor:
    """Parameters in ``[0, 1)`` around the closed polygon of each stroke."""
    with torch.no_grad():
        lengths = valid.sum(-1)
        last = (lengths - 1).clamp_min(0)[..., None, None].expand(*points.shape[:-2], 1,
                                                                   points.shape[-1])
        closing = points.gather(-2, last) - points[..., :1, :]  # (*, 1, D)
        step = safe_norm(torch.cat([points[..., 1:, :] - points[..., :-1, :], closing], -2), -1)
        step = torch.where(torch.cat([valid[..., 1:], valid[..., :1]], -1), step, 0.0)
        if parametrization == "uniform":
            step = torch.where(step.isnan(), step, 1.0) * torch.cat([valid[..., 1:],
                                                                      valid[..., :1]], -1)
        elif parametrization == "centripetal":
            step = step.sqrt()
        cumulative = torch.cat([torch.zeros_like(step[..., :1]), step[..., :-1].cumsum(-1)], -1)
        total = step.sum(-1, keepdim=True)
        flat = total == 0
        uniform = torch.arange(points.shape[-2], device=points.device).to(points.dtype)
        uniform = uniform / lengths[..., None].clamp_min(1)
        t = torch.where(flat, uniform, cumulative / torch.where(flat, 1.0, total))
        return torch.where(valid, t, 0.0)


def _least_squares(a, points, w):
    """Weighted normal equations in float64, pseudo-inverse where singular."""
    a, points, w = a.double(), points.double(), w.double()
    weighted = a * w[..., None]  # (*, M, K)
    gram = weighted.transpose(-1, -2) @ a
    rhs = weighted.transpose(-1, -2) @ points
    # a stroke with a NaN point, weight or parameter: solve the identity, then give NaN
    bad = ~(torch.isfinite(gram).all(-1).all(-1) & torch.isfinite(rhs).all(-1).all(-1))
    eye = torch.eye(gram.shape[-1], dtype=gram.dtype, device=gram.device)
    gram = torch.where(bad[..., None, None], eye, gram)
    rhs = torch.where(bad[..., None, None], 0.0, rhs)
    a = torch.where(bad[..., None, None], 0.0, a)
    solution, info = torch.linalg.solve_ex(gram, rhs)
    singular = (info != 0) | ~torch.isfinite(solution).all(-1).all(-1)
    if bool(singular.any()):
        root = w[singular].sqrt()[..., None]
        fallback = torch.linalg.pinv(a[singular] * root) @ (points[singular] * root)
        solution = solution.index_put((singular,), fallback)
    return torch.where(bad[..., None, None], torch.nan, solution)


def fit_bspline(points, degree: int, num_control_points: int | None = None,
                knots: torch.Tensor | None = None, parametrization: str = "chord",
                weights=None, periodic: bool = False, lengths=None) -> BSplineFit:
    """Fit one B-spline of ``degree`` to each ordered point set by least squares.

    Convention:
        See the module docstring. Give ``num_control_points`` (``n + 1``) or ``knots``
        (full ``(n + p + 2,)`` or ``(*, n + p + 2)`` on ``[0, 1]``; periodic: ``n + 2``
        breakpoints). Each stroke needs ``n + 1`` valid points or more.

    Args:
        points: ``(*, M, D)``, a list of ``(M_i, D)`` tensors, or a nested tensor.
        degree: ``p >= 0``.
        num_control_points: ``n + 1``.
        knots: the knots instead of ``num_control_points``.
        parametrization: ``"uniform"``, ``"chord"`` or ``"centripetal"``.
        weights: ``(*, M)`` non-negative sample weights.
        periodic: fit a closed curve.
        lengths: ``(*,)`` valid rows of a padded ``points`` tensor.

    Returns:
        :class:`BSplineFit` ``(control_points (*, n + 1, D), knots, t (*, M), rms (*))``.

    Example:
        >>> s = torch.linspace(0, 1, 50, dtype=torch.float64)
        >>> wave = torch.stack([s, torch.sin(6 * s)], -1)
        >>> fit = fit_bspline(wave, 3, 10, parametrization="uniform")
        >>> fit.control_points.shape, bool(fit.rms < 1e-3)
        (torch.Size([10, 2]), True)
    """
    degree = check_degree(degree)
    check_choice(parametrization, _METHODS, "parametrization")
    if (num_control_points is None) == (knots is None):
        raise ValueError("num_control_points, knots: give exactly one of the two")
    points, valid, weights = as_padded_strokes(points, lengths, weights)
    check_float(points, "points", low_precision=False)
    if knots is not None:
        count = knots.shape[-1] - (1 if periodic else degree + 1)
    else:
        count = check_degree(num_control_points, "num_control_points")
    least = int(valid.sum(-1).min()) if valid.numel() else count
    if count < (1 if periodic else degree + 1) or least < count:
        raise ShapeError(f"points: {count} control points of degree {degree} need at least "
                         f"{count} points, got {least} (shape {tuple(points.shape)})")
    if points.shape[:-2].numel() == 0:  # an empty batch
        k = knots if knots is not None else points.new_zeros(
            *points.shape[:-2], count + (1 if periodic else degree + 1))
        return BSplineFit(points.new_zeros(*points.shape[:-2], count, points.shape[-1]),
                          k.expand(*points.shape[:-2], k.shape[-1]), points[..., 0],
                          points.new_zeros(points.shape[:-2]))
    points = torch.where(valid[..., None], points, 0.0)
    if periodic:
        t = _closed_parameters(points, valid, parametrization)
    else:
        t = stroke_parameters(points, valid, parametrization)
    if knots is None:
        if periodic:
            knots = torch.linspace(0, 1, count + 1, dtype=points.dtype, device=points.device)
        else:
            knots = averaged_knots(t, count, degree, valid)
    elif not periodic:
        check_bspline_knots(knots, count, degree)
    knots = knots.to(points.dtype)
    w = valid.to(points.dtype) if weights is None else torch.where(valid, weights, 0.0)
    a = _design(t, degree, knots, count, periodic)
    a = torch.where(valid[..., None], a, 0.0)
    control = _least_squares(a, points, w).to(points.dtype)
    residual = ((a.to(points.dtype) @ control - points) ** 2).sum(-1)
    total = w.sum(-1)
    rms = safe_sqrt((w * residual).sum(-1) / torch.where(total > 0, total, 1.0), eps=0.0)
    return BSplineFit(control, knots, t, rms)
