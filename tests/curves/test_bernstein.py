"""Bernstein basis: closed form at low degree, stability to degree 1000, gradients."""

from __future__ import annotations

import math

import pytest
import torch

from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.curves import bernstein_basis


@pytest.mark.parametrize("degree", [0, 1, 2, 3, 7])
def test_matches_closed_form(degree, device, dtype):
    t = torch.linspace(-0.2, 1.2, 15, device=device, dtype=dtype)  # extrapolation included
    expected = torch.stack(
        [math.comb(degree, k) * t**k * (1 - t) ** (degree - k) for k in range(degree + 1)], -1
    )
    assert_close(bernstein_basis(t, degree), expected, scale=10)


def test_matches_scipy_bpoly_basis():
    from scipy.interpolate import BPoly

    t = torch.rand(20, dtype=torch.float64)
    degree = 6
    ours = bernstein_basis(t, degree)
    for k in range(degree + 1):
        coeffs = torch.zeros(degree + 1, 1, dtype=torch.float64)
        coeffs[k] = 1
        ref = BPoly(coeffs.numpy(), [0.0, 1.0])(t.numpy())
        assert_close(ours[:, k], torch.from_numpy(ref), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("degree", [200, 1000])
def test_high_degree_is_finite_and_partition_of_unity(degree, device, dtype):
    t = torch.cat([torch.tensor([0.0, 1.0, 0.5, 1e-7]), torch.rand(12)]).to(device, dtype)
    t.requires_grad_(True)
    basis = bernstein_basis(t, degree)
    assert basis.shape == (16, degree + 1)
    assert basis.isfinite().all()
    assert (basis >= 0).all()
    assert_close(basis.sum(-1), torch.ones_like(t), atol=1e-4 if dtype == torch.float32 else 1e-10)
    (basis * torch.linspace(0, 1, degree + 1, device=device, dtype=dtype)).sum().backward()
    assert t.grad.isfinite().all()


def test_high_degree_against_log_space_reference():
    degree = 1000
    t = torch.tensor([0.3, 0.5, 0.77], dtype=torch.float64)
    k = torch.arange(degree + 1, dtype=torch.float64)
    log_binom = (torch.lgamma(torch.tensor(degree + 1.0, dtype=torch.float64))
                 - torch.lgamma(k + 1) - torch.lgamma(degree - k + 1))
    ref = torch.exp(log_binom + k * t[:, None].log() + (degree - k) * (1 - t[:, None]).log())
    assert_close(bernstein_basis(t, degree), ref, rtol=1e-9, atol=1e-300)


def test_gradcheck():
    t = torch.rand(2, 5, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x: bernstein_basis(x, 4), (t,))


def test_endpoints_gradient_finite():
    t = torch.tensor([0.0, 1.0], dtype=torch.float64, requires_grad=True)
    bernstein_basis(t, 5).sum().backward()
    assert t.grad.isfinite().all()


def test_empty_and_batched_shapes():
    assert bernstein_basis(torch.zeros(0), 3).shape == (0, 4)
    assert bernstein_basis(torch.zeros(2, 0, 7), 2).shape == (2, 0, 7, 3)


def test_bad_input():
    with pytest.raises(TypeError, match="degree"):
        bernstein_basis(torch.rand(3), 2.0)
    with pytest.raises(ValueError, match="degree"):
        bernstein_basis(torch.rand(3), -1)
    with pytest.raises(TypeError, match="t: expected a floating-point"):
        bernstein_basis(torch.arange(3), 2)
    with pytest.raises(ValueError, match=r"t: expected shape \(\*, T\)"):
        bernstein_basis(torch.tensor(0.5), 2)
