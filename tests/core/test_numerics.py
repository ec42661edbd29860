import math

import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from torchgeo_cg.core.numerics import (
    cast_back,
    clamp_away_from_zero,
    hypot,
    power_of_two_scale,
    safe_div,
    safe_norm,
    safe_sqrt,
    working_dtype,
)


def test_safe_div_matches_division_away_from_zero(dtype, device):
    num = torch.tensor([1.0, -2.0, 3.0], dtype=dtype, device=device)
    den = torch.tensor([2.0, 4.0, -0.5], dtype=dtype, device=device)
    torch.testing.assert_close(safe_div(num, den), num / den)


def test_safe_div_legacy_eps_gradients_finite_at_zero(dtype, device):
    num = torch.tensor([1.0, 1.0, 1.0], dtype=dtype, device=device, requires_grad=True)
    den = torch.tensor([0.0, -0.0, 1e-30], dtype=dtype, device=device, requires_grad=True)
    out = safe_div(num, den, eps=1e-8)
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


SCALES = [1e-300, 1e-30, 1e-9, 1.0, 1e9, 1e30, 1e300]


@pytest.mark.parametrize("s", SCALES)
def test_safe_div_default_has_no_threshold(s):
    """The default guards exact zeros only: tiny and huge denominators divide exactly."""
    num = torch.tensor([3.0 * s, -1.0], dtype=torch.float64, requires_grad=True)
    den = torch.tensor([2.0 * s, 0.0], dtype=torch.float64, requires_grad=True)
    out = safe_div(num, den)
    assert out[0].item() == pytest.approx(1.5, rel=1e-15) and out[1].item() == 0.0
    out.sum().backward()
    assert torch.isfinite(num.grad).all() and torch.isfinite(den.grad).all()
    assert den.grad[1] == 0 and num.grad[1] == 0
    assert torch.isnan(safe_div(torch.tensor(float("nan")), torch.tensor(0.0)))


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float32, torch.float64])
def test_safe_norm_matches_float64_reference_at_every_scale(dtype):
    """Overflow/underflow-safe: |(3, 4) s| = 5 s over the whole finite range of the dtype."""
    info = torch.finfo(dtype)
    exps = torch.linspace(math.log10(info.tiny) + 1, math.log10(info.max) - 1, 9)
    for e in exps.tolist():
        s = 10.0**e
        for dim in (2, 3, 7):
            v = torch.zeros(dim, dtype=torch.float64)
            v[0], v[-1] = 3 * s, -4 * s
            got = safe_norm(v.to(dtype)).double()
            vd = v.to(dtype).double()  # reference: scaled by the max in float64
            big = vd.abs().max()
            want = big * (vd / big).square().sum().sqrt()
            assert torch.isfinite(got), (dtype, s, dim)
            torch.testing.assert_close(got, want, rtol=4 * info.eps, atol=0)


def test_safe_norm_float32_intermediate_overflow_regression():
    """|p| ~ 2e19 is finite in float32 although the sum of squares overflows."""
    p = torch.tensor([[2e19, 2e19, 2e19]], dtype=torch.float32, requires_grad=True)
    n = safe_norm(p)
    assert torch.isfinite(n).all()
    torch.testing.assert_close(n.double(), torch.tensor([2e19 * 3**0.5], dtype=torch.float64),
                               rtol=1e-6, atol=0)
    n.sum().backward()
    torch.testing.assert_close(p.grad, torch.full((1, 3), 3**-0.5), rtol=1e-6, atol=0)


def test_safe_norm_no_threshold_small_vectors():
    """The old default returned 0 below 1e-12; the norm of a 1e-200 vector is 1e-200."""
    v = torch.tensor([3e-200, 4e-200], dtype=torch.float64)
    assert safe_norm(v).item() == pytest.approx(5e-200, rel=1e-15)
    assert safe_sqrt(torch.tensor(1e-300, dtype=torch.float64)).item() == pytest.approx(1e-150)


