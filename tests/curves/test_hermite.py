"""Hermite curves, splines, PCHIP and cardinal tangents against scipy and hand values."""

from __future__ import annotations

import inspect

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from scipy.interpolate import CubicHermiteSpline
from scipy.interpolate import PchipInterpolator as ScipyPchip

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.curves import (
    HermiteCurve,
    HermiteSpline,
    PchipInterpolator,
    bezier,
    bezier_to_hermite,
    cardinal_tangents,
    catmull_rom_tangents,
    hermite,
    hermite_basis,
    hermite_spline,
    hermite_to_bezier,
    pchip_interpolate,
    pchip_tangents,
)
from torchgeo_cg.curves._knot_checks import check_knots


def test_basis_matches_appendix_a(device, dtype):
    t = torch.linspace(-0.5, 1.5, 21, device=device, dtype=dtype)
    expected = torch.stack([(1 + 2 * t) * (1 - t) ** 2, t * (1 - t) ** 2, t**2 * (3 - 2 * t),
                            t**2 * (t - 1)], dim=-1)
    assert_close(hermite_basis(t), expected)
    # Partition of unity for the point weights, and the endpoint conditions.
    assert_close(hermite_basis(t)[..., [0, 2]].sum(-1), torch.ones_like(t))


# Report Figure 4: endpoints 0 and 1 with four tangent variants.
FIGURE4 = {
    "original": ([1.0, 1.0], [1.0, -1.0]),
    "exaggerated": ([5.0, 5.0], [5.0, -5.0]),
    "vertical": ([0.0, 3.0], [0.0, -3.0]),
    "parallel": ([2.0, 0.0], [2.0, 0.0]),
}


@pytest.mark.parametrize("variant", list(FIGURE4))
def test_hermite_report_figure4_cases(variant):
    m0, m1 = (torch.tensor(v, dtype=torch.float64) for v in FIGURE4[variant])
    p0 = torch.tensor([0.0, 0.0], dtype=torch.float64)
    p1 = torch.tensor([1.0, 0.0], dtype=torch.float64)
    t = torch.linspace(0, 1, 11, dtype=torch.float64)
    out = hermite(p0, p1, m0, m1, t)
    assert_close(out[0], p0)
    assert_close(out[-1], p1)
    # Derivative at the ends equals the tangents (central differences on the cubic).
    h = 1e-6
    ends = torch.tensor([0.0, 1.0], dtype=torch.float64)
    deriv = (hermite(p0, p1, m0, m1, ends + h) - hermite(p0, p1, m0, m1, ends - h)) / (2 * h)
    assert_close(deriv, torch.stack([m0, m1]), rtol=1e-8, atol=1e-8)
    # scipy's CubicHermiteSpline on one segment [0, 1] is the same curve.
    ref = CubicHermiteSpline([0.0, 1.0], torch.stack([p0, p1]).numpy(),
                             torch.stack([m0, m1]).numpy())(t.numpy())
    assert_close(out, ref)


def test_hermite_bezier_round_trip(device, dtype):
    p0, p1, m0, m1 = torch.randn(4, 5, 3, device=device, dtype=dtype)
    cp = hermite_to_bezier(p0, p1, m0, m1)
    t = torch.rand(9, device=device, dtype=dtype)
    assert_close(bezier(cp, t), hermite(p0, p1, m0, m1, t), scale=10)
    back = bezier_to_hermite(cp)
    for a, b in zip(back, (p0, p1, m0, m1)):
        assert_close(a, b, scale=10)
    with pytest.raises(ShapeError, match=r"degree \+ 1 = 4 control points, got 3"):
        bezier_to_hermite(cp[..., :3, :])


