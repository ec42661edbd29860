"""Autograd gradients, normals and the Eikonal loss."""

from __future__ import annotations

import pytest
import torch

from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.sdf.gradients import eikonal_loss, sdf_gradient, sdf_normal
from torchgeo_cg.sdf.primitives import Sphere, sphere, torus


def test_sphere_gradient_closed_form(device, dtype):
    p = torch.randn(2, 30, 3, device=device, dtype=dtype)
    g = sdf_gradient(sphere, p)
    assert g.shape == p.shape and g.dtype == dtype
    assert_close(g, p / p.norm(dim=-1, keepdim=True), scale=10)


def test_algebraic_torus_gradient_is_2s_times_normal():
    p = torch.randn(50, 3, dtype=torch.float64)
    g = sdf_gradient(lambda q: torus(q, 1.0, 0.3, exact=False), p)
    s = torus(p, 1.0, 0.3) + 0.3
    assert_close(g.norm(dim=-1), 2 * s)
    n = sdf_normal(lambda q: torus(q, 1.0, 0.3, exact=False), p)
    assert_close(n, sdf_gradient(lambda q: torus(q, 1.0, 0.3), p))


def test_eikonal_loss_values_and_training_gradient():
    g = torch.tensor([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]], requires_grad=True)
    assert_close(eikonal_loss(g, "none"), torch.tensor([16.0, 1.0]))
    assert_close(eikonal_loss(g), torch.tensor(8.5))
    assert_close(eikonal_loss(g, "sum"), torch.tensor(17.0))
    eikonal_loss(g).backward()
    assert torch.isfinite(g.grad).all()  # finite at the zero vector
    # second order: the loss of a learned field reaches its parameters
    model = Sphere(1.0)
    pts = torch.randn(20, 3)
    loss = eikonal_loss(sdf_gradient(lambda q: model(q) * 2.0, pts))
    loss.backward()
    assert model.center.grad is not None


def test_gradient_under_no_grad_and_constant_field():
    with torch.no_grad():
        g = sdf_gradient(sphere, torch.tensor([[0.0, 0.0, 2.0]]), create_graph=False)
    assert_close(g, torch.tensor([[0.0, 0.0, 1.0]]))
    assert_close(sdf_gradient(lambda q: torch.zeros(q.shape[:-1]), torch.ones(2, 3)),
                 torch.zeros(2, 3))


def test_bad_input():
    with pytest.raises(ValueError, match="reduction"):
        eikonal_loss(torch.zeros(2, 3), "max")
    with pytest.raises(ValueError, match="sdf_fn"):
        sdf_gradient(lambda q: q.sum(), torch.zeros(2, 3))
    with pytest.raises(TypeError, match="floating-point"):
        sdf_gradient(sphere, torch.zeros(2, 3, dtype=torch.long))
