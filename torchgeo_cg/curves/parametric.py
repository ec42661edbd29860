"""Parametric and implicit 2D curves: circle, cycloid, figure-eight both ways (report 1.1).

Convention:
    - Points are ``(x, y)`` with y up; angles ``t`` are in radians, measured
      counter-clockwise from +x.
    - Implicit functions are negative inside, zero on the curve, positive
      outside. :func:`implicit_circle` is the report's algebraic form
      ``(x - cx)^2 + (y - cy)^2 - r^2`` (not a distance; its gradient vanishes
      at the centre only).
    - Grids use ``indexing="ij"``: array axis 0 is x, axis 1 is y, so
      ``field[i, j]`` is the value at ``origin + (i, j) * spacing``; this is the
      layout :func:`~torchgeo_cg.curves.marching_squares.marching_squares` reads.
    - Parameters (``center``, ``radius``) may be numbers, numpy values or tensors;
      they follow the dtype and device of ``t`` / ``xy``. float16/bfloat16 are
      rejected with a ``TypeError``.
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.core.check import check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import as_tensor_like
from torchgeo_cg.core.numerics import hypot

__all__ = [
    "circle",
    "implicit_circle",
    "cycloid",
    "figure_eight_implicit",
    "figure_eight_parametric",
    "grid_2d",
]


def _param(value, like: torch.Tensor, name: str) -> torch.Tensor:
    """A number, numpy value or float tensor as a tensor of ``like``'s dtype and device."""
    return as_tensor_like(value, like, name, cast=True)


def _check_t(t: torch.Tensor) -> None:
    check_float(t, "t", low_precision=False)
    check_shape(t, ["*", "T"], "t")


def circle(t: torch.Tensor, center=(0.0, 0.0), radius=1.0) -> torch.Tensor:
    """Points ``center + radius (cos t, sin t)`` of circles.

    Convention:
        Counter-clockwise for increasing ``t`` (radians), starting at
        ``center + (radius, 0)``; any ``t`` is allowed (periodic).

    Args:
        t: ``(T,)`` or ``(*, T)`` angles.
        center: ``(*, 2)`` tensor or a pair of numbers.
        radius: ``(*)`` tensor or a number.

    Returns:
        ``(*, T, 2)``.

    Example:
        >>> t = torch.tensor([0.0, math.pi / 2])
        >>> circle(t, center=(1.0, 0.0), radius=2.0).round(decimals=4)
        tensor([[3., 0.],
                [1., 2.]])
    """
    _check_t(t)
    center = _param(center, t, "center")
    check_shape(center, ["*", "2"], "center")
    radius = _param(radius, t, "radius")
    check_broadcastable({"t": t.shape[:-1], "center": center.shape[:-1], "radius": radius.shape})
    unit = torch.stack([torch.cos(t), torch.sin(t)], dim=-1)  # (*, T, 2)
    return center[..., None, :] + radius[..., None, None] * unit


def implicit_circle(xy: torch.Tensor, center=(0.0, 0.0), radius=1.0) -> torch.Tensor:
    """The report's implicit circle ``(x - cx)^2 + (y - cy)^2 - r^2``.

    Convention:
        Negative inside, zero on the circle, positive outside. ``center`` and
        ``radius`` broadcast against the batch of ``xy``.

    Args:
        xy: ``(*, 2)`` query points.
        center: ``(*, 2)`` tensor or a pair of numbers.
        radius: ``(*)`` tensor or a number.

    Returns:
        ``(*)``.

    Example:
        >>> implicit_circle(torch.tensor([[0.0, 0.0], [3.0, 4.0], [1.0, 0.0]]), radius=5.0)
        tensor([-25.,   0., -24.])
    """
    check_float(xy, "xy", low_precision=False)
    check_shape(xy, ["*", "2"], "xy")
    center = _param(center, xy, "center")
    check_shape(center, ["*", "2"], "center")
    radius = _param(radius, xy, "radius")
    check_broadcastable({"xy": xy.shape[:-1], "center": center.shape[:-1],
                         "radius": radius.shape})
    d = xy - center
    # |d|^2 - r^2 = (|d| - r)(|d| + r): no intermediate overflow (finite wherever the
    # value is) and no cancellation next to the circle; gradient 2 d everywhere.
    length = hypot(d[..., 0], d[..., 1])
    return (length - radius) * (length + radius)


def cycloid(t: torch.Tensor, radius=1.0) -> torch.Tensor:
    """The cycloid ``x = R (t - sin t)``, ``y = R (1 - cos t)``.

    The path of a point on a wheel of radius ``R`` rolling along the x axis;
    one arch per ``2 pi`` (report Figure 2 draws ``t`` in ``[0, 4 pi]``). Cusps
    (zero speed) at ``t = 2 pi k``.

    Convention:
        ``t`` in radians of wheel rotation; the wheel rolls towards +x.

    Args:
        t: ``(T,)`` or ``(*, T)``.
        radius: ``(*)`` tensor or a number.

    Returns:
        ``(*, T, 2)``.

    Example:
        >>> cycloid(torch.tensor([0.0, math.pi]), radius=2.0)
        tensor([[0.0000, 0.0000],
                [6.2832, 4.0000]])
    """
    _check_t(t)
    radius = _param(radius, t, "radius")
    check_broadcastable({"t": t.shape[:-1], "radius": radius.shape})
    radius = radius[..., None]
    return torch.stack([radius * (t - torch.sin(t)), radius * (1 - torch.cos(t))], dim=-1)


