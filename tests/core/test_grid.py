"""THE grid convention's shared pieces: the edge fraction of marching squares and cubes."""

from __future__ import annotations

import pytest
import torch

from torchgeo_cg.core.grid import edge_fraction


def test_edge_fraction_matches_the_clamped_quotient():
    f1 = torch.tensor([-1.0, 0.0, 2.0, -3.0], dtype=torch.float64)
    f2 = torch.tensor([3.0, 2.0, -2.0, -1.0], dtype=torch.float64)
    iso = torch.tensor([0.0, 0.0, 1.0, -2.5], dtype=torch.float64)
    delta = 1e-3
    want = ((iso - f1) / (f2 - f1)).clamp(delta, 1 - delta)
    torch.testing.assert_close(edge_fraction(f1, f2, iso, delta), want)


@pytest.mark.grad
def test_edge_fraction_gradient_is_the_quotient_rule_and_scale_free():
    f1 = torch.tensor([-1.0, -0.5], dtype=torch.float64, requires_grad=True)
    f2 = torch.tensor([3.0, 1.5], dtype=torch.float64, requires_grad=True)
    iso = torch.tensor([0.2, 0.1], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b, c: edge_fraction(a, b, c, 1e-3), (f1, f2, iso))
    # at a field scale of 1e-200 autograd's -num / den**2 would overflow; ours stays exact
    s = 1e-200
    a, b, c = (x.detach().mul(s).requires_grad_() for x in (f1, f2, iso))
    edge_fraction(a, b, c, 1e-3).sum().backward()
    f1.grad = None
    edge_fraction(f1, f2, iso, 1e-3).sum().backward()
    torch.testing.assert_close(a.grad * s, f1.grad)
    assert torch.isfinite(b.grad).all() and torch.isfinite(c.grad).all()


def test_edge_fraction_has_zero_gradient_where_clamped_and_survives_equal_ends():
    f1 = torch.tensor([0.0, 1.0], dtype=torch.float64, requires_grad=True)
    f2 = torch.tensor([1.0, 1.0], dtype=torch.float64, requires_grad=True)
    t = edge_fraction(f1, f2, torch.zeros(2, dtype=torch.float64), 1e-3)
    t.sum().backward()
    assert t[0] == 1e-3 and f1.grad[0] == 0 and f2.grad[0] == 0
    assert torch.isfinite(t).all() and torch.isfinite(f1.grad).all()
