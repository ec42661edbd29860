"""B-spline curves against scipy's BSpline (values and derivatives), knot insertion and Bezier
segments against evaluation, gradcheck and invariants."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.curves import (
    BSplineCurve,
    bezier,
    bezier_to_bspline,
    bspline,
    bspline_basis,
    bspline_derivative,
    bspline_to_bezier,
    insert_knot,
    uniform_knots,
)

scipy_interpolate = pytest.importorskip("scipy.interpolate")
F64 = torch.float64


def _knots(kind: str, count: int, degree: int, g: torch.Generator) -> torch.Tensor:
    inner = torch.sort(torch.rand(count + degree + 1, generator=g, dtype=F64)).values
    if kind == "unclamped":
        return inner
    if kind == "repeated":  # an interior knot of multiplicity min(p, 2)
        inner[degree + 2: degree + 2 + min(degree, 2)] = inner[degree + 2]
        return inner
    return uniform_knots(count, degree, dtype=F64)  # clamped


def _scipy(knots, cp, degree, t, nu, periodic=False):
    spline = scipy_interpolate.BSpline(knots.numpy(), cp.movedim(-2, 0).numpy(), degree,
                                       extrapolate="periodic" if periodic else True)
    return torch.from_numpy(np.moveaxis(spline(t.numpy(), nu=nu), 0, -2))


@pytest.mark.parametrize("degree", range(1, 8))
@pytest.mark.parametrize("kind", ["clamped", "unclamped", "repeated"])
def test_values_and_derivatives_match_scipy(degree, kind):
    g = torch.Generator().manual_seed(degree)
    count = degree + 6
    knots = _knots(kind, count, degree, g)
    cp = torch.randn(3, count, 2, generator=g, dtype=F64)
    lo, hi = float(knots[degree]), float(knots[count])
    t = torch.cat([torch.linspace(lo, hi, 41, dtype=F64), knots[degree:count + 1]])
    for order in range(degree + 2):
        ours = bspline_derivative(cp, t, degree, order, knots)
        ref = _scipy(knots, cp, degree, t, order)
        scale = max(1.0, float(ref.abs().max()))
        assert (ours - ref).abs().max() <= 1e-13 * scale, (order, kind)


@pytest.mark.parametrize("degree", range(1, 8))
def test_periodic_matches_scipy(degree):
    g = torch.Generator().manual_seed(10 + degree)
    count = degree + 4
    cp = torch.randn(2, count, 3, generator=g, dtype=F64)
    breaks = torch.sort(torch.rand(count + 1, generator=g, dtype=F64)).values
    period = breaks[-1] - breaks[0]
    j = torch.arange(-degree, count + degree + 1)
    full = breaks[j % count] + torch.div(j, count, rounding_mode="floor") * period
    wrapped = cp[:, torch.arange(count + degree) % count]
    t = torch.linspace(-1.5, 2.5, 57, dtype=F64)
    for order in range(degree + 1):
        ours = bspline_derivative(cp, t, degree, order, breaks, periodic=True)
        ref = _scipy(full, wrapped, degree, t, order, periodic=True)
        assert (ours - ref).abs().max() <= 1e-12 * max(1.0, float(ref.abs().max())), order
    # the default uniform knots close the curve with matching derivatives at the seam
    for order in range(degree):
        ends = bspline_derivative(cp, torch.tensor([0.0, 1.0], dtype=F64), degree, order,
                                  periodic=True)
        assert torch.allclose(ends[:, 0], ends[:, 1], atol=1e-12 * 10 ** order)


def test_per_curve_knots_and_parameters_match_a_loop():
    g = torch.Generator().manual_seed(3)
    degree, count = 3, 9
    knots = torch.sort(torch.rand(4, count + degree + 1, generator=g, dtype=F64), -1).values
    cp = torch.randn(4, count, 2, generator=g, dtype=F64)
    lo, hi = knots[:, degree:degree + 1], knots[:, count:count + 1]
    t = lo + (hi - lo) * torch.rand(4, 11, generator=g, dtype=F64)
    ours = bspline_derivative(cp, t, degree, 1, knots)
    for b in range(4):
        assert torch.allclose(ours[b], _scipy(knots[b], cp[b], degree, t[b], 1), atol=1e-12)


@pytest.mark.parametrize("degree", range(0, 8))
@pytest.mark.parametrize("kind", ["clamped", "unclamped", "repeated"])
@pytest.mark.parametrize("many", [True, False])  # by Bezier segments / by the basis
def test_per_curve_knots_match_scipy_on_both_paths(degree, kind, many, monkeypatch):
    bspline_module = __import__("torchgeo_cg.curves.bspline", fromlist=["_CHUNK"])
    monkeypatch.setattr(bspline_module, "_CHUNK", 40)  # several chunks of curves
    g = torch.Generator().manual_seed(100 + degree)
    count, curves = degree + 6, 5
    knots = torch.stack([_knots(kind, count, degree, g) for _ in range(curves)])
    cp = torch.randn(curves, count, 3, generator=g, dtype=F64)
    lo, hi = knots[:, degree:degree + 1], knots[:, count:count + 1]
    size = 37 if many else 1
    assert (size * bspline_module._SEGMENT_RATIO >= count - degree) == many
    t = lo + (hi - lo) * torch.rand(curves, size, generator=g, dtype=F64)
    if many:  # every knot of the domain, where spans change
        t = torch.cat([t, knots[:, degree:count + 1]], -1)
    for order in range(degree + 2):
        ours = bspline_derivative(cp, t, degree, order, knots)
        for b in range(curves):
            ref = _scipy(knots[b], cp[b], degree, t[b], order)
            scale = max(1.0, float(ref.abs().max()))
            assert (ours[b] - ref).abs().max() <= 1e-13 * scale, (order, b)
    outside = torch.cat([t[:, :-1], hi + 0.1 * (hi - lo)], -1)  # extrapolation: by the basis
    ours = bspline(cp, outside, degree, knots)
    for b in range(curves):
        ref = _scipy(knots[b], cp[b], degree, outside[b], 0)
        assert (ours[b] - ref).abs().max() <= 1e-13 * max(1.0, float(ref.abs().max()))
    shared_t = torch.linspace(0.2, 0.8, 24, dtype=F64)  # one t for all: as a loop
    ours = bspline(cp, shared_t, degree, knots if kind != "unclamped" else None)
    for b in range(curves):
        ref = _scipy(knots[b] if kind != "unclamped" else uniform_knots(count, degree, dtype=F64),
                     cp[b], degree, shared_t, 0)
        assert (ours[b] - ref).abs().max() <= 1e-13 * max(1.0, float(ref.abs().max()))


@pytest.mark.grad
@pytest.mark.parametrize("size", [12, 1])  # by Bezier segments / by the basis
def test_gradcheck_per_curve_knots(size):
    g = torch.Generator().manual_seed(5)
    knots = torch.tensor([[-0.3, -0.2, -0.1, 0.3, 0.45, 0.7, 1.1, 1.2, 1.3],
                          [-0.2, -0.1, 0.0, 0.2, 0.25, 0.6, 1.0, 1.05, 1.2]], dtype=F64,
                         requires_grad=True)
    cp = torch.randn(2, 6, 2, generator=g, dtype=F64, requires_grad=True)
    t = (torch.rand(2, size, generator=g, dtype=F64) * 0.9 + 0.05).requires_grad_(True)
    for order in (0, 1, 2):
        assert torch.autograd.gradcheck(
            lambda c, x, k, order=order: bspline_derivative(c, x, 2, order, k), (cp, t, knots))


def test_default_knots_give_the_bezier_curve_for_n_equals_p():
    cp = torch.randn(5, 6, 3, dtype=F64)
    t = torch.rand(13, dtype=F64)
    assert torch.allclose(bspline(cp, t, 5), bezier(cp, t), atol=1e-14)


def test_validation_names_the_first_bad_knot():
    cp = torch.zeros(4, 2)
    with pytest.raises(ValueError, match=r"knots\[\.\.\., 4\] = 0.25 is smaller"):
        bspline(cp, torch.rand(3), 2, torch.tensor([0.0, 0, 0, 0.5, 0.25, 1, 1]))
    with pytest.raises(ShapeError, match="knots"):
        bspline(cp, torch.rand(3), 2, torch.tensor([0.0, 0, 0, 1, 1, 1]))
    with pytest.raises(ValueError, match="empty"):
        bspline(cp, torch.rand(3), 1, torch.tensor([0.0, 0, 0, 0, 0, 1]))
    with pytest.raises(ShapeError, match="control_points"):
        bspline(torch.zeros(2, 2), torch.rand(3), 2)
    with pytest.raises(TypeError, match="t"):
        bspline(cp, torch.tensor([1, 2]), 2)


@pytest.mark.parametrize("degree", [1, 2, 3, 5])
def test_insert_knot_leaves_the_curve_unchanged(degree):
    g = torch.Generator().manual_seed(degree)
    count = degree + 5
    knots = _knots("repeated", count, degree, g)
    cp = torch.randn(3, count, 2, generator=g, dtype=F64)
    t = torch.linspace(float(knots[degree]), float(knots[count]), 97, dtype=F64)
    for value in (float(knots[degree + 2]), 0.5 * float(knots[degree] + knots[count])):
        new = insert_knot(cp, value, degree, knots, times=2)
        assert new.control_points.shape == (3, count + 2, 2)
        assert torch.allclose(bspline(new.control_points, t, degree, new.knots),
                              bspline(cp, t, degree, knots), atol=1e-13)
    per_curve = knots[degree] + (knots[count] - knots[degree]) * torch.tensor([0.2, 0.5, 0.7],
                                                                                dtype=F64)
    new = insert_knot(cp, per_curve, degree, knots)
    assert torch.allclose(bspline(new.control_points, t, degree, new.knots),
                          bspline(cp, t, degree, knots), atol=1e-13)
    with pytest.raises(ValueError, match="value"):
        insert_knot(cp, float(knots[count]) + 1, degree, knots)


def test_insert_knot_takes_a_number_in_the_knots_dtype():
    # a Python number is inserted in the knots' dtype, not rounded through float32
    knots = torch.tensor([0, 0, 0, 0, 0.5, 0.8, 1, 1, 1, 1], dtype=F64)
    cp = torch.randn(6, 2, generator=torch.Generator().manual_seed(0), dtype=F64)
    new = insert_knot(cp, 0.37, 3, knots)
    assert new.knots.dtype == F64 and bool((new.knots == 0.37).any())
    tck = scipy_interpolate.insert(0.37, (knots.numpy(), cp.T.numpy(), 3))
    np.testing.assert_array_equal(new.knots.numpy(), tck[0])
    twice = insert_knot(cp, 0.8, 3, knots, times=2)
    assert int((twice.knots == 0.8).sum()) == 3  # the multiplicity of 0.8 grows
    # a tensor value takes part in the dtype promotion, as t does in bspline
    promoted = insert_knot(cp.float(), torch.tensor(0.37, dtype=F64), 3, knots.float())
    assert promoted.knots.dtype == F64 and bool((promoted.knots == 0.37).any())
    assert insert_knot(cp.float(), 0.37, 3).knots.dtype == torch.float32


@pytest.mark.parametrize("degree", [1, 2, 3, 4])
@pytest.mark.parametrize("shared", [True, False])
def test_bezier_segments_equal_the_curve(degree, shared):
    g = torch.Generator().manual_seed(degree)
    count = degree + 5
    if shared:
        knots = _knots("repeated", count, degree, g)
    else:
        knots = torch.sort(torch.rand(3, count + degree + 1, generator=g, dtype=F64), -1).values
    cp = torch.randn(3, count, 2, generator=g, dtype=F64)
    seg = bspline_to_bezier(cp, degree, knots)
    assert seg.control_points.shape == (3, count - degree, degree + 1, 2)
    tau = torch.linspace(0, 1, 9, dtype=F64)[:-1]  # right-continuous: stay inside each span
    t = (seg.start[..., None] + tau * (seg.end - seg.start)[..., None]).reshape(3, -1)
    ours = bezier(seg.control_points, tau).reshape(3, -1, 2)
    assert torch.allclose(ours, bspline(cp, t, degree, knots), atol=1e-13)


def test_bezier_to_bspline_round_trip():
    cp = torch.randn(2, 8, 3, dtype=F64)
    seg = bspline_to_bezier(cp, 3)
    back = bezier_to_bspline(seg.control_points, torch.linspace(0, 1, 6, dtype=F64))
    t = torch.rand(31, dtype=F64)
    assert torch.allclose(bspline(back.control_points, t, 3, back.knots), bspline(cp, t, 3),
                          atol=1e-13)
    with pytest.raises(ValueError, match="breaks"):
        bezier_to_bspline(seg.control_points, torch.tensor([0.0, 0.5, 0.4, 0.6, 0.8, 1.0]))


def test_module_matches_function_and_learns():
    cp = torch.randn(6, 2, dtype=F64)
    curve = BSplineCurve(cp, 3)
    t = torch.rand(9, dtype=F64)
    assert torch.equal(curve(t), bspline(cp, t, 3))
    assert torch.equal(curve.derivative(t, 2), bspline_derivative(cp, t, 3, 2))
    curve(t).square().sum().backward()
    assert curve.control_points.grad is not None and curve.control_points.grad.abs().sum() > 0


@pytest.mark.grad
def test_gradcheck_points_parameters_and_knots():
    cp = torch.randn(6, 2, dtype=F64, requires_grad=True)
    knots = torch.tensor([-0.3, -0.2, -0.1, 0.3, 0.45, 0.7, 1.1, 1.2, 1.3], dtype=F64,
                         requires_grad=True)
    t = torch.tensor([0.1, 0.35, 0.5, 0.9], dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda c, x, k: bspline_derivative(c, x, 2, 1, k),
                                    (cp, t, knots))
    assert torch.autograd.gradcheck(lambda c, x: bspline(c, x, 3, periodic=True),
                                    (cp, t))


@given(st.integers(0, 6), st.integers(0, 5), st.floats(1e-6, 1e6))
def test_partition_of_unity_and_scale(degree, extra, scale):
    g = torch.Generator().manual_seed(degree * 7 + extra)
    count = degree + 1 + extra
    knots = torch.sort(torch.rand(count + degree + 1, generator=g, dtype=F64)).values * scale
    t = knots[degree] + (knots[count] - knots[degree]) * torch.rand(20, generator=g, dtype=F64)
    basis = bspline_basis(t, degree, knots)
    assert torch.allclose(basis.values[0].sum(-1), torch.ones(20, dtype=F64), atol=1e-12)
    assert bool((basis.values[0] >= -1e-15).all())
    cp = torch.randn(count, 2, generator=g, dtype=F64)
    assert torch.allclose(bspline(cp * scale, t, degree, knots), bspline(cp, t, degree, knots)
                          * scale, rtol=1e-10, atol=0)
