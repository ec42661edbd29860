"""Knot operations on B-splines: knot insertion, Bezier segments and back.

Convention:
    - As :func:`~torchgeo_cg.curves.bspline`: control points ``(*, n + 1, D)``, full
      knots ``(n + p + 2,)`` or ``(*, n + p + 2)``, ``None`` for clamped uniform knots
      on ``[0, 1]``.
    - Knot insertion is Boehm's algorithm (Piegl & Tiller eq. 5.15), written without a
      span search: ``Q_i = a_i P_i + (1 - a_i) P_{i-1}`` with
      ``a_i = clamp((u - u_i) / (u_{i+p} - u_i), 0, 1)`` (``a_i = 1`` where the
      interval is empty and ends at or before ``u``). The curve is unchanged.
    - Bezier segments are the polynomial pieces on the knot spans ``[u_s, u_{s+1}]``,
      ``s = p..n``, found by blossoming (Ramshaw): Bezier point ``m`` of a span
      ``[a, b]`` is the blossom ``f(a^(p-m), b^m)``, evaluated by de Boor's recurrence
      with one argument per level. Every span gives one segment, so the count
      ``n - p + 1`` is fixed; an empty span (a repeated knot) gives a segment whose
      points all equal the curve's point there.
    - Everything is differentiable with respect to the control points and knots.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.check import ShapeError, check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import as_tensor_like
from torchgeo_cg.curves._bspline_core import prepare_bspline
from torchgeo_cg.curves.bernstein import check_degree
from torchgeo_cg.curves.bspline import BSplineControls, bspline

__all__ = ["BezierSegments", "insert_knot", "bspline_to_bezier", "bezier_to_bspline"]


class BezierSegments(NamedTuple):
    """The Bezier pieces of a B-spline (:func:`bspline_to_bezier`).

    Attributes:
        control_points: ``(*, S, p + 1, D)``; segment ``s`` at ``tau`` in ``[0, 1]``
            is the curve at ``start + tau (end - start)``.
        start: ``(*, S)`` knot where each segment starts.
        end: ``(*, S)`` knot where it ends.

    Example:
        >>> seg = bspline_to_bezier(torch.tensor([[0.0], [1.0], [2.0]]), 1)
        >>> seg.control_points[..., 0], seg.start, seg.end
        (tensor([[0., 1.],
                [1., 2.]]), tensor([0.0000, 0.5000]), tensor([0.5000, 1.0000]))
    """

    control_points: torch.Tensor
    start: torch.Tensor
    end: torch.Tensor


def _one_insertion(cp, knots, value, degree: int):
    """Insert ``value (*, 1)`` once: ``(*, n + 2, D)`` points, ``(*, K + 1)`` knots."""
    count = cp.shape[-2]
    i = torch.arange(count + 1, device=cp.device)
    lo, hi = knots[..., i], knots[..., i + degree]  # u_i, u_{i+p}: (*, n + 2)
    gap = hi - lo
    ratio = (value - lo) / torch.where(gap > 0, gap, 1.0)
    a = torch.where(gap > 0, ratio.clamp(0, 1), (hi <= value).to(cp.dtype))[..., None]
    batch = torch.broadcast_shapes(cp.shape[:-2], a.shape[:-2])
    cp = cp.expand(*batch, *cp.shape[-2:])
    previous = torch.cat([cp[..., :1, :], cp], -2)  # P_{i-1}
    current = torch.cat([cp, cp[..., -1:, :]], -2)  # P_i
    points = a * current + (1 - a) * previous
    knots = knots.expand(*torch.broadcast_shapes(knots.shape[:-1], value.shape[:-1]),
                         knots.shape[-1])
    value = value.expand(*knots.shape[:-1], 1)
    new = torch.cat([knots, value], -1)
    order = torch.sort(new.detach(), dim=-1, stable=True).indices
    return points, new.gather(-1, order)


def insert_knot(control_points: torch.Tensor, value, degree: int,
                knots: torch.Tensor | None = None, *, times: int = 1) -> BSplineControls:
    """Insert the knot ``value`` ``times`` times (Boehm); the curve is unchanged.

    Convention:
        See the module docstring. ``value`` must lie strictly inside the domain
        ``(u_p, u_{n+1})``; it may be an existing knot (its multiplicity grows).

    Args:
        control_points: ``(*, n + 1, D)``.
        value: a number (it takes the knots' dtype, so ``0.37`` is inserted exactly as
            ``knots.new_tensor(0.37)``) or a ``(*,)`` float tensor (one knot per curve,
            promoted with the control points and knots as ``t`` is in
            :func:`~torchgeo_cg.curves.bspline`).
        degree: ``p >= 0``.
        knots: ``(n + p + 2,)`` or ``(*, n + p + 2)``, or ``None``.
        times: how many insertions (``>= 0``).

    Returns:
        :class:`BSplineControls` ``(control_points (*, n + 1 + times, D), knots (*, n + p
        + 2 + times))``.

    Raises:
        ValueError: ``value`` outside the open domain.

    Example:
        >>> P = torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]])
        >>> new = insert_knot(P, 0.5, 3)
        >>> new.knots
        tensor([0.0000, 0.0000, 0.0000, 0.0000, 0.5000, 1.0000, 1.0000, 1.0000, 1.0000])
        >>> new.control_points
        tensor([[0.0000, 0.0000],
                [0.5000, 1.0000],
                [2.0000, 2.0000],
                [3.5000, 1.0000],
                [4.0000, 0.0000]])
    """
    times = check_degree(times, "times")
    check_float(control_points, "control_points", low_precision=False)
    if isinstance(value, torch.Tensor):  # a tensor joins the dtype promotion, as t does
        check_float(value, "value", low_precision=False)
        probe = value.new_zeros(1, device=control_points.device)
    else:  # numbers take the knots' dtype
        probe = control_points.new_zeros(1)
    cp, _, knots = prepare_bspline(control_points, probe, degree, knots)
    value = as_tensor_like(value, knots, "value", like_name="knots", cast=True)
    if value.dim() > 0:
        check_shape(value, [*cp.shape[:-2]], "value")
    value = value[..., None]  # (*, 1)
    count = cp.shape[-2]
    inside = (value > knots[..., degree:degree + 1]) & (value < knots[..., count:count + 1])
    if not bool(inside.all()):
        raise ValueError(f"value: expected a knot strictly inside the domain (u_p, u_{{n+1}}), "
                         f"got {value.flatten().tolist()}")
    for _ in range(times):  # loop over insertions
        cp, knots = _one_insertion(cp, knots, value, degree)
    return BSplineControls(cp, knots)


def _blossom(local, knots, spans, args, degree: int) -> torch.Tensor:
    """de Boor with one argument per level: ``(*, S, M, p + 1, D)`` -> ``(*, S, M, D)``."""
    j = torch.arange(degree + 1, device=spans.device)
    d = local
    for r in range(1, degree + 1):  # loop over levels
        lo = knots[..., (spans[..., None] - degree + j)]  # u_{s-p+j}: (*, S, p + 1)
        hi = knots[..., (spans[..., None] + 1 + j - r).clamp(max=knots.shape[-1] - 1)]
        gap = (hi - lo)[..., None, :]  # (*, S, 1, p + 1)
        alpha = (args[..., r - 1:r] - lo[..., None, :]) / torch.where(gap > 0, gap, 1.0)
        alpha = torch.where(gap > 0, alpha, 0.0)[..., None]  # (*, S, M, p + 1, 1)
        shifted = torch.cat([d[..., :1, :], d[..., :-1, :]], -2)  # d_{j-1}
        d = (1 - alpha) * shifted + alpha * d
    return d[..., -1, :]


def bspline_to_bezier(control_points: torch.Tensor, degree: int,
                      knots: torch.Tensor | None = None) -> BezierSegments:
    """Split B-splines into their ``n - p + 1`` Bezier segments, one per knot span.

    Convention:
        See the module docstring; each segment evaluated by
        :func:`~torchgeo_cg.curves.bezier` at ``tau`` equals the curve at
        ``start + tau (end - start)``.

    Args:
        control_points: ``(*, n + 1, D)``.
        degree: ``p >= 0``.
        knots: ``(n + p + 2,)``, ``(*, n + p + 2)`` or ``None``.

    Returns:
        :class:`BezierSegments` ``(control_points (*, n - p + 1, p + 1, D), start (*, S),
        end (*, S))``.

    Example:
        >>> P = torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]])
        >>> bspline_to_bezier(P, 2).control_points
        tensor([[[0.0000, 0.0000],
                 [1.0000, 2.0000],
                 [2.0000, 2.0000]],
        <BLANKLINE>
                [[2.0000, 2.0000],
                 [3.0000, 2.0000],
                 [4.0000, 0.0000]]])
    """
    cp, _, knots = prepare_bspline(control_points, control_points.new_zeros(1), degree, knots)
    count, d = cp.shape[-2:]
    spans = torch.arange(degree, count, device=cp.device)  # (S,)
    start, end = knots[..., degree:count], knots[..., degree + 1:count + 1]  # (*, S)
    m = torch.arange(degree + 1, device=cp.device)
    levels = torch.arange(1, degree + 1, device=cp.device)
    use_end = levels[None, :] <= m[:, None]  # (M, p): argument r of point m is b if r <= m
    args = torch.where(use_end, end[..., None, None], start[..., None, None])  # (*, S, M, p)
    index = spans[:, None] - degree + m  # (S, p + 1)
    local = cp[..., index, :]  # (*, S, p + 1, D)
    batch = torch.broadcast_shapes(local.shape[:-3], args.shape[:-3])
    local = local.expand(*batch, *local.shape[-3:])[..., None, :, :]
    local = local.expand(*batch, spans.shape[0], degree + 1, degree + 1, d)
    knots_b = knots.expand(*batch, knots.shape[-1]) if knots.dim() > 1 else knots
    spans_b = spans.expand(*batch, spans.shape[0])
    if knots.dim() > 1:
        points = _blossom_batched(local, knots_b, spans_b, args, degree)
    else:
        points = _blossom(local, knots, spans, args, degree)
    empty = (end == start)
    if bool(empty.any()):
        at = bspline(cp, start, degree, knots)  # (*, S, D): the curve's point there
        points = torch.where(empty[..., None, None], at[..., None, :], points)
    return BezierSegments(points, start.expand(*batch, start.shape[-1]),
                          end.expand(*batch, end.shape[-1]))


def _blossom_batched(local, knots, spans, args, degree: int) -> torch.Tensor:
    """:func:`_blossom` with per-curve knots ``(*, K)``."""
    j = torch.arange(degree + 1, device=spans.device)
    last = knots.shape[-1] - 1
    d = local
    flat = knots.reshape(-1, knots.shape[-1])
    rows = torch.arange(flat.shape[0], device=spans.device)[:, None, None]
    shape = (*knots.shape[:-1], spans.shape[-1], degree + 1)
    for r in range(1, degree + 1):  # loop over levels
        lo_i = (spans[..., None] - degree + j).reshape(flat.shape[0], -1, degree + 1)
        hi_i = (spans[..., None] + 1 + j - r).clamp(max=last).reshape(flat.shape[0], -1,
                                                                      degree + 1)
        lo, hi = flat[rows, lo_i].reshape(shape), flat[rows, hi_i].reshape(shape)
        gap = (hi - lo)[..., None, :]
        alpha = (args[..., r - 1:r] - lo[..., None, :]) / torch.where(gap > 0, gap, 1.0)
        alpha = torch.where(gap > 0, alpha, 0.0)[..., None]
        shifted = torch.cat([d[..., :1, :], d[..., :-1, :]], -2)
        d = (1 - alpha) * shifted + alpha * d
    return d[..., -1, :]


def bezier_to_bspline(control_points: torch.Tensor,
                      breaks: torch.Tensor | None = None) -> BSplineControls:
    """Join Bezier segments of one degree into a clamped B-spline (interior knots repeated p times).

    Convention:
        Segment ``s`` spans ``[breaks_s, breaks_{s+1}]``. Consecutive segments are
        joined at their shared end point: the B-spline takes the last point of segment
        ``s`` and drops the first of segment ``s + 1`` (equal for a continuous curve).

    Args:
        control_points: ``(*, S, p + 1, D)`` segments, ``p >= 1``.
        breaks: ``(S + 1,)`` or ``(*, S + 1)`` increasing; ``None``: uniform on ``[0, 1]``.

    Returns:
        :class:`BSplineControls` ``(control_points (*, S p + 1, D), knots (*, S p + p + 2))``.

    Example:
        >>> segments = torch.tensor([[[0.0], [1.0], [2.0]], [[2.0], [3.0], [5.0]]])
        >>> spline = bezier_to_bspline(segments)
        >>> spline.control_points[..., 0]
        tensor([0., 1., 2., 3., 5.])
        >>> spline.knots.tolist()
        [0.0, 0.0, 0.0, 0.5, 0.5, 1.0, 1.0, 1.0]
    """
    check_float(control_points, "control_points", low_precision=False)
    sizes = check_shape(control_points, ["*", "S", "K", "D"], "control_points")
    s, k = sizes["S"], sizes["K"]
    if s < 1 or k < 2:
        raise ShapeError(f"control_points: expected at least one segment of degree >= 1, got "
                         f"shape {tuple(control_points.shape)}")
    degree = k - 1
    if breaks is None:
        breaks = torch.linspace(0, 1, s + 1, dtype=control_points.dtype,
                                device=control_points.device)
    check_float(breaks, "breaks", low_precision=False)
    check_shape(breaks, ["*", s + 1], "breaks")
    check_broadcastable({"control_points": control_points.shape[:-3],
                         "breaks": breaks.shape[:-1]})
    bad = ~(breaks[..., 1:] > breaks[..., :-1])
    if bool(bad.any()):
        raise ValueError(f"breaks: must be strictly increasing, got {breaks.tolist()}")
    dtype = torch.promote_types(control_points.dtype, breaks.dtype)
    control_points, breaks = control_points.to(dtype), breaks.to(dtype)
    first = control_points[..., :1, 0, :]  # (*, 1, D)
    rest = control_points[..., 1:, :].flatten(-3, -2)  # (*, S p, D)
    points = torch.cat([first, rest], -2)
    repeat = torch.full((s + 1,), degree, device=breaks.device)
    repeat[0] = repeat[-1] = degree + 1
    knots = breaks.repeat_interleave(repeat, dim=-1)
    return BSplineControls(points, knots)
