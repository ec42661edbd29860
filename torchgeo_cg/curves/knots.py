"""Knot vectors and the B-spline basis (Cox-de Boor), vectorised over every parameter.

A B-spline of degree ``p`` with ``n + 1`` control points has a knot vector of
``n + p + 2`` non-decreasing values ``u_0 <= ... <= u_{n+p+1}``; its domain is
``[u_p, u_{n+1}]``. On the knot span ``[u_s, u_{s+1})`` only the ``p + 1`` basis
functions ``N_{s-p}, ..., N_s`` are non-zero: this module returns those (the *local*
basis) with the span index ``s``, so an evaluation is a gather of ``p + 1`` control
points and a weighted sum.

Convention:
    - Knots are ``(K,)`` (shared by every curve) or ``(*, K)`` (one vector per curve),
      always the full vector, ``K = n + p + 2``.
    - Spans are right-continuous (as scipy's ``BSpline``): a parameter on a knot uses
      the span that starts there; the domain's right end uses the last non-empty span.
      Parameters outside the domain extrapolate the first or last polynomial piece.
    - The recurrence is Piegl & Tiller's algorithm A2.2 (The NURBS Book, 1997, eq. 2.5),
      one degree per step (a loop over degrees, never over parameters). Its
      denominators are lengths of knot intervals that contain the span, so they are
      positive: nothing is guarded and nothing can become NaN for finite input.
    - Derivatives (any order ``k``) follow eq. 2.9:
      ``N^(k)_{i,p} = p (N^(k-1)_{i,p-1} / (u_{i+p} - u_i) - N^(k-1)_{i+1,p-1} /
      (u_{i+p+1} - u_{i+1}))``, with a zero term where the knot interval is empty
      (its basis function is identically zero there). Order ``k > p`` gives zeros.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape
from torchgeo_cg.curves._basis import find_spans, local_basis, local_basis_list
from torchgeo_cg.curves.bernstein import check_degree

# find_spans and local_basis_list are public for the tensor-product surfaces
__all__ = ["BSplineBasis", "bspline_basis", "check_bspline_knots", "uniform_knots", "find_spans",
           "local_basis_list"]


class BSplineBasis(NamedTuple):
    """The local B-spline basis of :func:`bspline_basis`.

    Attributes:
        values: ``(order + 1, *, T, p + 1)``: ``values[k, ..., j]`` is the ``k``-th
            derivative of ``N_{span - p + j, p}`` at each parameter.
        spans: ``(*, T)`` int64 span index ``s`` (``p <= s <= n``).

    Example:
        >>> basis = bspline_basis(torch.tensor([0.5]), 1)
        >>> basis.values, basis.spans
        (tensor([[[0.5000, 0.5000]]]), tensor([1]))
    """

    values: torch.Tensor
    spans: torch.Tensor


def uniform_knots(num_control_points: int, degree: int, *, periodic: bool = False,
                  dtype=None, device=None) -> torch.Tensor:
    """The default knot vector on the domain ``[0, 1]``: clamped uniform, or periodic.

    Convention:
        Clamped: ``p + 1`` zeros, the ``n - p`` uniform interior knots, ``p + 1``
        ones (``n + p + 2`` values). Periodic (``n + 1`` distinct control points):
        the uniform knots ``(j - p) / (n + 1)``, ``j = 0..n + 2p + 1``, of the curve
        whose control points wrap around (see :func:`~torchgeo_cg.curves.bspline`).

    Args:
        num_control_points: ``n + 1 >= p + 1`` (periodic: ``>= 1``).
        degree: ``p >= 0``.
        periodic: the knots of a closed curve.
        dtype, device: of the result (default float32 / CPU, torch's defaults).

    Returns:
        ``(n + p + 2,)`` knots, or ``(n + 2 p + 2,)`` when periodic (``n + 1`` the count).

    Example:
        >>> uniform_knots(5, 2)
        tensor([0.0000, 0.0000, 0.0000, 0.3333, 0.6667, 1.0000, 1.0000, 1.0000])
        >>> uniform_knots(3, 1, periodic=True)
        tensor([-0.3333,  0.0000,  0.3333,  0.6667,  1.0000,  1.3333])
    """
    degree = check_degree(degree)
    count = check_degree(num_control_points, "num_control_points")
    if periodic:
        if count < 1:
            raise ValueError("num_control_points: a periodic curve needs at least 1, got 0")
        j = torch.arange(count + 2 * degree + 1, dtype=torch.float64, device=device)
        return ((j - degree) / count).to(dtype or torch.get_default_dtype())
    if count < degree + 1:
        raise ValueError(f"num_control_points: degree {degree} needs at least degree + 1 = "
                         f"{degree + 1}, got {count}")
    inner = torch.linspace(0, 1, count - degree + 1, dtype=torch.float64, device=device)
    knots = torch.cat([inner.new_zeros(degree), inner, inner.new_ones(degree)])
    return knots.to(dtype or torch.get_default_dtype())


def check_bspline_knots(knots: torch.Tensor, num_control_points: int, degree: int,
                        name: str = "knots") -> dict:
    """Check a full knot vector ``(*, n + p + 2)``: float, non-decreasing, non-empty domain.

    Args:
        knots: ``(*, K)`` with ``K = num_control_points + degree + 1``.
        num_control_points: ``n + 1``.
        degree: ``p``.
        name: argument name for messages.

    Returns:
        The bound sizes (``{"K": K, "*": batch}``).

    Raises:
        ShapeError: wrong number of knots.
        ValueError: a knot smaller than its predecessor (or NaN), naming the first
            one, or an empty domain ``u_p == u_{n+1}``.

    Example:
        >>> check_bspline_knots(torch.tensor([0.0, 0.0, 1.0, 0.5]), 2, 1)
        Traceback (most recent call last):
        ...
        ValueError: knots: must be non-decreasing, but knots[..., 3] = 0.5 is smaller than ...
    """
    check_float(knots, name, low_precision=False)
    count = num_control_points + degree + 1
    sizes = check_shape(knots, ["*", count], name)
    bad = ~(knots[..., 1:] >= knots[..., :-1])  # (*, K - 1); NaN counts as bad
    if bool(bad.any()):
        flat = bad.reshape(-1, bad.shape[-1])
        column = int(flat.any(0).nonzero()[0, 0])
        row = int(flat[:, column].nonzero()[0, 0])
        k = knots.detach().reshape(-1, count)[row]
        raise ValueError(
            f"{name}: must be non-decreasing, but {name}[..., {column + 1}] = "
            f"{float(k[column + 1])} is smaller than {name}[..., {column}] = {float(k[column])}"
        )
    empty = knots[..., num_control_points] == knots[..., degree]
    if bool(empty.any()):
        raise ValueError(f"{name}: the domain [{name}[..., {degree}], {name}[..., "
                         f"{num_control_points}]] is empty (the two knots are equal)")
    return sizes


def _batched(knots: torch.Tensor, t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Knots and parameters with one common batch (shared ``(K,)``/``(T,)`` stay 1-D)."""
    if knots.dim() == 1 and t.dim() == 1:
        return knots, t
    batch = torch.broadcast_shapes(knots.shape[:-1], t.shape[:-1])
    return knots.expand(*batch, knots.shape[-1]), t.expand(*batch, t.shape[-1])


def bspline_basis(t: torch.Tensor, degree: int, knots: torch.Tensor | None = None,
                  order: int = 0, num_control_points: int | None = None) -> BSplineBasis:
    """The ``p + 1`` non-zero B-spline basis functions (and derivatives) at parameters ``t``.

    Convention:
        See the module docstring. ``knots=None`` means clamped uniform knots on
        ``[0, 1]`` for ``num_control_points`` control points (default ``p + 1``: the
        Bernstein basis). Differentiable with respect to ``t`` and ``knots``.

    Args:
        t: ``(T,)`` or ``(*, T)`` parameters.
        degree: ``p >= 0``.
        knots: ``(K,)`` or ``(*, K)`` full knot vectors (validated), or ``None``.
        order: highest derivative order ``>= 0``.
        num_control_points: ``n + 1`` (default ``K - p - 1``).

    Returns:
        :class:`BSplineBasis` ``(values (order + 1, *, T, p + 1), spans (*, T))``.

    Example:
        >>> knots = torch.tensor([0.0, 0.0, 0.0, 1.0, 2.0, 2.0, 2.0])
        >>> basis = bspline_basis(torch.tensor([0.5, 1.5]), 2, knots, order=1)
        >>> basis.spans.tolist()
        [2, 3]
        >>> basis.values[0]
        tensor([[0.2500, 0.6250, 0.1250],
                [0.1250, 0.6250, 0.2500]])
        >>> basis.values[1].sum(-1)  # derivatives of a partition of unity
        tensor([0., 0.])
    """
    check_float(t, "t", low_precision=False)
    check_shape(t, ["*", "T"], "t")
    degree = check_degree(degree)
    order = check_degree(order, "order")
    if knots is None:
        count = degree + 1 if num_control_points is None else num_control_points
        knots = uniform_knots(count, degree, dtype=t.dtype, device=t.device)
    else:
        count = knots.shape[-1] - degree - 1 if num_control_points is None else num_control_points
        if count < degree + 1:
            raise ShapeError(f"knots: degree {degree} needs at least 2 (degree + 1) = "
                             f"{2 * degree + 2} knots, got shape {tuple(knots.shape)}")
        check_bspline_knots(knots, count, degree)
    dtype = torch.promote_types(t.dtype, knots.dtype)
    knots, t = _batched(knots.to(dtype), t.to(dtype))
    spans = find_spans(knots, t, degree)
    return BSplineBasis(local_basis(knots, t, spans, degree, order), spans)


