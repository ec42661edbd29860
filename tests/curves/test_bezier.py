"""Bezier curves against the `bezier` package, scipy BPoly, brute force and hand values."""

from __future__ import annotations

import inspect

import bezier as bezier_pkg
import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from scipy import integrate
from scipy.interpolate import BPoly

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.curves import (
    BezierCurve,
    bezier,
    bezier_arclength_params,
    bezier_curvature,
    bezier_derivative,
    bezier_length,
    bezier_normal,
    bezier_tangent,
    cubic_bezier,
    de_casteljau,
    elevate_bezier,
    quartic_bezier,
    split_bezier,
)

# Report Figure 3 control points (cubic and quartic test cases).
CUBIC = [[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]]
QUARTIC = [[0.0, 0.0], [1.0, 3.0], [2.0, -1.0], [3.0, 3.0], [4.0, 0.0]]


def _pkg_curve(points: torch.Tensor) -> bezier_pkg.Curve:
    nodes = np.asfortranarray(points.detach().cpu().double().numpy().T)
    return bezier_pkg.Curve(nodes, degree=points.shape[0] - 1)


@pytest.mark.parametrize("degree", [1, 2, 3, 5, 9])
def test_bezier_matches_bpoly_and_bezier_package(degree, device, dtype, tol):
    gen = torch.Generator().manual_seed(degree)
    cp = torch.randn(3, degree + 1, 2, generator=gen, dtype=torch.float64)
    t = torch.linspace(0, 1, 17, dtype=torch.float64)
    ours = bezier(cp.to(device, dtype), t.to(device, dtype))
    assert ours.shape == (3, 17, 2) and ours.dtype == dtype and ours.device.type == device.type
    for b in range(3):
        ref_bpoly = BPoly(cp[b].numpy()[:, None, :], [0.0, 1.0])(t.numpy())
        ref_pkg = _pkg_curve(cp[b]).evaluate_multi(t.numpy()).T
        assert_close(ours[b], ref_bpoly, scale=10)
        assert_close(ours[b], ref_pkg, scale=10)


def test_extrapolation_matches_bpoly():
    cp = torch.randn(4, 3, dtype=torch.float64)  # 3D cubic
    t = torch.tensor([-0.5, -0.1, 1.1, 2.0], dtype=torch.float64)
    ref = BPoly(cp.numpy()[:, None, :], [0.0, 1.0], extrapolate=True)(t.numpy())
    assert_close(bezier(cp, t), ref)
    assert_close(de_casteljau(cp, t), ref)


def test_report_figure3_cases_by_hand():
    cubic = torch.tensor(CUBIC)
    quartic = torch.tensor(QUARTIC)
    t = torch.tensor([0.0, 0.5, 1.0])
    assert_close(cubic_bezier(cubic, t), [[0.0, 0.0], [2.0, 1.5], [4.0, 0.0]])
    # Quartic at 1/2: weights (1, 4, 6, 4, 1) / 16 -> y = (12 - 6 + 12) / 16.
    assert_close(quartic_bezier(quartic, t), [[0.0, 0.0], [2.0, 1.125], [4.0, 0.0]])


def test_explicit_forms_equal_general(device, dtype, tol):
    t = torch.rand(2, 11, device=device, dtype=dtype)
    cubic = torch.randn(2, 4, 2, device=device, dtype=dtype)
    quartic = torch.randn(2, 5, 3, device=device, dtype=dtype)
    assert_close(cubic_bezier(cubic, t), bezier(cubic, t), scale=10)
    assert_close(quartic_bezier(quartic, t), bezier(quartic, t), scale=10)
    assert_close(de_casteljau(quartic, t), bezier(quartic, t), scale=10)


def test_per_curve_parameters_broadcast():
    cp = torch.randn(5, 4, 2, dtype=torch.float64)
    t = torch.rand(5, 7, dtype=torch.float64)
    out = bezier(cp, t)
    for b in range(5):
        assert_close(out[b], bezier(cp[b], t[b]))
    assert_close(de_casteljau(cp, t), out)