def test_hypot_gradients_zero_vector_and_second_order():
    x = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    y = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    (gx,) = torch.autograd.grad(hypot(x, y).sum(), x, create_graph=True)
    assert torch.equal(gx, torch.zeros(3, dtype=torch.float64))
    a = torch.tensor([0.3, -2.0], dtype=torch.float64, requires_grad=True)
    b = torch.tensor([1.5, 0.7], dtype=torch.float64, requires_grad=True)
    c = torch.tensor([-0.2, 0.4], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(hypot, (a, b, c))
    assert torch.autograd.gradgradcheck(hypot, (a, b, c))
    assert torch.isnan(hypot(torch.tensor(float("nan")), torch.tensor(1.0)))


def test_hypot_vmap():
    x, y = torch.randn(4, 5), torch.randn(4, 5)
    out = torch.vmap(hypot)(x, y)
    torch.testing.assert_close(out, (x * x + y * y).sqrt())


def test_clamp_away_from_zero_default_and_relative():
    x = torch.tensor([1e-30, 0.0, -0.0, 2.0], dtype=torch.float64)
    out = clamp_away_from_zero(x)
    tiny = torch.finfo(torch.float64).tiny
    assert out.tolist() == [1e-30, tiny, -tiny, 2.0]
    scale = torch.tensor([1e6, 1.0, 1.0, 1.0], dtype=torch.float64)
    rel = clamp_away_from_zero(x, torch.finfo(x.dtype).eps * scale)
    assert rel[0].item() == pytest.approx(2.220446049250313e-10)


def test_working_dtype_and_cast_back():
    assert working_dtype(torch.bfloat16) == torch.float32
    assert working_dtype(torch.float32) == torch.float32
    x = torch.tensor([1e6, -1e30, float("nan")])
    half = cast_back(x, torch.float16)
    assert half.dtype == torch.float16
    assert half[:2].tolist() == [65504.0, -65504.0] and torch.isnan(half[2])
    assert cast_back(x, torch.float32) is x


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_hypot_mixed_ranges_in_one_tensor(dtype):
    """Fast path and exact fix-up together: normal, overflowing, subnormal and zero entries."""
    info = torch.finfo(dtype)
    big, small = info.max / 4, info.tiny * 64
    x = torch.tensor([3.0, big, small, 0.0, 1e-3, float("nan"), float("inf")], dtype=dtype)
    y = torch.tensor([4.0, big, small, 0.0, 0.0, 1.0, 1.0], dtype=dtype)
    got = hypot(x, y)
    want = torch.hypot(x, y)  # torch's own scaled hypot as the reference
    torch.testing.assert_close(got, want, rtol=2 * info.eps, atol=0, equal_nan=True)
    assert got[1] > big and torch.isfinite(got[1])
    assert got[2] > 0 and got[3] == 0 and got[6] == float("inf")


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float32, torch.float64])
def test_power_of_two_scale_brings_magnitudes_into_half_open_unit_range(dtype):
    info = torch.finfo(dtype)
    mags = torch.tensor([3.0, 4.0, 0.75, info.tiny, info.max / 8], dtype=dtype)
    scale = power_of_two_scale(mags)
    ratio = mags / scale
    assert ((ratio >= 0.5) & (ratio < 1)).all(), ratio
    # exactly a power of two: its mantissa from frexp is 0.5
    assert (torch.frexp(scale).mantissa == 0.5).all()
    # hand-derived values: 3 -> 4, 4 -> 8, 0.75 -> 1
    assert scale[:3].tolist() == [4.0, 8.0, 1.0]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_power_of_two_scale_at_the_top_of_the_range_and_undefined_magnitudes(dtype):
    info = torch.finfo(dtype)
    mags = torch.tensor([info.max, 0.0, float("nan"), float("inf")], dtype=dtype)
    scale = power_of_two_scale(mags)
    assert torch.isfinite(scale).all()
    assert 1 <= float(mags[0] / scale[0]) < 2  # the largest finite power of two
    assert scale[1:].tolist() == [1.0, 1.0, 1.0]
    x = torch.tensor([2.5], dtype=dtype, requires_grad=True)
    assert not power_of_two_scale(x).requires_grad