def test_hermite_gradcheck_and_zero_tangents():
    p0, p1, m0, m1 = torch.randn(4, 2, 2, dtype=torch.float64, requires_grad=True)
    t = torch.rand(5, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(hermite, (p0, p1, m0, m1, t))
    zeros = torch.zeros(2, dtype=torch.float64, requires_grad=True)
    hermite(p0[0], p1[0], zeros, zeros, t).sum().backward()
    assert zeros.grad.isfinite().all()


def test_hermite_curve_module():
    p0, p1, m0, m1 = torch.randn(4, 3, 2)
    t = torch.rand(6)
    curve = HermiteCurve(p0, p1, m0, m1)
    assert len(list(curve.parameters())) == 4
    assert_close(curve(t), hermite(p0, p1, m0, m1, t))
    assert_close(curve.to_bezier(), hermite_to_bezier(p0, p1, m0, m1))
    frozen = HermiteCurve(p0, p1, m0, m1, learnable=False).to(torch.float64)
    assert list(frozen.parameters()) == [] and frozen.p0.dtype == torch.float64
    with pytest.raises(ShapeError, match="m1"):
        HermiteCurve(p0, p1, m0, torch.randn(3, 3))


def _random_series(batch: int, knots: int, seed: int):
    rng = np.random.default_rng(seed)
    x = np.sort(rng.random(knots)) * 10
    x += np.arange(knots) * 1e-3  # strictly increasing
    y = rng.standard_normal((batch, knots)).cumsum(1)
    y[:, 3:6] = y[:, 3:4]  # flat pieces exercise the zero-slope rule
    y[0, -3:] = [1.0, 5.0, 4.0]  # sign change next to the end exercises the end rule
    return x, y


def test_hermite_spline_matches_scipy_cubic_hermite_spline(device, dtype):
    x, y = _random_series(4, 12, 0)
    m = np.random.default_rng(1).standard_normal(y.shape)
    xq = np.linspace(x[0] - 1, x[-1] + 1, 50)
    ref = CubicHermiteSpline(x, y, m, axis=1)(xq)
    args = [torch.tensor(a, device=device, dtype=dtype) for a in (x, y, m, xq)]
    assert_close(hermite_spline(*args), ref, scale=1e3 if dtype == torch.float32 else 10)
    # Per-series knots and queries take the gather path; same answer.
    xb = args[0].expand(4, 12)
    qb = args[3].expand(4, 50)
    assert_close(hermite_spline(xb, args[1], args[2], qb), ref,
                 scale=1e3 if dtype == torch.float32 else 10)
    spline = HermiteSpline(*args[:3])
    assert_close(spline(args[3]), hermite_spline(*args))


def test_pchip_matches_scipy_to_1e12_including_end_rule():
    x, y = _random_series(64, 40, 2)
    xq = np.concatenate([np.linspace(x[0], x[-1], 301), x, [x[0] - 0.3, x[-1] + 0.3]])
    scipy_pchip = ScipyPchip(x, y, axis=1)
    ref_tangents = scipy_pchip.derivative()(x)
    X, Y, XQ = (torch.tensor(a, dtype=torch.float64) for a in (x, y, xq))
    ours = pchip_tangents(X, Y)
    np.testing.assert_allclose(ours.numpy(), ref_tangents, rtol=0, atol=1e-12)
    # The end rule fired (set to 0 or clipped to 3 d0) on some series: a real check.
    slope0 = (y[:, 1] - y[:, 0]) / (x[1] - x[0])
    assert (np.isclose(ref_tangents[:, 0], 0) | np.isclose(ref_tangents[:, 0], 3 * slope0)).any()
    values = PchipInterpolator(X, Y)(XQ)
    np.testing.assert_allclose(values.numpy(), scipy_pchip(xq), rtol=0, atol=1e-12)
    assert_close(pchip_interpolate(X, Y, XQ), values, rtol=0, atol=0)
    # Batched knots: one set per series.
    xb = X.expand(64, 40)
    np.testing.assert_allclose(pchip_tangents(xb, Y).numpy(), ref_tangents, rtol=0, atol=1e-12)
    np.testing.assert_allclose(PchipInterpolator(xb, Y)(XQ.expand(64, -1)).numpy(),
                               scipy_pchip(xq), rtol=0, atol=1e-12)


@pytest.mark.parametrize("knots", [2, 3])
def test_pchip_few_knots_like_scipy(knots):
    x = np.arange(knots, dtype=float) ** 1.5
    y = np.random.default_rng(knots).standard_normal((3, knots))
    xq = np.linspace(-0.5, x[-1] + 0.5, 9)
    ours = pchip_interpolate(torch.tensor(x), torch.tensor(y), torch.tensor(xq))
    np.testing.assert_allclose(ours.numpy(), ScipyPchip(x, y, axis=1)(xq), atol=1e-12)


@given(st.lists(st.floats(-5, 5, allow_nan=False), min_size=3, max_size=12))
def test_property_pchip_preserves_monotonicity(steps):
    y = torch.tensor(np.cumsum(np.abs(steps)), dtype=torch.float64)  # non-decreasing data
    x = torch.arange(len(steps), dtype=torch.float64)
    xq = torch.linspace(0, len(steps) - 1, 200, dtype=torch.float64)
    out = pchip_interpolate(x, y, xq)
    assert (out[1:] - out[:-1] >= -1e-12).all()


def test_pchip_gradcheck_and_finite_gradients_on_flat_data():
    x = torch.tensor([0.0, 1.0, 2.5, 3.0, 4.0], dtype=torch.float64)
    y = torch.tensor([[0.0, 1.0, 0.5, 2.0, 3.0]], dtype=torch.float64, requires_grad=True)
    xq = torch.tensor([0.3, 1.7, 2.9, 3.5], dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda v: pchip_interpolate(x, v, xq), (y,))
    assert torch.autograd.gradcheck(lambda v: hermite_spline(x, v, v * 0.5, xq), (y,))
    flat = torch.zeros(1, 5, dtype=torch.float64, requires_grad=True)
    pchip_interpolate(x, flat, xq).sum().backward()
    assert flat.grad.isfinite().all()


def test_cardinal_and_catmull_rom_by_hand():
    x = torch.tensor([0.0, 1.0, 3.0, 4.0], dtype=torch.float64)
    y = torch.tensor([0.0, 2.0, 2.0, 5.0], dtype=torch.float64)
    expected = torch.tensor([2.0, 2 / 3, 1.0, 3.0], dtype=torch.float64)
    assert_close(catmull_rom_tangents(x, y), expected)
    assert_close(cardinal_tangents(x, y, tension=0.25), 0.75 * expected)
    assert_close(cardinal_tangents(x, y, tension=1.0), torch.zeros(4, dtype=torch.float64))
    two = cardinal_tangents(x[:2], y[:2])
    assert_close(two, torch.tensor([2.0, 2.0], dtype=torch.float64))
    # A Catmull-Rom spline interpolates and is C1.
    m = catmull_rom_tangents(x, y)
    h = 1e-7
    knot = torch.tensor([1.0 - h, 1.0 + h], dtype=torch.float64)
    out = hermite_spline(x, y, m, knot)
    assert_close(out, torch.tensor([2.0, 2.0], dtype=torch.float64), atol=1e-6, rtol=0)
    with pytest.raises(TypeError, match="tension"):
        cardinal_tangents(x, y, tension="tight")


def test_knots_must_be_strictly_increasing_with_index():
    y = torch.zeros(5)
    # the message names the argument as the caller wrote it (pchip's knots are ``x``)
    with pytest.raises(ValueError, match=r"^x: must be strictly increasing, but x\[\.\.\., 3\] = "
                                         r"2\.0 is not greater than x\[\.\.\., 2\] = 2\.0"):
        pchip_tangents(torch.tensor([0.0, 1.0, 2.0, 2.0, 3.0]), y)
    with pytest.raises(ValueError, match=r"knots\[\.\.\., 1\]"):
        check_knots(torch.tensor([[0.0, 1.0, 2.0], [0.0, -1.0, 2.0]]))
    with pytest.raises(ValueError, match="strictly increasing"):
        PchipInterpolator(torch.tensor([0.0, float("nan"), 1.0]), torch.zeros(3))
    with pytest.raises(ShapeError, match="at least 2 knots"):
        check_knots(torch.tensor([1.0]))
    with pytest.raises(ShapeError, match="values"):
        hermite_spline(torch.arange(4.0), torch.zeros(5), torch.zeros(4), torch.rand(3))
    with pytest.raises(TypeError, match="x: expected a floating-point"):
        hermite_spline(torch.arange(4.0), torch.zeros(4), torch.zeros(4), torch.arange(3))


def test_empty_batches():
    x = torch.arange(4.0)
    assert pchip_interpolate(x, torch.zeros(0, 4), torch.rand(5)).shape == (0, 5)
    assert pchip_interpolate(x, torch.zeros(2, 4), torch.zeros(0)).shape == (2, 0)
    assert hermite(*torch.zeros(4, 0, 2), torch.rand(3)).shape == (0, 3, 2)


def test_modules_equal_functions_and_defaults():
    x = torch.arange(5.0, dtype=torch.float64)
    y = torch.randn(3, 5, dtype=torch.float64)
    xq = torch.rand(7, dtype=torch.float64) * 4
    assert_close(PchipInterpolator(x, y)(xq), hermite_spline(x, y, pchip_tangents(x, y), xq))
    assert_close(PchipInterpolator(x, y).tangents, pchip_tangents(x, y))
    spline = HermiteSpline(x, y, catmull_rom_tangents(x, y), learnable=True)
    assert len(list(spline.parameters())) == 2
    assert_close(spline(xq), hermite_spline(x, y, catmull_rom_tangents(x, y), xq))
    moved = PchipInterpolator(x.float(), y.float()).to(torch.float64)
    assert moved.knots.dtype == torch.float64 and moved._table.dtype == torch.float64
    assert inspect.signature(cardinal_tangents).parameters["tension"].default == 0.0


def test_pchip_no_grad_fast_path_equals_autograd_path():
    x, y = _random_series(16, 30, 5)
    X = torch.tensor(x)
    Y = torch.tensor(y)
    XQ = torch.linspace(x[0] - 0.5, x[-1] + 0.5, 77, dtype=torch.float64)
    fast = PchipInterpolator(X, Y)  # in-place table build
    slow = PchipInterpolator(X, Y.clone().requires_grad_(True))  # autograd path
    assert_close(fast.tangents, slow.tangents.detach(), rtol=0, atol=0)
    assert_close(fast(XQ), slow(XQ).detach(), rtol=0, atol=0)
    for knots in (2, 3):
        few = PchipInterpolator(X[:knots], Y[:, :knots])
        ref = ScipyPchip(x[:knots], y[:, :knots], axis=1)
        np.testing.assert_allclose(few.tangents.numpy(), ref.derivative()(x[:knots]), atol=1e-12)


def test_per_series_knots_broadcast_against_queries():
    x = torch.sort(torch.rand(3, 1, 6, dtype=torch.float64), dim=-1).values
    x = x + torch.arange(6, dtype=torch.float64)  # strictly increasing per series
    y = torch.randn(3, 2, 6, dtype=torch.float64)
    xq = torch.rand(2, 5, dtype=torch.float64) * 5
    out = hermite_spline(x, y, pchip_tangents(x, y), xq)
    assert out.shape == (3, 2, 5)
    for i in range(3):
        for j in range(2):
            ref = ScipyPchip(x[i, 0].numpy(), y[i, j].numpy())(xq[j].numpy())
            np.testing.assert_allclose(out[i, j].numpy(), ref, atol=1e-12)


def test_query_dtype_error():
    interp = PchipInterpolator(torch.arange(4.0), torch.zeros(4))
    with pytest.raises(TypeError, match="xq: expected a floating-point"):
        interp(torch.arange(3))