def test_degree_count_mismatch_raises():
    with pytest.raises(ShapeError, match=r"degree \+ 1 = 4 control points, got 5"):
        cubic_bezier(torch.randn(5, 2), torch.rand(3))
    with pytest.raises(ShapeError, match=r"degree \+ 1 = 5 control points, got 4"):
        quartic_bezier(torch.randn(4, 2), torch.rand(3))
    with pytest.raises(ShapeError, match="at least one control point"):
        bezier(torch.zeros(0, 2), torch.rand(3))
    with pytest.raises(ShapeError, match=r"control_points: expected shape \(\*, K, D\)"):
        bezier(torch.zeros(3), torch.rand(3))
    with pytest.raises(TypeError, match="t: expected a floating-point"):
        bezier(torch.zeros(3, 2), torch.arange(3))
    with pytest.raises(TypeError, match="t0"):
        split_bezier(torch.zeros(3, 2), "half")
    with pytest.raises(ValueError, match="order"):
        bezier_derivative(torch.zeros(3, 2), -1)
    with pytest.raises(ValueError, match="n: expected an int >= 2"):
        bezier_arclength_params(torch.zeros(3, 2), 1)


def test_empty_batches():
    t = torch.rand(6)
    assert bezier(torch.zeros(0, 4, 2), t).shape == (0, 6, 2)
    assert cubic_bezier(torch.zeros(0, 4, 2), t).shape == (0, 6, 2)
    assert bezier(torch.zeros(3, 4, 2), torch.zeros(0)).shape == (3, 0, 2)
    assert bezier_length(torch.zeros(0, 4, 2)).shape == (0,)
    assert split_bezier(torch.zeros(0, 4, 2), 0.3).left.shape == (0, 4, 2)
    assert elevate_bezier(torch.zeros(0, 4, 2)).shape == (0, 5, 2)


def test_derivative_matches_bpoly():
    cp = torch.randn(6, 2, dtype=torch.float64)
    t = torch.rand(9, dtype=torch.float64)
    poly = BPoly(cp.numpy()[:, None, :], [0.0, 1.0])
    for order in (1, 2, 3):
        ours = bezier(bezier_derivative(cp, order), t)
        assert_close(ours, poly.derivative(order)(t.numpy()))
    assert_close(bezier_derivative(cp, 6), torch.zeros(1, 2, dtype=torch.float64))
    assert bezier_derivative(cp, 9).shape == (1, 2)


def test_split_and_elevate_match_bezier_package():
    cp = torch.randn(5, 2, dtype=torch.float64)
    curve = _pkg_curve(cp)
    left, right = split_bezier(cp, 0.3)
    assert_close(left, curve.specialize(0.0, 0.3).nodes.T)
    assert_close(right, curve.specialize(0.3, 1.0).nodes.T)
    half_left, half_right = curve.subdivide()
    assert_close(split_bezier(cp).left, half_left.nodes.T)
    assert_close(split_bezier(cp).right, half_right.nodes.T)
    assert_close(elevate_bezier(cp), curve.elevate().nodes.T)
    assert_close(elevate_bezier(cp, 2), curve.elevate().elevate().nodes.T)


def test_split_per_curve_t0():
    cp = torch.randn(3, 4, 2, dtype=torch.float64)
    t0 = torch.tensor([0.2, 0.5, 0.9], dtype=torch.float64)
    left, right = split_bezier(cp, t0)
    for b in range(3):
        ref = split_bezier(cp[b], float(t0[b]))
        assert_close(left[b], ref.left)
        assert_close(right[b], ref.right)


_coord = st.floats(-10, 10, allow_nan=False, width=64)
_points = st.integers(1, 8).flatmap(
    lambda k: st.lists(st.tuples(_coord, _coord), min_size=k + 1, max_size=k + 1)
)


@given(_points, st.floats(0.01, 0.99), st.floats(0, 1))
def test_property_split_then_evaluate(points, t0, s):
    cp = torch.tensor(points, dtype=torch.float64)
    left, right = split_bezier(cp, t0)
    s_t = torch.tensor([s], dtype=torch.float64)
    assert_close(bezier(left, s_t), bezier(cp, s_t * t0), atol=1e-9)
    assert_close(bezier(right, s_t), bezier(cp, t0 + s_t * (1 - t0)), atol=1e-9)


@given(_points, st.integers(1, 3))
def test_property_elevation_preserves_points(points, times):
    cp = torch.tensor(points, dtype=torch.float64)
    t = torch.linspace(0, 1, 13, dtype=torch.float64)
    assert_close(bezier(elevate_bezier(cp, times), t), bezier(cp, t), atol=1e-9)


