"""B-spline curves of any degree and dimension: evaluation, derivatives, closed curves.

``C(t) = sum_i N_{i,p}(t) P_i`` with ``n + 1`` control points ``P_i`` and the
B-spline basis ``N_{i,p}`` of degree ``p`` over a knot vector (Piegl & Tiller, The
NURBS Book, ch. 2-3).

Convention:
    - Control points are ``(*, n + 1, D)``, as for :func:`~torchgeo_cg.curves.bezier`;
      ``n + 1 >= p + 1``.
    - ``t`` is ``(T,)`` (shared) or ``(*, T)`` (per curve, broadcast against the
      control points' batch). ``knots`` is ``(n + p + 2,)`` (shared) or
      ``(*, n + p + 2)`` (per curve), always the full non-decreasing vector; the
      domain is ``[u_p, u_{n+1}]``. ``knots=None`` means clamped uniform knots on
      ``[0, 1]``, where the curve starts at ``P_0``, ends at ``P_n``, and with
      ``n = p`` is the Bezier curve of the same control points.
    - Spans are right-continuous (scipy's rule); ``t`` outside the domain
      extrapolates the end pieces, as scipy's ``BSpline(extrapolate=True)``.
    - ``periodic=True``: a closed curve through the ``n + 1`` distinct control points
      ``P_0..P_n``; the basis runs over the wrapped points ``P_0..P_n, P_0..P_{p-1}``
      and ``t`` is taken modulo the period. ``knots`` is then one period of
      ``n + 2`` breakpoints ``tau_0 < ... < tau_{n+1}`` (``None``: uniform on
      ``[0, 1]``); the full vector of the wrapped curve (``n + 2p + 2`` values) is
      their periodic extension. The curve is ``C^(p-1)`` everywhere, the seam too.
    - Differentiable with respect to control points, ``t`` and knots. dtypes are
      promoted (``torch.promote_types``); float16/bfloat16 are rejected.
    - Scale: the curve is affine in the control points, so scaling them by ``s``
      scales points and derivatives by ``s``; no threshold anywhere.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import nn

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.curves._basis import find_spans, local_basis_list, span_limits
from torchgeo_cg.curves._bspline_core import evaluate_local, prepare_bspline
from torchgeo_cg.curves.bernstein import check_degree

#: per-curve knots or parameters: evaluate the values (not derivatives, whose forward
#: differences lose digits on short spans) by Bezier segments (one table row per span,
#: then a few operations per parameter) when ``T * SEGMENT_RATIO >= S`` spans and every
#: parameter is inside the domain (the Bernstein form extrapolates badly); else by the
#: basis recurrence at every parameter
_SEGMENT_RATIO = 4
#: parameters per chunk of :func:`evaluate_table` (its intermediates stay in cache)
_CHUNK = 16384

__all__ = ["BSplineControls", "BSplineCurve", "bspline", "bspline_derivative"]


class BSplineControls(NamedTuple):
    """A B-spline as data: control points ``(*, n + 1, D)`` and full knots ``(*, n + p + 2)``.

    Returned by :func:`insert_knot`, :func:`bezier_to_bspline` and
    :func:`interpolate_bspline`.

    Example:
        >>> from torchgeo_cg.curves import bezier_to_bspline
        >>> bezier_to_bspline(torch.tensor([[[0.0], [1.0]]])).knots
        tensor([0., 0., 1., 1.])
    """

    control_points: torch.Tensor
    knots: torch.Tensor


def _evaluate(control_points, t, knots, degree: int, order: int) -> torch.Tensor:
    if t.numel() == 0 or control_points.numel() == 0:
        batch = torch.broadcast_shapes(control_points.shape[:-2], t.shape[:-1], knots.shape[:-1])
        return control_points.new_zeros(*batch, t.shape[-1], control_points.shape[-1])
    if knots.dim() > 1 or t.dim() > 1:
        batch = torch.broadcast_shapes(knots.shape[:-1], t.shape[:-1])
        if order == 0 and t.shape[-1] * _SEGMENT_RATIO >= control_points.shape[-2] - degree \
                and _inside(t, knots, degree, control_points.shape[-2]):
            table = _bezier_table(control_points, knots, degree)
            return _evaluate_table(table, knots, t, degree, control_points.shape[-1])
        knots, t = knots.expand(*batch, knots.shape[-1]), t.expand(*batch, t.shape[-1])
    spans = find_spans(knots, t, degree)
    basis = local_basis_list(knots, t, spans, degree, order)[order]
    return evaluate_local(control_points, basis, spans, degree)


def _bezier_table(control_points, knots, degree: int) -> torch.Tensor:
    """Every knot span as a scaled Bezier segment: ``(W, *, S)``, ``W = (p + 1) D + 2``.

    For the ``S = n - p + 1`` spans ``s = p..n``: the first ``(p + 1) D`` rows hold
    ``C(p, m) b_m`` (``b_m`` the span's Bezier points, coordinate-minor), then ``u_s`` and
    ``h = u_{s+1} - u_s``; so ``C(t) = sum_m x^m (1 - x)^(p - m) row_m`` with ``x = (t -
    u_s) / h``. The Bezier points are blossoms ``b(u_{s+1}^m, u_s^(p-m))`` by de Boor's
    algorithm, sharing the common prefixes of their arguments: convex combinations, as
    stable as the basis recurrence. Empty spans (repeated knots) get finite unused rows.
    """
    count, d = control_points.shape[-2:]
    spans = count - degree
    batch = torch.broadcast_shapes(control_points.shape[:-2], knots.shape[:-1])
    knots = knots.expand(*batch, knots.shape[-1])
    start, end = knots[..., degree:count], knots[..., degree + 1:count + 1]  # (*, S)
    # layout (state, point, D, *, S): every operation runs along the spans, contiguously
    cp = control_points.expand(*batch, count, d).movedim(-1, 0)  # (D, *, n + 1)
    points = torch.stack([cp[..., i:i + spans] for i in range(degree + 1)])[None]
    for r in range(1, degree + 1):  # loop over blossom levels: (r, p + 2 - r, D, *, S)
        lo = torch.stack([knots[..., r + i:r + i + spans] for i in range(degree + 1 - r)])
        hi = torch.stack([knots[..., degree + 1 + i:degree + 1 + i + spans]
                          for i in range(degree + 1 - r)])
        gap = hi - lo  # (p + 1 - r, *, S), >= h > 0 on a non-empty span
        args = torch.stack([start] * r + [end])  # r prefixes keep u_s, one adds u_{s+1}
        alpha = (args[:, None] - lo) / torch.where(gap > 0, gap, 1.0)
        alpha = torch.where(gap > 0, alpha, 0.0)[:, :, None]  # (r + 1, p + 1 - r, 1, *, S)
        points = torch.cat([points, points[-1:]])
        points = torch.lerp(points[:, :-1], points[:, 1:], alpha)
    points = points[:, 0]  # (p + 1, D, *, S)
    binomials = torch.tensor([math.comb(degree, m) for m in range(degree + 1)],
                             dtype=points.dtype, device=points.device)
    points = points * binomials.view(-1, *([1] * (points.dim() - 1)))
    columns = torch.cat([points.flatten(0, 1), start[None], (end - start)[None]])  # (W, *, S)
    return columns


def _evaluate_table(table, knots, t, degree: int, dims: int) -> torch.Tensor:
    """Curve (or derivative) values ``(*, T, D)`` from :func:`bezier_table` rows.

    ``table`` is ``(W, *, S)``, ``knots`` ``(K,)`` or ``(*, K)``, ``t`` ``(T,)`` or ``(*, T)``
    (batches broadcast). One row is gathered per parameter; the parameters are processed a
    few curves at a time, so that every intermediate stays in cache (one pass, out of
    place, where autograd records). The result is a view of a ``(D, *, T)`` tensor, one
    contiguous plane per coordinate.
    """
    spans = table.shape[-1]
    batch = torch.broadcast_shapes(table.shape[1:-1], knots.shape[:-1], t.shape[:-1])
    columns = table.reshape(table.shape[0], -1)  # (W, curves * S)
    base = torch.arange(columns.shape[1] // spans, device=t.device).reshape(table.shape[1:-1])
    base = (base * spans - degree).expand(batch).reshape(-1, 1)  # row of span 0, each curve
    t_flat = t.expand(*batch, t.shape[-1]).reshape(-1, t.shape[-1])
    if knots.dim() > 1:
        knots = knots.expand(*batch, knots.shape[-1]).reshape(-1, knots.shape[-1])
    low, high = span_limits(knots, degree)  # (curves or 1, 1)
    count, length = t_flat.shape
    record = records_graph(table, t)
    step = count if record else max(1, _CHUNK // max(length, 1))
    out = table.new_empty(dims, count, length)
    for c in range(0, count, step):  # loop over chunks of curves
        t_c = t_flat[c:c + step].contiguous()
        k_c = knots if knots.dim() == 1 else knots[c:c + step]
        lo, hi = (low, high) if knots.dim() == 1 else (low[c:c + step], high[c:c + step])
        first = base[c:c + step]
        rows = torch.searchsorted(k_c.contiguous(), t_c.detach(), right=True).add_(first - 1)
        rows = torch.minimum(torch.maximum(rows, lo + first), hi + first).view(-1)
        if record:
            return _segment_values(columns, rows, t_c.view(-1), dims).view(
                dims, *batch, length).movedim(0, -1)
        _segment_values(columns, rows, t_c.view(-1), dims, out[:, c:c + step].view(dims, -1))
    return out.view(dims, *batch, length).movedim(0, -1)


def _segment_values(columns, rows, t, dims: int, out=None) -> torch.Tensor:
    """``sum_m x^m (1 - x)^(q - m) row_m`` at every parameter: ``(D, N)`` (into ``out``)."""
    picked = columns.gather(1, rows.expand(columns.shape[0], -1))  # (W, N), contiguous rows
    q = (columns.shape[0] - 2) // dims - 1
    if q == 0:
        return picked[:dims] if out is None else out.copy_(picked[:dims])
    x = (t - picked[-2]) / picked[-1]
    y = 1 - x
    xs, ys = [None, x], [None, y]
    for _ in range(2, q + 1):  # loop over powers
        xs.append(xs[-1] * x)
        ys.append(ys[-1] * y)
    weights = [ys[q]] + [xs[m] * ys[q - m] for m in range(1, q)] + [xs[q]]
    planes = []
    for d in range(dims):  # loop over coordinates (into ``out`` in place, if given)
        acc = torch.mul(picked[d], weights[0], out=None if out is None else out[d])
        for m in range(1, q + 1):  # loop over the q + 1 Bernstein terms: same rounding
            acc = (acc.addcmul_ if out is not None else acc.addcmul)(picked[m * dims + d],
                                                                     weights[m])
        planes.append(acc)
    if out is None:
        return torch.stack(planes)
    return out


def _inside(t, knots, degree: int, count: int) -> bool:
    """Every parameter is inside its curve's domain ``[u_p, u_{n+1}]``."""
    t = t.detach()
    low, high = t.amin(-1, keepdim=True), t.amax(-1, keepdim=True)
    knots = knots.detach()
    return bool(((low >= knots[..., degree:degree + 1])
                 & (high <= knots[..., count:count + 1])).all())


def bspline(control_points: torch.Tensor, t: torch.Tensor, degree: int,
            knots: torch.Tensor | None = None, *, periodic: bool = False) -> torch.Tensor:
    """Evaluate B-spline curves of degree ``p`` at parameters ``t``.

    Convention:
        See the module docstring: ``(*, n + 1, D)`` control points, shared or per-curve
        ``t`` and ``knots`` (full vectors, ``n + p + 2`` values), clamped uniform
        knots on ``[0, 1]`` by default, right-continuous spans, extrapolation outside
        the domain, ``periodic`` closed curves.

    Args:
        control_points: ``(*, n + 1, D)``.
        t: ``(T,)`` or ``(*, T)`` parameters.
        degree: ``p >= 0``.
        knots: ``(n + p + 2,)`` or ``(*, n + p + 2)``; periodic: ``(*, n + 2)``
            breakpoints of one period; ``None``: uniform on ``[0, 1]``.
        periodic: a closed curve (see the module docstring).

    Returns:
        ``(*, T, D)`` points (for shared ``t`` and knots, a view of one matrix product).

    Raises:
        ShapeError: too few control points, or knots of the wrong length.
        ValueError: knots that decrease (naming the first) or an empty domain.

    Example:
        >>> P = torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]])
        >>> bspline(P, torch.tensor([0.0, 0.5, 1.0]), 2)
        tensor([[0.0000, 0.0000],
                [2.0000, 2.0000],
                [4.0000, 0.0000]])
        >>> square = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        >>> bspline(square, torch.tensor([0.0, 1.0]), 1, periodic=True)  # closed
        tensor([[0., 0.],
                [0., 0.]])
    """
    control_points, t, knots = prepare_bspline(control_points, t, degree, knots, periodic)
    return _evaluate(control_points, t, knots, degree, 0)


def bspline_derivative(control_points: torch.Tensor, t: torch.Tensor, degree: int,
                       order: int = 1, knots: torch.Tensor | None = None, *,
                       periodic: bool = False) -> torch.Tensor:
    """The ``order``-th derivative ``d^k C / dt^k`` of B-spline curves at ``t``.

    Convention:
        As :func:`bspline`. Exact (basis derivatives, Piegl & Tiller eq. 2.9); at a
        knot the derivative is the right-hand one (right-continuous spans); ``order >
        degree`` gives zeros.

    Args:
        control_points: ``(*, n + 1, D)``.
        t: ``(T,)`` or ``(*, T)``.
        degree: ``p >= 0``.
        order: ``k >= 0`` (0 is :func:`bspline`).
        knots: as :func:`bspline`.
        periodic: a closed curve.

    Returns:
        ``(*, T, D)`` derivative values (length / parameter^k).

    Example:
        >>> P = torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]])
        >>> bspline_derivative(P, torch.tensor([0.0, 1.0]), 3)  # 3 (P1 - P0), 3 (P3 - P2)
        tensor([[ 3.,  6.],
                [ 3., -6.]])
    """
    order = check_degree(order, "order")
    control_points, t, knots = prepare_bspline(control_points, t, degree, knots, periodic)
    return _evaluate(control_points, t, knots, degree, order)


class BSplineCurve(nn.Module):
    """A (batch of) B-spline curve(s) with learnable control points; ``forward`` is :func:`bspline`.

    Convention:
        As :func:`bspline`. The knots are a non-learnable buffer (``None``: the default
        knots, built at each call in the control points' dtype).

    Args:
        control_points: ``(*, n + 1, D)``.
        degree: ``p >= 0``.
        knots: as :func:`bspline`, or ``None``.
        periodic: a closed curve.
        learnable: store the control points as an ``nn.Parameter`` (else a buffer).

    Example:
        >>> curve = BSplineCurve(torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]]), 2)
        >>> curve(torch.tensor([0.5])).detach()
        tensor([[2., 2.]])
        >>> curve.derivative(torch.tensor([0.0])).detach()
        tensor([[4., 8.]])
    """

    control_points: torch.Tensor
    knots: torch.Tensor | None

    def __init__(self, control_points: torch.Tensor, degree: int,
                 knots: torch.Tensor | None = None, periodic: bool = False,
                 learnable: bool = True) -> None:
        super().__init__()
        prepare_bspline(control_points, control_points.new_zeros(1), degree, knots, periodic)
        self.degree, self.periodic, self.learnable = degree, periodic, learnable
        if learnable:
            self.control_points = nn.Parameter(control_points.detach().clone())
        else:
            self.register_buffer("control_points", control_points, persistent=False)
        self.register_buffer("knots", None if knots is None else knots.detach().clone())

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        """``(T,)`` or ``(*, T)`` parameters -> ``(*, T, D)`` points."""
        check_module_dtype(self, t, "t")
        return bspline(self.control_points, t, self.degree, self.knots, periodic=self.periodic)

    def derivative(self, t: torch.Tensor, order: int = 1) -> torch.Tensor:
        """``(*, T, D)`` ``order``-th derivative; see :func:`bspline_derivative`."""
        return bspline_derivative(self.control_points, t, self.degree, order, self.knots,
                                  periodic=self.periodic)
