import torch
from hypothesis import given
from hypothesis import strategies as st

from torchgeo_cg.core.numerics import clamp_away_from_zero, safe_div, safe_norm, safe_sqrt


def test_safe_div_matches_division_away_from_zero(dtype, device):
    num = torch.tensor([1.0, -2.0, 3.0], dtype=dtype, device=device)
    den = torch.tensor([2.0, 4.0, -0.5], dtype=dtype, device=device)
    torch.testing.assert_close(safe_div(num, den), num / den)


def test_safe_div_gradients_finite_at_zero(dtype, device):
    num = torch.tensor([1.0, 1.0, 1.0], dtype=dtype, device=device, requires_grad=True)
    den = torch.tensor([0.0, -0.0, 1e-30], dtype=dtype, device=device, requires_grad=True)
    out = safe_div(num, den)
    out.sum().backward()
    assert torch.isfinite(out).all()
    assert torch.isfinite(num.grad).all() and torch.isfinite(den.grad).all()
    # sign of zero is kept: +0 -> +eps, -0 -> -eps
    assert out[0] > 0 and out[1] < 0
    # clamped entries get zero gradient with respect to the denominator
    assert (den.grad == 0).all()


def test_nan_in_nan_out():
    assert torch.isnan(safe_div(torch.tensor(1.0), torch.tensor(float("nan"))))
    assert torch.isnan(clamp_away_from_zero(torch.tensor(float("nan"))))
    assert torch.isnan(safe_sqrt(torch.tensor(float("nan"))))
    assert torch.isnan(safe_norm(torch.tensor([float("nan"), 1.0])))


@given(st.floats(-1e6, 1e6, allow_nan=False))
def test_clamp_away_from_zero_magnitude(x):
    out = clamp_away_from_zero(torch.tensor(x, dtype=torch.float64), 1e-8)
    assert abs(out.item()) >= 1e-8
    if abs(x) >= 1e-8:
        assert out.item() == x


def test_safe_sqrt_and_norm_gradcheck():
    x = torch.tensor([0.3, 2.0, 5.0], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(safe_sqrt, (x,))
    v = torch.tensor([[3.0, 4.0], [1.0, -2.0]], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(safe_norm, (v,))
    torch.testing.assert_close(safe_norm(v), torch.linalg.vector_norm(v, dim=-1))
    zero = torch.zeros(2, dtype=torch.float64, requires_grad=True)
    safe_norm(zero).backward()
    assert torch.equal(zero.grad, torch.zeros(2, dtype=torch.float64))