@given(_points)
def test_property_endpoint_interpolation(points):
    cp = torch.tensor(points, dtype=torch.float64)
    ends = bezier(cp, torch.tensor([0.0, 1.0], dtype=torch.float64))
    assert_close(ends, cp[[0, -1]], atol=1e-12)


@given(_points, st.floats(0, 1), st.floats(0, 2 * np.pi))
def test_property_convex_hull(points, t, angle):
    cp = torch.tensor(points, dtype=torch.float64)
    u = torch.tensor([np.cos(angle), np.sin(angle)], dtype=torch.float64)
    value = bezier(cp, torch.tensor([t], dtype=torch.float64))[0] @ u
    support = (cp @ u).max()
    assert float(value) <= float(support) + 1e-9


def test_tangent_normal_curvature_by_hand_and_finite_differences():
    cp = torch.tensor(CUBIC, dtype=torch.float64)
    t = torch.tensor([0.5], dtype=torch.float64)
    assert_close(bezier_tangent(cp, t), [[1.0, 0.0]])
    assert_close(bezier_normal(cp, t), [[0.0, 1.0]])
    # B'(1/2) = (4.5, 0), B''(1/2) = (0, -12): kappa = 4.5 * -12 / 4.5^3.
    assert_close(bezier_curvature(cp, t), [-12 / 4.5**2])
    # Curvature against the osculating circle through finite differences.
    ts = torch.rand(6, dtype=torch.float64) * 0.8 + 0.1
    h = 1e-4
    p0, p1, p2 = (bezier(cp, ts + d) for d in (-h, 0.0, h))
    v, a = (p2 - p0) / (2 * h), (p2 - 2 * p1 + p0) / h**2
    kappa = (v[:, 0] * a[:, 1] - v[:, 1] * a[:, 0]) / v.norm(dim=-1) ** 3
    assert_close(bezier_curvature(cp, ts), kappa, rtol=1e-5, atol=1e-6)


def test_3d_curvature_and_normal_on_a_helix_like_curve():
    cp = torch.randn(5, 3, dtype=torch.float64)
    t = torch.rand(7, dtype=torch.float64)
    v = bezier(bezier_derivative(cp), t)
    a = bezier(bezier_derivative(cp, 2), t)
    kappa = torch.linalg.cross(v, a).norm(dim=-1) / v.norm(dim=-1) ** 3
    assert_close(bezier_curvature(cp, t), kappa)
    normal = bezier_normal(cp, t)
    assert_close((normal * v).sum(-1), torch.zeros(7, dtype=torch.float64), atol=1e-9)
    assert_close(normal.norm(dim=-1), torch.ones(7, dtype=torch.float64))


def _quad_length(cp: torch.Tensor) -> float:
    hodo = bezier_derivative(cp).numpy()
    poly = BPoly(hodo[:, None, :], [0.0, 1.0])

    def speed(s):
        return float(np.linalg.norm(poly(s)))

    return integrate.quad(speed, 0, 1, epsabs=1e-14, epsrel=1e-13, limit=500)[0]


def _near_cusp_cubics(count: int, gen: torch.Generator) -> torch.Tensor:
    """Symmetric cubics (0,0),(1+e,h),(-e,h),(1,0): exact cusp at e = 0, near-cusp for small e."""
    e = (torch.rand(count, generator=gen, dtype=torch.float64) - 0.5) * 2e-3
    h = 0.5 + torch.rand(count, generator=gen, dtype=torch.float64)
    zero, one = torch.zeros_like(e), torch.ones_like(e)
    return torch.stack([torch.stack([zero, zero], -1), torch.stack([1 + e, h], -1),
                        torch.stack([-e, h], -1), torch.stack([one, zero], -1)], dim=-2)


def test_length_matches_quad_and_bezier_package_including_cusps():
    gen = torch.Generator().manual_seed(0)
    cp = torch.cat([torch.randn(6, 4, 2, generator=gen, dtype=torch.float64),
                    _near_cusp_cubics(6, gen),
                    torch.tensor([[[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0]]],
                                 dtype=torch.float64)])
    ref = torch.tensor([_quad_length(c) for c in cp], dtype=torch.float64)
    assert ((bezier_length(cp) - ref).abs() / ref).max() < 1e-7  # default rtol
    ours = bezier_length(cp, rtol=1e-11)
    assert ((ours - ref).abs() / ref).max() < 1e-9
    pkg = torch.tensor([_pkg_curve(c).length for c in cp[:6]], dtype=torch.float64)
    assert ((ours[:6] - pkg).abs() / pkg).max() < 1e-9


