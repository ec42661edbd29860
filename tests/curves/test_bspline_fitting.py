"""B-spline interpolation and least squares against scipy make_interp_spline / make_lsq_spline."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.curves import bspline, fit_bspline, interpolate_bspline

scipy_interpolate = pytest.importorskip("scipy.interpolate")
F64 = torch.float64


@pytest.mark.parametrize("degree", range(0, 8))
def test_interpolation_matches_make_interp_spline(degree):
    g = torch.Generator().manual_seed(degree)
    x = torch.sort(torch.rand(14, generator=g, dtype=F64)).values
    y = torch.randn(14, 2, generator=g, dtype=F64)
    ours = interpolate_bspline(x, y, degree)
    ref = scipy_interpolate.make_interp_spline(x.numpy(), y.numpy(), degree)
    assert np.abs(ours.knots.numpy() - ref.t).max() == 0
    assert np.abs(ours.control_points.numpy() - ref.c).max() <= 1e-10 * np.abs(ref.c).max()
    if degree > 0:
        assert torch.allclose(bspline(ours.control_points, x, degree, ours.knots), y,
                              atol=1e-10)


def test_batched_sites_match_a_loop():
    g = torch.Generator().manual_seed(1)
    x = torch.sort(torch.rand(3, 9, generator=g, dtype=F64), -1).values
    y = torch.randn(3, 9, 2, generator=g, dtype=F64)
    ours = interpolate_bspline(x, y, 3)
    for b in range(3):
        ref = scipy_interpolate.make_interp_spline(x[b].numpy(), y[b].numpy(), 3)
        assert np.allclose(ours.control_points[b].numpy(), ref.c, atol=1e-10)


@pytest.mark.parametrize("degree", [1, 2, 3, 5])
@pytest.mark.parametrize("parametrization", ["uniform", "chord", "centripetal"])
def test_least_squares_matches_make_lsq_spline(degree, parametrization):
    g = torch.Generator().manual_seed(degree)
    points = torch.randn(3, 40, 2, generator=g, dtype=F64).cumsum(1)
    fit = fit_bspline(points, degree, 10, parametrization=parametrization)
    assert fit.control_points.shape == (3, 10, 2) and fit.knots.shape == (3, 10 + degree + 1)
    for b in range(3):
        ref = scipy_interpolate.make_lsq_spline(fit.t[b].numpy(), points[b].numpy(),
                                                fit.knots[b].numpy(), degree)
        assert np.abs(ref.c - fit.control_points[b].numpy()).max() <= 1e-10 * np.abs(ref.c).max()
        residual = ref(fit.t[b].numpy()) - points[b].numpy()
        assert abs(np.sqrt((residual ** 2).sum(-1).mean()) - float(fit.rms[b])) < 1e-10


def test_given_knots_weights_and_ragged_strokes():
    g = torch.Generator().manual_seed(2)
    strokes = [torch.randn(n, 2, generator=g, dtype=F64).cumsum(0) for n in (20, 33, 12)]
    weights = [torch.rand(len(s), generator=g, dtype=F64) for s in strokes]
    knots = torch.tensor([0, 0, 0, 0, 0.3, 0.5, 0.8, 1, 1, 1, 1], dtype=F64)
    fit = fit_bspline(strokes, 3, knots=knots, weights=weights)
    for b, (s, w) in enumerate(zip(strokes, weights)):
        single = fit_bspline(s, 3, knots=knots, weights=w)
        assert torch.allclose(fit.control_points[b], single.control_points, atol=1e-12)
        # scipy minimises sum (w_k r_k)^2, ours sum w_k |r_k|^2
        ref = scipy_interpolate.make_lsq_spline(single.t.numpy(), s.numpy(), knots.numpy(), 3,
                                                w=np.sqrt(w.numpy()))
        assert np.allclose(ref.c, single.control_points.numpy(), atol=1e-10)


def test_periodic_fit_recovers_a_closed_curve():
    g = torch.Generator().manual_seed(4)
    cp = torch.randn(7, 2, generator=g, dtype=F64)
    t = torch.linspace(0, 1, 80, dtype=F64)[:-1]
    samples = bspline(cp, t, 3, periodic=True)
    fit = fit_bspline(samples, 3, 7, parametrization="uniform", periodic=True)
    assert torch.allclose(fit.t, t, atol=1e-15)
    assert torch.allclose(fit.control_points, cp, atol=1e-10) and float(fit.rms) < 1e-10


def test_errors():
    points = torch.randn(5, 2)
    with pytest.raises(ShapeError, match="points"):
        fit_bspline(points, 3, 8)
    with pytest.raises(ValueError, match="exactly one"):
        fit_bspline(points, 3)
    with pytest.raises(ValueError, match="x"):
        interpolate_bspline(torch.tensor([0.0, 1.0, 1.0, 2.0]), torch.zeros(4, 1), 1)


@pytest.mark.grad
def test_gradcheck():
    points = torch.randn(12, 2, dtype=F64).cumsum(0).requires_grad_()
    # uniform parameters: chord ones are constants of the gradient (documented)
    assert torch.autograd.gradcheck(
        lambda p: fit_bspline(p, 3, 6, parametrization="uniform").control_points, (points,))
    x = torch.linspace(0, 1, 7, dtype=F64)
    assert torch.autograd.gradcheck(lambda p: interpolate_bspline(x, p[:7], 3).control_points,
                                    (points,))


def test_bad_parametrization_names_the_choices():
    points = torch.rand(20, 2, dtype=torch.float64)
    with pytest.raises(ValueError, match="parametrization: expected one of 'uniform', 'chord', "
                                         "'centripetal', got 'arc'"):
        fit_bspline(points, 3, 6, parametrization="arc")
