"""Validation and local evaluation shared by the B-spline and NURBS curves: the normalised
(points, t, knots) of a curve and the sum of its p + 1 local control points;
internals of :mod:`torchgeo_cg.curves.bspline`."""

from __future__ import annotations

import torch

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import ShapeError, check_broadcastable, check_float, check_shape
from torchgeo_cg.curves.bernstein import check_degree
from torchgeo_cg.curves.knots import check_bspline_knots, uniform_knots

__all__ = ["evaluate_local", "prepare_bspline"]


def _check_control_points(control_points: torch.Tensor, degree: int, periodic: bool) -> int:
    check_float(control_points, "control_points", low_precision=False)
    sizes = check_shape(control_points, ["*", "K", "D"], "control_points")
    least = 1 if periodic else degree + 1
    if sizes["K"] < least:
        raise ShapeError(f"control_points: a degree {degree} B-spline needs at least {least} "
                         f"control points, got shape {tuple(control_points.shape)}")
    return sizes["K"]


def _periodic_knots(knots: torch.Tensor, count: int, degree: int) -> torch.Tensor:
    """Full ``(*, n + 2p + 2)`` knots extending one period of ``n + 2`` breakpoints."""
    check_float(knots, "knots", low_precision=False)
    check_shape(knots, ["*", count + 1], "knots")
    check_bspline_knots(knots, count, 0)  # non-decreasing, tau_{n+1} > tau_0
    period = knots[..., -1:] - knots[..., :1]
    g = torch.arange(-degree, count + degree + 1, device=knots.device)  # full index - p
    wraps = torch.div(g, count, rounding_mode="floor")
    return knots[..., g - wraps * count] + wraps.to(knots.dtype) * period


def prepare_bspline(control_points, t, degree, knots=None, periodic=False):
    """Validate and normalise a B-spline: ``(points, t, knots)`` ready for evaluation.

    Periodic curves come back as their wrapped open form with ``t`` reduced into the
    domain. dtypes are promoted together; ``t`` and ``knots`` keep their own batch.

    Example:
        >>> cp, t, knots = prepare_bspline(torch.zeros(3, 2), torch.tensor([1.25]), 1,
        ...                                periodic=True)
        >>> cp.shape, t, knots.shape
        (torch.Size([4, 2]), tensor([0.2500]), torch.Size([6]))
    """
    degree = check_degree(degree)
    count = _check_control_points(control_points, degree, periodic)
    check_float(t, "t", low_precision=False)
    check_shape(t, ["*", "T"], "t")
    dtype = torch.promote_types(control_points.dtype, t.dtype)
    if knots is not None:
        check_float(knots, "knots", low_precision=False)
        dtype = torch.promote_types(dtype, knots.dtype)
    batches = {"control_points": control_points.shape[:-2]}
    if t.dim() > 1:
        batches["t"] = t.shape[:-1]
    if knots is not None and knots.dim() > 1:
        batches["knots"] = knots.shape[:-1]
    check_broadcastable(batches)
    control_points, t = control_points.to(dtype), t.to(dtype)
    if periodic:
        if knots is None:
            knots = uniform_knots(count, degree, periodic=True, dtype=dtype,
                                  device=control_points.device)
        else:
            knots = _periodic_knots(knots.to(dtype), count, degree)
        wrap = torch.arange(count + degree, device=control_points.device) % count
        control_points = control_points[..., wrap, :]
        start, end = knots[..., degree:degree + 1], knots[..., count + degree:count + degree + 1]
        t = start + torch.remainder(t - start, end - start)
    elif knots is None:
        knots = uniform_knots(count, degree, dtype=dtype, device=control_points.device)
    else:
        check_bspline_knots(knots, count, degree)
        knots = knots.to(dtype)
    return control_points, t, knots


def evaluate_local(control_points, basis, spans, degree: int) -> torch.Tensor:
    """``sum_j basis[..., j] P_{span - p + j}``: ``(*, T, p + 1)`` basis -> ``(*, T, D)``.

    ``basis`` may also be a list of the ``p + 1`` tensors ``(*, T)``. With one shared basis
    ``(T, p + 1)`` the basis is scattered into a dense ``(T, n + 1)`` matrix and applied by
    one GEMM to every curve at once (the result is a view of that product); otherwise the
    ``p + 1`` control points of every parameter are gathered, one coordinate at a time.

    Example:
        >>> cp = torch.tensor([[0.0], [1.0], [4.0]])
        >>> evaluate_local(cp, torch.tensor([[0.5, 0.5]]), torch.tensor([1]), 1)  # P0 / 2 + P1 / 2
        tensor([[0.5000]])
    """
    k, d = control_points.shape[-2:]
    if spans.dim() == 1:
        basis = torch.stack(basis, -1) if isinstance(basis, list) else basis
        columns = spans[:, None] - degree + torch.arange(degree + 1, device=spans.device)
        dense = basis.new_zeros(basis.shape[0], k).scatter_add(1, columns, basis)  # (T, K)
        if control_points.dim() == 2:
            return dense @ control_points
        batch = control_points.shape[:-2]
        flat = control_points.reshape(-1, k, d).permute(1, 0, 2).reshape(k, -1)  # (K, B D)
        out = (dense @ flat).reshape(basis.shape[0], *batch, d)  # (T, *, D)
        return out.movedim(0, -2)  # a view: (*, T, D)
    if not isinstance(basis, list):
        basis = list(basis.unbind(-1))
    batch = torch.broadcast_shapes(control_points.shape[:-2], spans.shape[:-1])
    cp = control_points.expand(*batch, k, d).reshape(-1, k, d)  # (B, K, D)
    spans = spans.expand(*batch, spans.shape[-1]).reshape(cp.shape[0], -1)  # (B, T)
    inplace = not records_graph(cp, *basis)
    out = None
    first = spans - degree
    for j in range(degree + 1):  # loop over the p + 1 local control points
        index = (first + j if j else first)[..., None].expand(-1, -1, d)
        weight = basis[j].expand(*batch, spans.shape[-1]).reshape(spans.shape)[..., None]
        points = cp.gather(1, index)  # (B, T, D)
        if out is None:
            out = points.mul_(weight) if inplace else points * weight
        else:
            out = out.addcmul_(points, weight) if inplace else out + points * weight
    return out.reshape(*batch, -1, d)