def test_length_float32_within_1e6(device):
    gen = torch.Generator().manual_seed(1)
    cp = torch.cat([torch.randn(5, 4, 2, generator=gen, dtype=torch.float64),
                    _near_cusp_cubics(5, gen)])
    ref = bezier_length(cp)
    ours = bezier_length(cp.to(device, torch.float32)).cpu().double()
    assert ((ours - ref).abs() / ref).max() < 1e-6


def test_length_of_straight_line_and_batch_shape():
    line = torch.tensor([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]], dtype=torch.float64)
    assert_close(bezier_length(line), torch.tensor(18.0, dtype=torch.float64).sqrt())
    assert bezier_length(line.expand(2, 3, 4, 2)).shape == (2, 3)


def test_gradcheck_evaluation_split_elevate_length():
    cp = torch.randn(2, 4, 2, dtype=torch.float64, requires_grad=True)
    t = torch.rand(5, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(bezier, (cp, t))
    assert torch.autograd.gradcheck(cubic_bezier, (cp, t))
    assert torch.autograd.gradcheck(de_casteljau, (cp, t))
    assert torch.autograd.gradcheck(lambda p: split_bezier(p, 0.3), (cp,))
    assert torch.autograd.gradcheck(elevate_bezier, (cp,))
    assert torch.autograd.gradcheck(lambda p: bezier_curvature(p, t.detach()), (cp,))
    assert torch.autograd.gradcheck(bezier_length, (cp,), atol=1e-6)


def test_gradient_of_length_matches_finite_difference_of_quad():
    cp = torch.tensor(CUBIC, dtype=torch.float64, requires_grad=True)
    bezier_length(cp).backward()
    h = 1e-6
    bumped = cp.detach().clone()
    bumped[1, 0] += h
    fd = (_quad_length(bumped) - _quad_length(cp.detach())) / h
    assert abs(float(cp.grad[1, 0]) - fd) < 1e-5


def test_coincident_points_and_cusps_give_finite_gradients():
    point = torch.tensor([[1.0, 2.0]] * 4, dtype=torch.float64, requires_grad=True)
    cusp = torch.tensor([[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0]],
                        dtype=torch.float64, requires_grad=True)
    t = torch.tensor([0.0, 0.5, 1.0], dtype=torch.float64)
    for cp in (point, cusp):
        total = (bezier_tangent(cp, t).sum() + bezier_normal(cp, t).sum()
                 + bezier_curvature(cp, t).sum() + bezier_length(cp))
        total.backward()
        assert torch.isfinite(total)
        assert cp.grad.isfinite().all()
    assert_close(bezier_length(point.detach()), torch.tensor(0.0, dtype=torch.float64))


def test_arclength_parameters_give_equal_pieces():
    gen = torch.Generator().manual_seed(3)
    cp = torch.cat([torch.randn(3, 4, 2, generator=gen, dtype=torch.float64),
                    _near_cusp_cubics(2, gen)])
    n = 9
    t = bezier_arclength_params(cp, n)
    assert t.shape == (5, n)
    for b in range(5):
        hodo = BPoly(bezier_derivative(cp[b]).numpy()[:, None, :], [0.0, 1.0])
        pieces = [integrate.quad(lambda s, h=hodo: float(np.linalg.norm(h(s))), float(t[b, k]),
                                 float(t[b, k + 1]), epsabs=1e-13, limit=200)[0]
                  for k in range(n - 1)]
        pieces = np.array(pieces)
        # Smooth curves: Newton-polished to rounding; near-cusp ones: the kink in |B'|
        # limits the tabulated Gauss-Legendre inversion to about 1e-7.
        assert np.abs(pieces / pieces.mean() - 1).max() < (1e-10 if b < 3 else 1e-6)


def test_module_equals_functions_and_defaults_match(device, dtype):
    cp = torch.randn(3, 4, 2, device=device, dtype=dtype)
    t = torch.rand(6, device=device, dtype=dtype)
    curve = BezierCurve(cp)
    assert curve.degree == 3
    assert isinstance(curve.control_points, torch.nn.Parameter)
    assert_close(curve(t), bezier(cp, t))
    assert_close(curve.tangent(t), bezier_tangent(cp, t))
    assert_close(curve.normal(t), bezier_normal(cp, t))
    assert_close(curve.curvature(t), bezier_curvature(cp, t))
    assert_close(curve.length(), bezier_length(cp))
    assert_close(curve.derivative(2).control_points, bezier_derivative(cp, 2))
    left, right = curve.split(0.25)
    ref = split_bezier(cp, 0.25)
    assert_close(left.control_points, ref.left)
    assert_close(right.control_points, ref.right)
    assert_close(curve.elevate().control_points, elevate_bezier(cp))
    points = curve.reparametrize_by_arclength(5)
    assert_close(points, bezier(cp, bezier_arclength_params(cp, 5)))
    pairs = [(BezierCurve.split, split_bezier, "t0"),
             (BezierCurve.elevate, elevate_bezier, "times"),
             (BezierCurve.derivative, bezier_derivative, "order"),
             (BezierCurve.length, bezier_length, "rtol")]
    for method, function, name in pairs:
        assert (inspect.signature(method).parameters[name].default
                == inspect.signature(function).parameters[name].default)


def test_module_learns_and_moves():
    curve = BezierCurve(torch.zeros(4, 2), learnable=True)
    target = torch.tensor(CUBIC)
    optim = torch.optim.Adam(curve.parameters(), lr=0.1)
    t = torch.linspace(0, 1, 20)
    for _ in range(200):
        optim.zero_grad()
        loss = (curve(t) - bezier(target, t)).pow(2).mean()
        loss.backward()
        optim.step()
    assert float(loss.detach()) < 1e-3
    frozen = BezierCurve(target, learnable=False)
    assert list(frozen.parameters()) == []
    assert frozen.to(torch.float64).control_points.dtype == torch.float64
    assert curve.to(torch.float64).control_points.dtype == torch.float64
    # Curves derived from a learnable one keep the graph back to its parameters.
    curve.split(0.5)[0].length().backward()
    assert curve.control_points.grad is not None


def test_gauss_kronrod_rule_is_generated_correctly():
    import sys

    nodes, kronrod, gauss = sys.modules["torchgeo_cg.curves.bezier"]._gauss_kronrod(7)
    # QUADPACK's GK15 abscissae and weights (on [-1, 1]), first entries.
    assert abs(2 * nodes[-1] - 1 - 0.991455371120813) < 1e-14
    assert abs(2 * kronrod[0] - 0.022935322010529) < 1e-14
    assert abs(2 * gauss[7] - 0.417959183673469) < 1e-14  # 7-point Gauss centre weight
    for k in range(24):  # exact to degree 23 (Kronrod) and 13 (Gauss) on [0, 1]
        assert abs((kronrod * nodes**k).sum() - 1 / (k + 1)) < 1e-14
        if k < 14:
            assert abs((gauss * nodes**k).sum() - 1 / (k + 1)) < 1e-14


def test_more_bad_input():
    with pytest.raises(TypeError, match="control_points: expected a floating-point"):
        bezier(torch.zeros(4, 2, dtype=torch.long), torch.rand(3))
    with pytest.raises(ValueError, match="times"):
        elevate_bezier(torch.zeros(4, 2), -2)
    with pytest.raises(TypeError, match="order"):
        bezier_derivative(torch.zeros(4, 2), 1.5)


def test_per_curve_t_must_broadcast_with_the_curves():
    cp = torch.randn(2, 4, 2)
    assert bezier(cp, torch.rand(2, 5)).shape == (2, 5, 2)  # one row of t per curve
    assert bezier(cp[0], torch.rand(3, 5)).shape == (3, 5, 2)  # one curve, 3 rows of t
    clash = r"batch dims do not broadcast: control_points \(2\), t \(3\)"
    with pytest.raises(ShapeError, match=clash):
        bezier(cp, torch.rand(3, 5))
    with pytest.raises(ShapeError, match="control_points"):
        cubic_bezier(cp, torch.rand(3, 5))


def test_bezier_curve_methods():
    for method in ("forward", "derivative", "tangent", "normal", "curvature", "split",
                   "elevate", "length", "reparametrize_by_arclength"):
        assert callable(getattr(BezierCurve, method))
