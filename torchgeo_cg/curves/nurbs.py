"""NURBS curves: rational B-splines with exact derivatives of any order.

``C(t) = sum_i N_{i,p}(t) w_i P_i / sum_i N_{i,p}(t) w_i`` (Piegl & Tiller ch. 4).

Convention:
    - Control points ``(*, n + 1, D)``, weights ``(*, n + 1)`` (broadcast against the
      points' batch), ``t``, ``degree``, ``knots`` and ``periodic`` exactly as
      :func:`~torchgeo_cg.curves.bspline`. Weights must be positive (``ValueError``
      otherwise), so the denominator ``w(t)`` is positive on the domain; outside it
      (extrapolation) a point where ``w(t) = 0`` exactly is at infinity and gives 0.
    - The curve is the projection of the B-spline ``A(t) = sum N w P``, ``w(t) = sum N w``
      in homogeneous coordinates; its derivatives are exact (eq. 4.8):
      ``C^(k) = (A^(k) - sum_{i=1..k} C(k, i) w^(i) C^(k-i)) / w``.
    - Scaling the points by ``s`` scales the curve by ``s``; scaling the weights by any
      positive factor leaves it unchanged. Differentiable in points, weights, ``t``
      and knots.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from torchgeo_cg.core.check import check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.core.numerics import safe_div
from torchgeo_cg.curves._basis import find_spans, local_basis
from torchgeo_cg.curves._bspline_core import evaluate_local, prepare_bspline
from torchgeo_cg.curves.bernstein import check_degree

__all__ = ["NURBSCurve", "nurbs", "nurbs_derivative", "check_weights"]


def check_weights(weights: torch.Tensor, control_points: torch.Tensor,
                  name: str = "weights") -> torch.Tensor:
    """Check positive float weights ``(*, n + 1)``; return them in the points' dtype.

    Example:
        >>> check_weights(torch.tensor([1.0, -1.0]), torch.zeros(2, 3))
        Traceback (most recent call last):
        ...
        ValueError: weights: expected positive weights, got a value <= 0 at index 1
    """
    check_float(weights, name, low_precision=False)
    check_shape(weights, ["*", control_points.shape[-2]], name)
    check_broadcastable({"control_points": control_points.shape[:-2],
                         name: weights.shape[:-1]})
    bad = weights <= 0
    if bool(bad.any()):
        index = int(bad.reshape(-1, bad.shape[-1]).any(0).nonzero()[0, 0])
        raise ValueError(f"{name}: expected positive weights, got a value <= 0 at index {index}")
    return weights


def _rational_derivatives(homogeneous: list[torch.Tensor]) -> list[torch.Tensor]:
    """Derivatives ``C, C', ..., C^(k)`` from homogeneous ones ``[A|w]^(0..k)`` (eq. 4.8).

    Args:
        homogeneous: ``k + 1`` tensors ``(*, D + 1)``, the last coordinate the weight.

    Returns:
        ``k + 1`` tensors ``(*, D)``.

    Example:
        >>> _rational_derivatives([torch.tensor([2.0, 2.0]), torch.tensor([1.0, 0.0])])
        [tensor([1.]), tensor([0.5000])]
    """
    w0 = homogeneous[0][..., -1:]
    out = []
    for k, h in enumerate(homogeneous):  # loop over derivative orders
        value = h[..., :-1]
        for i in range(1, k + 1):
            value = value - math.comb(k, i) * homogeneous[i][..., -1:] * out[k - i]
        out.append(safe_div(value, w0))
    return out


def _homogeneous(control_points, weights, t, degree, knots, periodic, order):
    check_float(control_points, "control_points", low_precision=False)
    check_shape(control_points, ["*", "K", "D"], "control_points")
    check_weights(weights, control_points)
    dtype = torch.promote_types(control_points.dtype, weights.dtype)
    weights = weights.to(dtype)
    batch = torch.broadcast_shapes(control_points.shape[:-2], weights.shape[:-1])
    cp = control_points.to(dtype).expand(*batch, *control_points.shape[-2:])
    lifted = torch.cat([cp * weights.expand(*batch, -1)[..., None],
                        weights.expand(*batch, -1)[..., None]], -1)  # (*, n + 1, D + 1)
    lifted, t, knots = prepare_bspline(lifted, t, degree, knots, periodic)
    if t.numel() == 0 or lifted.numel() == 0:
        shape = torch.broadcast_shapes(lifted.shape[:-2], t.shape[:-1], knots.shape[:-1])
        return [lifted.new_zeros(*shape, t.shape[-1], lifted.shape[-1])] * (order + 1)
    if knots.dim() > 1 or t.dim() > 1:
        shape = torch.broadcast_shapes(knots.shape[:-1], t.shape[:-1])
        knots, t = knots.expand(*shape, knots.shape[-1]), t.expand(*shape, t.shape[-1])
    spans = find_spans(knots, t, degree)
    basis = local_basis(knots, t, spans, degree, order)
    return [evaluate_local(lifted, basis[k], spans, degree) for k in range(order + 1)]


def nurbs(control_points: torch.Tensor, weights: torch.Tensor, t: torch.Tensor, degree: int,
          knots: torch.Tensor | None = None, *, periodic: bool = False) -> torch.Tensor:
    """Evaluate NURBS curves at parameters ``t``.

    Convention:
        See the module docstring; knots, ``t`` and periodic curves as
        :func:`~torchgeo_cg.curves.bspline`.

    Args:
        control_points: ``(*, n + 1, D)``.
        weights: ``(*, n + 1)`` positive.
        t: ``(T,)`` or ``(*, T)``.
        degree: ``p >= 0``.
        knots: ``(n + p + 2,)``, ``(*, n + p + 2)`` or ``None`` (clamped uniform).
        periodic: a closed curve.

    Returns:
        ``(*, T, D)`` points.

    Example:
        >>> quarter = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # a quarter circle
        >>> w = torch.tensor([1.0, 0.5 ** 0.5, 1.0])
        >>> p = nurbs(quarter, w, torch.linspace(0, 1, 5), 2)
        >>> p.norm(dim=-1)
        tensor([1.0000, 1.0000, 1.0000, 1.0000, 1.0000])
    """
    homogeneous = _homogeneous(control_points, weights, t, degree, knots, periodic, 0)
    return _rational_derivatives(homogeneous)[0]


def nurbs_derivative(control_points: torch.Tensor, weights: torch.Tensor, t: torch.Tensor,
                     degree: int, order: int = 1, knots: torch.Tensor | None = None, *,
                     periodic: bool = False) -> torch.Tensor:
    """The exact ``order``-th derivative of NURBS curves at ``t`` (quotient rule, eq. 4.8).

    Convention:
        As :func:`nurbs`; right-hand derivatives at knots.

    Args:
        control_points: ``(*, n + 1, D)``.
        weights: ``(*, n + 1)`` positive.
        t: ``(T,)`` or ``(*, T)``.
        degree: ``p >= 0``.
        order: ``k >= 0``.
        knots: as :func:`nurbs`.
        periodic: a closed curve.

    Returns:
        ``(*, T, D)``.

    Example:
        >>> quarter = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        >>> w = torch.tensor([1.0, 0.5 ** 0.5, 1.0])
        >>> d = nurbs_derivative(quarter, w, torch.tensor([0.0, 1.0]), 2)
        >>> d / d.norm(dim=-1, keepdim=True)  # tangent to the circle
        tensor([[ 0.,  1.],
                [-1.,  0.]])
    """
    order = check_degree(order, "order")
    homogeneous = _homogeneous(control_points, weights, t, degree, knots, periodic, order)
    return _rational_derivatives(homogeneous)[order]


class NURBSCurve(nn.Module):
    """NURBS curve(s) with learnable control points and weights; ``forward`` is :func:`nurbs`.

    Convention:
        As :func:`nurbs`. The knots are a buffer; the weights are a parameter that
        the optimiser may move: keep them positive (e.g. by a small learning rate),
        :func:`nurbs` rejects non-positive weights.

    Args:
        control_points: ``(*, n + 1, D)``.
        weights: ``(*, n + 1)`` positive.
        degree: ``p >= 0``.
        knots: as :func:`nurbs`, or ``None``.
        periodic: a closed curve.
        learnable: store points and weights as ``nn.Parameter`` (else buffers).

    Example:
        >>> quarter = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        >>> curve = NURBSCurve(quarter, torch.tensor([1.0, 0.5 ** 0.5, 1.0]), 2)
        >>> curve(torch.tensor([0.5])).detach()
        tensor([[0.7071, 0.7071]])
    """

    control_points: torch.Tensor
    weights: torch.Tensor
    knots: torch.Tensor | None

    def __init__(self, control_points: torch.Tensor, weights: torch.Tensor, degree: int,
                 knots: torch.Tensor | None = None, periodic: bool = False,
                 learnable: bool = True) -> None:
        super().__init__()
        nurbs(control_points, weights, control_points.new_zeros(1), degree, knots,
              periodic=periodic)
        self.degree, self.periodic, self.learnable = degree, periodic, learnable
        if learnable:
            self.control_points = nn.Parameter(control_points.detach().clone())
            self.weights = nn.Parameter(weights.detach().clone().to(control_points.dtype))
        else:
            self.register_buffer("control_points", control_points, persistent=False)
            self.register_buffer("weights", weights.to(control_points.dtype), persistent=False)
        self.register_buffer("knots", None if knots is None else knots.detach().clone())

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        """``(T,)`` or ``(*, T)`` parameters -> ``(*, T, D)`` points."""
        check_module_dtype(self, t, "t")
        return nurbs(self.control_points, self.weights, t, self.degree, self.knots,
                     periodic=self.periodic)

    def derivative(self, t: torch.Tensor, order: int = 1) -> torch.Tensor:
        """``(*, T, D)`` ``order``-th derivative; see :func:`nurbs_derivative`."""
        return nurbs_derivative(self.control_points, self.weights, t, self.degree, order,
                                self.knots, periodic=self.periodic)
