"""Cubic Hermite curves and splines: basis, curves, C1 splines, PCHIP, Catmull-Rom.

A cubic Hermite segment from
``p0`` to ``p1`` with end tangents ``m0, m1`` is

``H(t) = H00(t) p0 + H10(t) m0 + H01(t) p1 + H11(t) m1``, ``t`` in ``[0, 1]``,

``H00 = (1 + 2t)(1 - t)^2, H10 = t (1 - t)^2, H01 = t^2 (3 - 2t), H11 = t^2 (t - 1)``.

A Hermite *spline* strings segments over knots ``x_0 < ... < x_{K-1}``; on
``[x_i, x_{i+1}]`` with ``h = x_{i+1} - x_i`` and ``s = (x - x_i) / h``,
``f(x) = H00(s) y_i + H01(s) y_{i+1} + h (H10(s) m_i + H11(s) m_{i+1})``, where the
``m`` are derivatives ``df/dx`` at the knots. It is C1 by construction.

Convention:
    - Points and tangents of single curves are ``(*, D)``; parameters ``t`` are
      ``(T,)`` shared or ``(*, T)`` per curve; results ``(*, T, D)``. ``t``
      outside ``[0, 1]`` extrapolates the cubic.
    - Splines are scalar-valued per series: knots ``(K,)`` shared or ``(*, K)``,
      values and tangents ``(*, K)``, queries ``(Q,)`` shared or ``(*, Q)``; the
      result is ``(*, Q)``. For a curve in ``D`` dimensions put the coordinates in
      the batch (values ``(..., D, K)``).
    - Queries outside ``[x_0, x_{K-1}]`` extrapolate the first or last cubic, as
      scipy does with ``extrapolate=True``.
    - Knots must be strictly increasing; the error names the first offending index.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import ShapeError, check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.curves._knot_checks import check_knots

__all__ = [
    "hermite_basis",
    "hermite",
    "HermiteControls",
    "hermite_to_bezier",
    "bezier_to_hermite",
    "HermiteCurve",
    "hermite_spline",
    "HermiteSpline",
    "pchip_tangents",
    "pchip_interpolate",
    "PchipInterpolator",
    "cardinal_tangents",
    "catmull_rom_tangents",
]


def hermite_basis(t: torch.Tensor) -> torch.Tensor:
    """The four cubic Hermite basis functions ``H00, H10, H01, H11`` (module docstring).

    Convention:
        Column order ``H00, H10, H01, H11``: weights of ``p0, m0, p1, m1``.
        ``t`` outside ``[0, 1]`` extrapolates.

    Args:
        t: ``(*, T)`` parameters.

    Returns:
        ``(*, T, 4)``.

    Example:
        >>> hermite_basis(torch.tensor([0.0, 0.5, 1.0]))
        tensor([[ 1.0000,  0.0000,  0.0000,  0.0000],
                [ 0.5000,  0.1250,  0.5000, -0.1250],
                [ 0.0000,  0.0000,  1.0000,  0.0000]])
    """
    check_float(t, "t", low_precision=False)
    check_shape(t, ["*", "T"], "t")
    s = 1 - t
    t2 = t * t
    return torch.stack([(1 + 2 * t) * s * s, t * s * s, t2 * (3 - 2 * t), t2 * (t - 1)], dim=-1)


class HermiteControls(NamedTuple):
    """End points and end tangents of cubic Hermite segments, each ``(*, D)``.

    Example:
        >>> line = torch.tensor([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
        >>> controls = bezier_to_hermite(line)
        >>> controls.m0, controls.p1
        (tensor([3., 0.]), tensor([3., 0.]))
    """

    p0: torch.Tensor
    p1: torch.Tensor
    m0: torch.Tensor
    m1: torch.Tensor


def _check_controls(p0, p1, m0, m1) -> tuple[torch.Tensor, ...]:
    sizes: dict = {}
    for value, name in ((p0, "p0"), (p1, "p1"), (m0, "m0"), (m1, "m1")):
        check_float(value, name, low_precision=False)
        sizes = check_shape(value, ["*", "D"], name, sizes={"D": sizes["D"]} if sizes else None)
    check_broadcastable({"p0": p0.shape[:-1], "p1": p1.shape[:-1], "m0": m0.shape[:-1],
                         "m1": m1.shape[:-1]})
    return torch.broadcast_tensors(p0, p1, m0, m1)


def hermite(p0: torch.Tensor, p1: torch.Tensor, m0: torch.Tensor, m1: torch.Tensor,
            t: torch.Tensor) -> torch.Tensor:
    """Cubic Hermite curves ``H00 p0 + H10 m0 + H01 p1 + H11 m1`` (Appendix A).

    Convention:
        Tangents are derivatives with respect to ``t`` in ``[0, 1]`` (so a tangent
        of length ``L`` matters as much as a chord of length ``L``); ``t`` outside
        ``[0, 1]`` extrapolates. Batch dimensions of the four controls broadcast.

    Args:
        p0, p1: ``(*, D)`` end points.
        m0, m1: ``(*, D)`` end tangents.
        t: ``(T,)`` or ``(*, T)``.

    Returns:
        ``(*, T, D)``.

    Example:
        >>> p0, p1 = torch.tensor([0.0, 0.0]), torch.tensor([1.0, 0.0])
        >>> m0, m1 = torch.tensor([0.0, 1.0]), torch.tensor([0.0, -1.0])
        >>> hermite(p0, p1, m0, m1, torch.tensor([0.0, 0.5, 1.0]))
        tensor([[0.0000, 0.0000],
                [0.5000, 0.2500],
                [1.0000, 0.0000]])
    """
    p0, p1, m0, m1 = _check_controls(p0, p1, m0, m1)
    basis = hermite_basis(t)  # (*, T, 4)
    check_broadcastable({"p0, p1, m0, m1": p0.shape[:-1], "t": t.shape[:-1]})
    controls = torch.stack([p0, m0, p1, m1], dim=-2)  # (*, 4, D)
    dtype = torch.promote_types(basis.dtype, controls.dtype)
    return torch.matmul(basis.to(dtype), controls.to(dtype))


def hermite_to_bezier(p0: torch.Tensor, p1: torch.Tensor, m0: torch.Tensor,
                      m1: torch.Tensor) -> torch.Tensor:
    """Cubic Bezier control points of the same curve: ``p0, p0 + m0/3, p1 - m1/3, p1``.

    Convention:
        Tangents are ``dH/dt`` on ``[0, 1]``; the Bezier curve equals the Hermite
        curve at every ``t``.

    Args:
        p0, p1, m0, m1: ``(*, D)``.

    Returns:
        ``(*, 4, D)``.

    Example:
        >>> hermite_to_bezier(torch.tensor([0.0, 0.0]), torch.tensor([3.0, 0.0]),
        ...                   torch.tensor([3.0, 3.0]), torch.tensor([3.0, -3.0]))
        tensor([[0., 0.],
                [1., 1.],
                [2., 1.],
                [3., 0.]])
    """
    p0, p1, m0, m1 = _check_controls(p0, p1, m0, m1)
    return torch.stack([p0, p0 + m0 / 3, p1 - m1 / 3, p1], dim=-2)


def bezier_to_hermite(control_points: torch.Tensor) -> HermiteControls:
    """Hermite controls of a cubic Bezier curve: ``m0 = 3 (P1 - P0)``, ``m1 = 3 (P3 - P2)``.

    Convention:
        Inverse of :func:`hermite_to_bezier`.

    Args:
        control_points: ``(*, 4, D)``.

    Returns:
        :class:`HermiteControls` ``(p0, p1, m0, m1)``, each ``(*, D)``.

    Raises:
        ShapeError: not exactly 4 control points.

    Example:
        >>> bezier_to_hermite(torch.tensor([[0.0, 0.0], [1.0, 1.0], [2.0, 1.0], [3.0, 0.0]])).m1
        tensor([ 3., -3.])
    """
    check_float(control_points, "control_points", low_precision=False)
    check_shape(control_points, ["*", "K", "D"], "control_points")
    if control_points.shape[-2] != 4:
        raise ShapeError(
            "control_points: a cubic (degree 3) Bezier curve needs degree + 1 = 4 control "
            f"points, got {control_points.shape[-2]} (shape {tuple(control_points.shape)})"
        )
    P = control_points
    return HermiteControls(P[..., 0, :], P[..., 3, :], 3 * (P[..., 1, :] - P[..., 0, :]),
                           3 * (P[..., 3, :] - P[..., 2, :]))


class HermiteCurve(nn.Module):
    """A (batch of) cubic Hermite curve(s) with learnable end points and tangents.

    ``forward(t)`` is :func:`hermite`; the four controls are ``nn.Parameter`` when
    ``learnable`` (default), else buffers.

    Convention:
        As :func:`hermite`.

    Args:
        p0, p1, m0, m1: ``(*, D)``.
        learnable: make the controls parameters.

    Example:
        >>> curve = HermiteCurve(torch.tensor([0.0, 0.0]), torch.tensor([1.0, 0.0]),
        ...                      torch.tensor([0.0, 1.0]), torch.tensor([0.0, -1.0]))
        >>> curve(torch.tensor([0.5])).detach()
        tensor([[0.5000, 0.2500]])
        >>> curve.to_bezier().detach()[1]
        tensor([0.0000, 0.3333])
    """

    p0: torch.Tensor
    p1: torch.Tensor
    m0: torch.Tensor
    m1: torch.Tensor

    def __init__(self, p0: torch.Tensor, p1: torch.Tensor, m0: torch.Tensor, m1: torch.Tensor,
                 learnable: bool = True) -> None:
        super().__init__()
        controls = _check_controls(p0, p1, m0, m1)
        self.learnable = learnable
        for name, value in zip(("p0", "p1", "m0", "m1"), controls):
            if learnable:
                setattr(self, name, nn.Parameter(value.detach().clone()))
            else:
                self.register_buffer(name, value, persistent=False)

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        """``(T,)`` or ``(*, T)`` -> ``(*, T, D)``."""
        check_module_dtype(self, t, "t")
        return hermite(self.p0, self.p1, self.m0, self.m1, t)

    def to_bezier(self) -> torch.Tensor:
        """``(*, 4, D)`` cubic Bezier control points of the same curve."""
        return hermite_to_bezier(self.p0, self.p1, self.m0, self.m1)


# --------------------------------------------------------------------------- splines


def _check_series(knots, values, name, knots_name: str = "knots") -> tuple[int, ...]:
    """Check knots and one series against them; return their broadcast batch shape."""
    sizes = check_knots(knots, knots_name)
    check_float(values, name, low_precision=False)
    check_shape(values, ["*", "K"], name, sizes={"K": sizes["K"]})
    return check_broadcastable({knots_name: knots.shape[:-1], name: values.shape[:-1]})


def _interval(knots: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Index ``i`` in ``[0, K - 2]`` with ``x_i <= x < x_{i+1}`` (clamped at the ends)."""
    k = knots.shape[-1]
    if knots.dim() == 1:
        idx = torch.searchsorted(knots, x.detach().contiguous(), right=True)
    else:
        batch = torch.broadcast_shapes(knots.shape[:-1], x.shape[:-1])
        idx = torch.searchsorted(knots.detach().expand(*batch, k).contiguous(),
                                 x.detach().expand(*batch, x.shape[-1]).contiguous(), right=True)
    return (idx - 1).clamp(0, k - 2)


def _spline_weights(knots, x, idx):
    """Weights of ``y_i, y_{i+1}, m_i, m_{i+1}`` at queries: each shaped like ``idx``."""
    if knots.dim() == 1:
        x0, x1 = knots[idx], knots[idx + 1]
    else:
        knots = knots.expand(*idx.shape[:-1], knots.shape[-1])
        x0, x1 = knots.gather(-1, idx), knots.gather(-1, idx + 1)
    h = x1 - x0
    s = (x - x0) / h  # knots strictly increasing: h > 0
    basis = hermite_basis(s)
    return basis[..., 0], basis[..., 2], h * basis[..., 1], h * basis[..., 3]


def hermite_spline(knots: torch.Tensor, values: torch.Tensor, tangents: torch.Tensor,
                   x: torch.Tensor) -> torch.Tensor:
    """Evaluate piecewise cubic Hermite splines (C1) at queries ``x``.

    Matches ``scipy.interpolate.CubicHermiteSpline(knots, values, tangents)(x)``.

    Convention:
        See the module docstring: knots ``(K,)`` or ``(*, K)``; values, tangents
        ``(*, K)`` (tangents are ``df/dx``); queries ``(Q,)`` or ``(*, Q)``;
        extrapolation with the end cubics. Differentiable with respect to values,
        tangents, knots and queries.

    Args:
        knots: ``(K,)`` or ``(*, K)`` strictly increasing.
        values: ``(*, K)``.
        tangents: ``(*, K)``.
        x: ``(Q,)`` or ``(*, Q)``.

    Returns:
        ``(*, Q)``.

    Example:
        >>> knots = torch.tensor([0.0, 1.0, 3.0])
        >>> hermite_spline(knots, torch.tensor([0.0, 1.0, 0.0]), torch.tensor([1.0, 0.0, -1.0]),
        ...                torch.tensor([0.5, 1.0, 2.0]))
        tensor([0.6250, 1.0000, 0.7500])
    """
    _check_series(knots, values, "values")
    check_float(tangents, "tangents", low_precision=False)
    check_shape(tangents, ["*", "K"], "tangents", sizes={"K": knots.shape[-1]})
    check_float(x, "x", low_precision=False)
    check_shape(x, ["*", "Q"], "x")
    batch = check_broadcastable({"knots": knots.shape[:-1], "values": values.shape[:-1],
                                 "tangents": tangents.shape[:-1], "x": x.shape[:-1]})
    if knots.dim() == 1 and x.dim() == 1:
        return _shared_spline(knots, _stack_series(values, tangents), x, batch)
    idx = _interval(knots, x)
    w0, w1, w2, w3 = _spline_weights(knots, x, idx)
    batch = torch.broadcast_shapes(values.shape[:-1], tangents.shape[:-1], idx.shape[:-1])
    idx = idx.expand(*batch, idx.shape[-1])

    def take(v, i):
        return v.expand(*batch, v.shape[-1]).gather(-1, i)

    return (w0 * take(values, idx) + w1 * take(values, idx + 1)
            + w2 * take(tangents, idx) + w3 * take(tangents, idx + 1))


def _stack_series(values: torch.Tensor, tangents: torch.Tensor) -> torch.Tensor:
    """``(*, K)`` values and tangents -> ``(2K, B)``, knots first, series last."""
    values, tangents = torch.broadcast_tensors(values, tangents)
    k = values.shape[-1]
    return torch.cat([values.reshape(-1, k).t(), tangents.reshape(-1, k).t()], dim=0)


def _shared_spline(knots: torch.Tensor, table: torch.Tensor, x: torch.Tensor,
                   batch: tuple[int, ...]) -> torch.Tensor:
    """Shared knots ``(K,)`` and queries ``(Q,)``; ``table (2K, B)`` from :func:`_stack_series`.

    Each query is a 4-term weighted sum of table rows: one fused ``embedding_bag``.
    """
    k = knots.shape[-1]
    idx = _interval(knots, x)  # (Q,)
    weights = torch.stack(_spline_weights(knots, x, idx), dim=-1)  # (Q, 4)
    rows = torch.stack([idx, idx + 1, idx + k, idx + k + 1], dim=-1)  # (Q, 4)
    dtype = torch.promote_types(weights.dtype, table.dtype)
    table, weights = table.to(dtype), weights.to(dtype)
    if table.shape[1] == 0 or rows.shape[0] == 0:
        return table.new_zeros(*batch, x.shape[0])
    out = F.embedding_bag(rows, table, per_sample_weights=weights, mode="sum")  # (Q, B)
    return out.t().reshape(*batch, x.shape[0])


class HermiteSpline(nn.Module):
    """Piecewise cubic Hermite spline module; ``forward(x)`` is :func:`hermite_spline`.

    Convention:
        As :func:`hermite_spline`. Knots are a buffer; values and tangents are
        parameters when ``learnable`` else buffers (``.to()`` moves all of them).

    Args:
        knots: ``(K,)`` or ``(*, K)``.
        values: ``(*, K)``.
        tangents: ``(*, K)``.
        learnable: make values and tangents ``nn.Parameter``.

    Example:
        >>> spline = HermiteSpline(torch.tensor([0.0, 1.0, 3.0]), torch.tensor([0.0, 1.0, 0.0]),
        ...                        torch.tensor([1.0, 0.0, -1.0]))
        >>> spline(torch.tensor([0.5, 2.0]))
        tensor([0.6250, 0.7500])
    """

    knots: torch.Tensor
    values: torch.Tensor
    tangents: torch.Tensor

    def __init__(self, knots: torch.Tensor, values: torch.Tensor, tangents: torch.Tensor,
                 learnable: bool = False) -> None:
        super().__init__()
        _check_series(knots, values, "values")
        check_float(tangents, "tangents", low_precision=False)
        check_shape(tangents, ["*", "K"], "tangents", sizes={"K": knots.shape[-1]})
        check_broadcastable({"knots": knots.shape[:-1], "values": values.shape[:-1],
                             "tangents": tangents.shape[:-1]})
        self.learnable = learnable
        self.register_buffer("knots", knots, persistent=False)
        for name, value in (("values", values), ("tangents", tangents)):
            if learnable:
                setattr(self, name, nn.Parameter(value.detach().clone()))
            else:
                self.register_buffer(name, value, persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(Q,)`` or ``(*, Q)`` queries -> ``(*, Q)``."""
        check_module_dtype(self, x, "x")
        return hermite_spline(self.knots, self.values, self.tangents, x)


# --------------------------------------------------------------------------- PCHIP


def _edge_tangent(h0, h1, m0, m1):
    """scipy's three-point end rule, clipped for shape preservation."""
    d = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    zero = torch.sign(d) != torch.sign(m0)
    clip = (torch.sign(m0) != torch.sign(m1)) & (d.abs() > 3 * m0.abs()) & ~zero
    return torch.where(zero, torch.zeros_like(d), torch.where(clip, 3 * m0, d))


def _pchip_knots_first(h: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """PCHIP derivatives with knots in dim 0: ``h (K-1, 1 or B)``, ``y (K, B)`` -> ``(K, B)``."""
    slope = (y[1:] - y[:-1]) / h  # (K-1, B)
    if y.shape[0] == 2:
        return torch.cat([slope, slope], dim=0)
    # scipy: sign change, or either slope zero -> derivative 0 ("flat").
    negative = torch.signbit(slope)
    flat = (negative[1:] != negative[:-1]) | (slope[1:] == 0) | (slope[:-1] == 0)  # (K-2, B)
    w1 = 2 * h[1:] + h[:-1]
    w2 = h[1:] + 2 * h[:-1]
    left = torch.where(flat, 1.0, slope[:-1])  # double where: no 1/0 in either branch
    right = torch.where(flat, 1.0, slope[1:])
    harmonic = (w1 / left + w2 / right) / (w1 + w2)  # weighted harmonic mean of the slopes
    inner = torch.where(flat, 0.0, 1.0 / harmonic)
    first = _edge_tangent(h[:1], h[1:2], slope[:1], slope[1:2])
    last = _edge_tangent(h[-1:], h[-2:-1], slope[-1:], slope[-2:-1])
    return torch.cat([first, inner, last], dim=0)


def _pchip_knots_first_into(h: torch.Tensor, y: torch.Tensor, out: torch.Tensor) -> None:
    """:func:`_pchip_knots_first` without autograd, writing into ``out (K, B)``.

    Same operations in the same order (so the same rounding as scipy), but with
    two float temporaries instead of about twelve: large fresh allocations cost
    page faults that dominate this memory-bound step.
    """
    slope = torch.sub(y[1:], y[:-1]).div_(h)  # (K-1, B)
    if y.shape[0] == 2:
        out.copy_(slope.expand(2, -1))
        return
    negative = torch.signbit(slope)
    flat = negative[1:] != negative[:-1]
    flat |= slope[1:] == 0
    flat |= slope[:-1] == 0
    w1 = 2 * h[1:] + h[:-1]
    w2 = h[1:] + 2 * h[:-1]
    out[:1] = _edge_tangent(h[:1], h[1:2], slope[:1], slope[1:2])
    out[-1:] = _edge_tangent(h[-1:], h[-2:-1], slope[-1:], slope[-2:-1])
    inner = out[1:-1]
    # Flat entries are overwritten with 0 below; give them a safe slope of 1 first.
    torch.div(w1, slope[:-1].masked_fill(flat, 1.0), out=inner)
    inner.add_(torch.div(w2, slope[1:].masked_fill_(flat, 1.0)))
    inner.div_(w1 + w2).reciprocal_().masked_fill_(flat, 0.0)


def pchip_tangents(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Shape-preserving PCHIP derivatives (Fritsch-Butland), exactly scipy's rule.

    Interior knots: 0 where the neighbouring slopes differ in sign or one is 0,
    else the weighted harmonic mean ``(w1 + w2) / (w1 / d_{k-1} + w2 / d_k)`` with
    ``w1 = 2 h_k + h_{k-1}``, ``w2 = h_k + 2 h_{k-1}``. End knots: the one-sided
    three-point estimate ``((2 h0 + h1) d0 - h0 d1) / (h0 + h1)``, set to 0 if its
    sign differs from ``d0`` and to ``3 d0`` if ``d0, d1`` differ in sign and it
    exceeds ``3 |d0|``. With 2 knots both derivatives are the slope.

    Convention:
        Derivatives ``dy/dx``. Matches ``scipy.interpolate.PchipInterpolator`` to
        rounding. Gradients are finite (the discarded branches never divide by 0).

    Args:
        x: ``(K,)`` or ``(*, K)`` strictly increasing knots.
        y: ``(*, K)`` values.

    Returns:
        ``(*, K)``.

    Example:
        >>> pchip_tangents(torch.tensor([0.0, 1.0, 2.0, 3.0]), torch.tensor([0.0, 1.0, 1.0, 3.0]))
        tensor([1.5000, 0.0000, 0.0000, 3.0000])
    """
    batch = _check_series(x, y, "y", "x")
    k = x.shape[-1]
    dtype = torch.promote_types(x.dtype, y.dtype)
    y_kf = y.to(dtype).expand(*batch, k).reshape(-1, k).t()  # (K, B)
    if x.dim() == 1:
        h = (x[1:] - x[:-1]).to(dtype)[:, None]  # (K-1, 1)
    else:
        x_kf = x.to(dtype).expand(*batch, k).reshape(-1, k).t()
        h = x_kf[1:] - x_kf[:-1]
    return _pchip_knots_first(h, y_kf.contiguous()).t().reshape(*batch, k)


def pchip_interpolate(x: torch.Tensor, y: torch.Tensor, xq: torch.Tensor) -> torch.Tensor:
    """One-shot PCHIP: :func:`pchip_tangents` then :func:`hermite_spline` at ``xq``.

    Convention:
        As :class:`PchipInterpolator`.

    Args:
        x: ``(K,)`` or ``(*, K)``.
        y: ``(*, K)``.
        xq: ``(Q,)`` or ``(*, Q)``.

    Returns:
        ``(*, Q)``.

    Example:
        >>> pchip_interpolate(torch.tensor([0.0, 1.0, 2.0]), torch.tensor([0.0, 1.0, 4.0]),
        ...                   torch.tensor([0.5, 1.5]))
        tensor([0.3125, 2.1875])
    """
    return PchipInterpolator(x, y)(xq)


class PchipInterpolator(nn.Module):
    """Monotone piecewise cubic interpolation, identical to scipy's ``PchipInterpolator``.

    Tangents are computed once at construction (:func:`pchip_tangents`), with
    gradients when ``y`` requires them; ``forward(xq)`` evaluates the spline.

    Convention:
        Knots ``(K,)`` shared or ``(*, K)``; ``y (*, K)``; queries ``(Q,)`` or
        ``(*, Q)``; extrapolation with the end cubics (scipy's ``extrapolate=True``).

    Args:
        x: ``(K,)`` or ``(*, K)`` strictly increasing knots.
        y: ``(*, K)`` values.

    Example:
        >>> interp = PchipInterpolator(torch.tensor([0.0, 1.0, 2.0]), torch.tensor([0.0, 1.0, 4.0]))
        >>> interp.tangents
        tensor([0.0000, 1.5000, 4.0000])
        >>> interp(torch.tensor([0.5, 1.5]))
        tensor([0.3125, 2.1875])
    """

    knots: torch.Tensor
    values: torch.Tensor
    tangents: torch.Tensor

    def __init__(self, x: torch.Tensor, y: torch.Tensor) -> None:
        super().__init__()
        batch = _check_series(x, y, "y", "x")
        k = x.shape[-1]
        dtype = torch.promote_types(x.dtype, y.dtype)
        x, y = x.to(dtype), y.to(dtype)
        self._batch = batch
        self.register_buffer("knots", x, persistent=False)
        self.register_buffer("values", y, persistent=False)
        y_flat = y.expand(*batch, k).reshape(-1, k)  # (B, K)
        needs_grad = records_graph(x, y)
        if x.dim() == 1 and not needs_grad:
            # Shared knots, no autograd: build the knots-first table in place.
            table = y.new_empty(2 * k, y_flat.shape[0])  # (2K, B): values, then tangents
            table[:k] = y_flat.t()
            _pchip_knots_first_into((x[1:] - x[:-1])[:, None], table[:k], table[k:])
            self.register_buffer("_table", table, persistent=False)
            tangents_kf = table[k:]
        elif x.dim() == 1:
            y_kf = y_flat.t().contiguous()  # (K, B)
            tangents_kf = _pchip_knots_first((x[1:] - x[:-1])[:, None], y_kf)
            # Shared knots: keep the knots-first table for the fused evaluation.
            self.register_buffer("_table", torch.cat([y_kf, tangents_kf], 0), persistent=False)
        else:
            y_kf = y_flat.t().contiguous()
            x_kf = x.expand(*batch, k).reshape(-1, k).t()
            tangents_kf = _pchip_knots_first(x_kf[1:] - x_kf[:-1], y_kf)
            self._table = None
        self.register_buffer("tangents", tangents_kf.t().reshape(*batch, k), persistent=False)

    def forward(self, xq: torch.Tensor) -> torch.Tensor:
        """``(Q,)`` or ``(*, Q)`` queries -> ``(*, Q)``."""
        check_module_dtype(self, xq, "xq")
        check_float(xq, "xq", low_precision=False)
        check_shape(xq, ["*", "Q"], "xq")
        check_broadcastable({"x": self.knots.shape[:-1], "y": self._batch, "xq": xq.shape[:-1]})
        if self._table is not None and xq.dim() == 1:
            return _shared_spline(self.knots, self._table, xq, self._batch)
        return hermite_spline(self.knots, self.values, self.tangents, xq)


# --------------------------------------------------------------------------- cardinal


def cardinal_tangents(knots: torch.Tensor, values: torch.Tensor,
                      tension: float = 0.0) -> torch.Tensor:
    """Cardinal-spline derivatives ``(1 - c) (y_{k+1} - y_{k-1}) / (x_{k+1} - x_{k-1})``.

    ``tension = c = 0`` gives Catmull-Rom; ``c = 1`` gives zero tangents. End knots
    use the one-sided difference ``(1 - c)(y_1 - y_0) / (x_1 - x_0)`` (and likewise
    at the end).

    Convention:
        Derivatives ``dy/dx`` for :func:`hermite_spline`. For a Catmull-Rom curve
        through points ``(*, D, K)`` use ``knots = arange(K)`` (uniform).

    Args:
        knots: ``(K,)`` or ``(*, K)`` strictly increasing.
        values: ``(*, K)``.
        tension: ``c``.

    Returns:
        ``(*, K)``.

    Example:
        >>> knots = torch.tensor([0.0, 1.0, 2.0, 3.0])
        >>> cardinal_tangents(knots, torch.tensor([0.0, 1.0, 0.0, 1.0]), tension=0.5)
        tensor([0.5000, 0.0000, 0.0000, 0.5000])
    """
    _check_series(knots, values, "values")
    if isinstance(tension, bool) or not isinstance(tension, (int, float)):
        raise TypeError(f"tension: expected a number, got {type(tension).__name__}")
    x, y = torch.broadcast_tensors(knots, values) if knots.dim() > 1 else (knots, values)
    if knots.shape[-1] == 2:
        slope = (y[..., 1:] - y[..., :-1]) / (x[..., 1:] - x[..., :-1])
        return (1 - tension) * torch.cat([slope, slope], dim=-1)
    inner = (y[..., 2:] - y[..., :-2]) / (x[..., 2:] - x[..., :-2])
    first = (y[..., 1:2] - y[..., :1]) / (x[..., 1:2] - x[..., :1])
    last = (y[..., -1:] - y[..., -2:-1]) / (x[..., -1:] - x[..., -2:-1])
    shape = torch.broadcast_shapes(inner.shape[:-1], first.shape[:-1])
    parts = [p.expand(*shape, p.shape[-1]) for p in (first, inner, last)]
    return (1 - tension) * torch.cat(parts, dim=-1)


def catmull_rom_tangents(knots: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """Catmull-Rom derivatives: :func:`cardinal_tangents` with ``tension = 0``.

    Convention:
        As :func:`cardinal_tangents`.

    Args:
        knots: ``(K,)`` or ``(*, K)``.
        values: ``(*, K)``.

    Returns:
        ``(*, K)``.

    Example:
        >>> catmull_rom_tangents(torch.tensor([0.0, 1.0, 3.0]), torch.tensor([0.0, 1.0, 5.0]))
        tensor([1.0000, 1.6667, 2.0000])
    """
    return cardinal_tangents(knots, values, 0.0)
