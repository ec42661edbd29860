"""Least-squares Bezier fitting against numpy lstsq and exact recovery."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.curves import bernstein_basis, bezier, fit_bezier, fit_parameters


def test_exact_recovery_with_known_parameters(device, dtype):
    cp = torch.randn(4, 5, 2, device=device, dtype=dtype)
    t = torch.linspace(0, 1, 30, device=device, dtype=dtype)
    fit = fit_bezier(bezier(cp, t), 4, parametrization="uniform")
    assert fit.control_points.dtype == dtype
    assert_close(fit.control_points, cp, scale=1e3 if dtype == torch.float32 else 10)
    assert fit.rms.max() < (1e-4 if dtype == torch.float32 else 1e-10)


@pytest.mark.parametrize("parametrization", ["uniform", "chord", "centripetal"])
def test_matches_numpy_lstsq(parametrization):
    rng = np.random.default_rng(0)
    points = torch.tensor(rng.standard_normal((3, 25, 2)).cumsum(1))
    fit = fit_bezier(points, 3, parametrization)
    for b in range(3):
        basis = bernstein_basis(fit.t[b], 3).numpy()
        ref = np.linalg.lstsq(basis, points[b].numpy(), rcond=None)[0]
        assert_close(fit.control_points[b], ref)
        assert_close(fit.rms[b], np.sqrt(((basis @ ref - points[b].numpy()) ** 2).sum() / 25))


def test_parameters_by_hand():
    pts = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 3.0]], dtype=torch.float64)
    assert_close(fit_parameters(pts, "uniform"), [0.0, 0.5, 1.0])
    assert_close(fit_parameters(pts, "chord"), [0.0, 0.25, 1.0])
    assert_close(fit_parameters(pts, "centripetal"), [0.0, 1 / (1 + 3**0.5), 1.0])
    same = torch.zeros(4, 2)
    assert_close(fit_parameters(same, "chord"), torch.linspace(0, 1, 4))


def test_gradient_through_fit():
    points = torch.randn(12, 2, dtype=torch.float64, requires_grad=True)
    # Uniform parameters do not depend on the points, so the full derivative is checked.
    assert torch.autograd.gradcheck(lambda p: fit_bezier(p, 3, "uniform").control_points,
                                    (points,))


def test_bad_input():
    with pytest.raises(ShapeError, match=r"degree \+ 1 = 5 points, got 3"):
        fit_bezier(torch.randn(3, 2), 4)
    with pytest.raises(ValueError, match="parametrization"):
        fit_bezier(torch.randn(8, 2), 3, parametrization="arc")
    with pytest.raises(ShapeError, match="at least 2 points"):
        fit_parameters(torch.randn(1, 2))