def figure_eight_implicit(xy: torch.Tensor, radius=5.0) -> torch.Tensor:
    """The report's implicit figure-eight: the product of two touching circle fields.

    ``f = c_left * c_right`` with ``c_left = implicit_circle(xy, (-r, 0), r)`` and
    ``c_right = implicit_circle(xy, (r, 0), r)``; its zero set is the union of the
    two circles, which touch at the origin.

    Why the crossing goes wrong (the report's "invalid values"): near the origin
    ``c_left = x^2 + 2 r x + y^2`` and ``c_right = x^2 - 2 r x + y^2``, so
    ``f = (x^2 + y^2)^2 - 4 r^2 x^2``. At the origin both factors vanish: ``f`` and
    its gradient ``c_left grad c_right + c_right grad c_left`` are both zero, a
    singular point (a tacnode: both circles have the vertical tangent there). The
    product's sign is ``-`` in the thin cusp regions between the two arcs and
    ``+`` outside, and on a grid those regions are narrower than a cell, so grid
    samples near the origin are products of two tiny numbers and the sign
    pattern is a saddle: contouring cannot tell "two circles touching" from
    "one curve crossing itself", and anything that divides by ``|grad f|`` (a
    normal, a Newton projection, a distance estimate ``f / |grad f|``) divides
    ``0 / 0`` there; that is where numpy produced invalid values.
    :func:`figure_eight_parametric` has none of these problems. Our marching
    squares stays finite (its interpolation never divides by zero), but its
    polylines at the crossing are one valid resolution of an ambiguous saddle.

    Convention:
        Negative inside exactly one circle, positive outside both, zero on them.

    Args:
        xy: ``(*, 2)``.
        radius: the radius ``r`` of both circles, a number or ``(*)`` tensor.

    Returns:
        ``(*)``.

    Example:
        >>> figure_eight_implicit(torch.tensor([[0.0, 0.0], [-5.0, 0.0], [10.0, 0.0]]))
        tensor([    0., -1875.,     0.])
    """
    check_float(xy, "xy", low_precision=False)
    check_shape(xy, ["*", "2"], "xy")
    radius = _param(radius, xy, "radius")
    zero = torch.zeros_like(radius)
    left = implicit_circle(xy, torch.stack([-radius, zero], -1), radius)
    right = implicit_circle(xy, torch.stack([radius, zero], -1), radius)
    return left * right


def figure_eight_parametric(t: torch.Tensor, radius=5.0) -> torch.Tensor:
    """The parametric figure-eight: the two circles stitched at the origin.

    ``t`` in ``[0, 2 pi)`` runs counter-clockwise round the left circle (centre
    ``(-r, 0)``) from the origin; ``t`` in ``[2 pi, 4 pi)`` runs clockwise round
    the right circle (centre ``(r, 0)``) from the origin. Both halves leave the
    origin heading +y, so the stitched curve is continuous with a continuous
    tangent (G1) and is periodic with period ``4 pi``.

    Convention:
        ``t`` in radians; values outside ``[0, 4 pi)`` wrap around.

    Args:
        t: ``(T,)`` or ``(*, T)``.
        radius: a number or ``(*)`` tensor.

    Returns:
        ``(*, T, 2)``.

    Example:
        >>> t = torch.tensor([0.0, math.pi, 2 * math.pi, 3 * math.pi])
        >>> figure_eight_parametric(t, radius=1.0).round(decimals=4) + 0.0
        tensor([[ 0.,  0.],
                [-2.,  0.],
                [ 0.,  0.],
                [ 2.,  0.]])
    """
    _check_t(t)
    radius = _param(radius, t, "radius")
    check_broadcastable({"t": t.shape[:-1], "radius": radius.shape})
    radius = radius[..., None]
    phase = torch.remainder(t, 4 * math.pi)
    on_left = phase < 2 * math.pi
    # Left: (-r, 0) + r (cos t, sin t). Right: (r, 0) + r (cos(pi - s), sin(pi - s)), s = t - 2 pi.
    angle = torch.where(on_left, phase, 3 * math.pi - phase)
    shift = torch.where(on_left, -radius, radius)
    return torch.stack([shift + radius * torch.cos(angle), radius * torch.sin(angle)], dim=-1)


def grid_2d(n: int = 2000, low: float = -10.0, high: float = 10.0, device=None,
            dtype=None) -> torch.Tensor:
    """An ``n x n`` grid of points over ``[low, high]^2`` (report: 2000 points on [-10, 10]).

    Convention:
        ``indexing="ij"``: ``grid[i, j] = (x_i, y_j)``, axis 0 is x. The origin is
        ``(low, low)`` and the spacing ``(high - low) / (n - 1)`` on both axes.

    Args:
        n: points per axis, ``>= 2``.
        low, high: the interval.
        device, dtype: of the result (torch defaults when ``None``).

    Returns:
        ``(n, n, 2)``.

    Example:
        >>> grid_2d(3, -1.0, 1.0)[:, :, 0]
        tensor([[-1., -1., -1.],
                [ 0.,  0.,  0.],
                [ 1.,  1.,  1.]])
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise ValueError(f"n: expected an int >= 2, got {n!r}")
    axis = torch.linspace(low, high, n, device=device, dtype=dtype)
    x, y = torch.meshgrid(axis, axis, indexing="ij")
    return torch.stack([x, y], dim=-1)
