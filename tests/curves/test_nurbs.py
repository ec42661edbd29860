"""NURBS curves: the rational quadratic circle (exactly on the circle), geomdl values and
derivatives, finite differences for higher orders, gradcheck."""

from __future__ import annotations

import math

import pytest
import torch

from torchgeo_cg.curves import NURBSCurve, bspline, nurbs, nurbs_derivative

F64 = torch.float64


def _circle(radius=1.0):
    """The 9-point rational quadratic circle (Piegl & Tiller ex. 7.2)."""
    corners = torch.tensor([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1],
                            [1, -1], [1, 0]], dtype=F64) * radius
    w = torch.tensor([1, math.sqrt(0.5)] * 4 + [1], dtype=F64)
    knots = torch.tensor([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1], dtype=F64)
    return corners, w, knots


@pytest.mark.parametrize("radius", [1e-6, 1.0, 1e6])
def test_rational_quadratic_circle_is_exactly_a_circle(radius):
    cp, w, knots = _circle(radius)
    t = torch.linspace(0, 1, 1001, dtype=F64)
    points = nurbs(cp, w, t, 2, knots)
    assert (points.norm(dim=-1) / radius - 1).abs().max() < 4e-16
    # the derivative is tangent: perpendicular to the radius
    d = nurbs_derivative(cp, w, t, 2, 1, knots)
    assert ((points * d).sum(-1).abs() / (radius * d.norm(dim=-1))).max() < 1e-14


def test_unit_weights_give_the_bspline():
    cp = torch.randn(2, 7, 3, dtype=F64)
    t = torch.rand(11, dtype=F64)
    assert torch.allclose(nurbs(cp, torch.ones(7, dtype=F64), t, 3), bspline(cp, t, 3),
                          atol=1e-14)
    assert torch.allclose(nurbs(cp, 3.5 * torch.ones(2, 7, dtype=F64), t, 3),
                          bspline(cp, t, 3), atol=1e-14)


def test_matches_geomdl_values_and_derivatives():
    geomdl_nurbs = pytest.importorskip("geomdl.NURBS")
    g = torch.Generator().manual_seed(0)
    degree, count = 3, 8
    cp = torch.randn(count, 3, generator=g, dtype=F64)
    w = 0.3 + torch.rand(count, generator=g, dtype=F64)
    inner = torch.sort(torch.rand(count - degree - 1, generator=g, dtype=F64)).values
    knots = torch.cat([torch.zeros(degree + 1, dtype=F64), inner, torch.ones(degree + 1,
                                                                             dtype=F64)])
    curve = geomdl_nurbs.Curve()
    curve.degree = degree
    curve.ctrlptsw = [[*(cp[i] * w[i]).tolist(), float(w[i])] for i in range(count)]
    curve.knotvector = knots.tolist()
    t = torch.rand(25, generator=g, dtype=F64)
    ref = torch.tensor([curve.derivatives(float(x), order=2) for x in t], dtype=F64)
    for order in range(3):
        ours = nurbs_derivative(cp, w, t, degree, order, knots)
        assert torch.allclose(ours, ref[:, order], rtol=0, atol=1e-12 * ref[:, order].abs().max())


@pytest.mark.parametrize("order", [3, 4])
def test_higher_derivatives_against_finite_differences(order):
    cp, w, knots = _circle()
    t = torch.tensor([0.1, 0.3, 0.6, 0.9], dtype=F64)  # inside the spans (smooth)
    h = 1e-3
    lower = lambda x: nurbs_derivative(cp, w, x, 2, order - 1, knots)  # noqa: E731
    fd = (lower(t + h) - lower(t - h)) / (2 * h)
    ours = nurbs_derivative(cp, w, t, 2, order, knots)
    assert torch.allclose(ours, fd, rtol=1e-4, atol=1e-4 * float(fd.abs().max()))


def test_validation():
    cp, w, knots = _circle()
    with pytest.raises(ValueError, match="weights"):
        nurbs(cp, -w, torch.rand(3, dtype=F64), 2, knots)
    with pytest.raises(ValueError, match="weights"):
        nurbs(cp, w[:-1], torch.rand(3, dtype=F64), 2, knots)


def test_module_learns_points_and_weights():
    cp, w, knots = _circle()
    curve = NURBSCurve(cp, w, 2, knots)
    t = torch.rand(7, dtype=F64)
    assert torch.equal(curve(t), nurbs(cp, w, t, 2, knots))
    curve(t)[..., 0].sum().backward()
    assert curve.weights.grad.abs().sum() > 0 and curve.control_points.grad.abs().sum() > 0


@pytest.mark.grad
def test_gradcheck():
    cp, w, knots = _circle()
    cp = cp.clone().requires_grad_()
    w = w.clone().requires_grad_()
    t = torch.tensor([0.1, 0.4, 0.8], dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda c, ww, x: nurbs_derivative(c, ww, x, 2, 2, knots),
                                    (cp, w, t))
