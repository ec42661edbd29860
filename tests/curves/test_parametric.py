"""Parametric and implicit 2D curves: hand values, consistency between the two forms."""

from __future__ import annotations

import math

import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.curves import (
    circle,
    cycloid,
    figure_eight_implicit,
    figure_eight_parametric,
    grid_2d,
    implicit_circle,
)


def test_circle_points_lie_on_implicit_circle(device, dtype, tol):
    t = torch.linspace(0, 2 * math.pi, 50, device=device, dtype=dtype)
    center = torch.tensor([[1.0, -2.0], [0.0, 0.5]], device=device, dtype=dtype)
    radius = torch.tensor([3.0, 0.5], device=device, dtype=dtype)
    points = circle(t, center, radius)
    assert points.shape == (2, 50, 2)
    values = implicit_circle(points, center[:, None, :], radius[:, None])
    assert_close(values, torch.zeros_like(values), atol=1e-5 if dtype == torch.float32 else 1e-12)
    assert_close(points[:, 0], center + torch.stack([radius, torch.zeros_like(radius)], -1))


def test_implicit_circle_sign_convention():
    xy = torch.tensor([[0.0, 0.0], [2.0, 0.0], [5.0, 5.0]])
    values = implicit_circle(xy, (0.0, 0.0), 2.0)
    assert values[0] < 0 and values[1] == 0 and values[2] > 0


def test_cycloid_by_hand_and_rolling_property():
    t = torch.tensor([0.0, math.pi / 2, math.pi, 2 * math.pi, 4 * math.pi], dtype=torch.float64)
    out = cycloid(t, 2.0)
    expected = torch.tensor([[0.0, 0.0], [2 * (math.pi / 2 - 1), 2.0], [2 * math.pi, 4.0],
                             [4 * math.pi, 0.0], [8 * math.pi, 0.0]], dtype=torch.float64)
    assert_close(out, expected, atol=1e-12, rtol=0)
    # One arch has length 8 R (a classic result): check with fine polyline.
    fine = cycloid(torch.linspace(0, 2 * math.pi, 200001, dtype=torch.float64), 1.5)
    length = (fine[1:] - fine[:-1]).norm(dim=-1).sum()
    assert abs(float(length) - 12.0) < 1e-6


def test_figure_eight_two_ways_agree():
    t = torch.linspace(0, 4 * math.pi, 400, dtype=torch.float64)
    points = figure_eight_parametric(t, 5.0)
    values = figure_eight_implicit(points, 5.0)
    assert values.abs().max() < 1e-9
    # Continuous (small steps everywhere, including the stitch at 2 pi) and periodic.
    steps = (points[1:] - points[:-1]).norm(dim=-1)
    assert steps.max() < 2 * 5.0 * (4 * math.pi / 399)
    assert_close(figure_eight_parametric(t + 4 * math.pi, 5.0), points, atol=1e-9, rtol=0)
    # G1 at the origin: both halves leave heading +y.
    h = 1e-6
    for start in (0.0, 2 * math.pi):
        s = torch.tensor([start, start + h], dtype=torch.float64)
        p = figure_eight_parametric(s, 5.0)
        direction = (p[1] - p[0]) / h
        assert_close(direction / direction.norm(), torch.tensor([0.0, 1.0], dtype=torch.float64),
                     atol=1e-5, rtol=0)


def test_figure_eight_implicit_is_singular_at_the_crossing():
    xy = torch.zeros(1, 2, dtype=torch.float64, requires_grad=True)
    value = figure_eight_implicit(xy)
    (grad,) = torch.autograd.grad(value.sum(), xy)
    assert float(value.detach()) == 0.0 and float(grad.abs().max()) == 0.0  # f = 0 and grad f = 0


def test_grid_convention_and_factory_kwargs():
    grid = grid_2d(2000, dtype=torch.float64)
    assert grid.shape == (2000, 2000, 2) and grid.dtype == torch.float64
    assert_close(grid[0, 0], torch.tensor([-10.0, -10.0], dtype=torch.float64))
    assert_close(grid[1, 0] - grid[0, 0], torch.tensor([20 / 1999, 0.0], dtype=torch.float64))
    assert grid_2d(3).dtype == torch.get_default_dtype()


def test_gradients_and_gradcheck():
    t = torch.rand(6, dtype=torch.float64, requires_grad=True)
    r = torch.tensor(1.5, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b: circle(a, (0.0, 1.0), b), (t, r))
    assert torch.autograd.gradcheck(cycloid, (t, r))
    assert torch.autograd.gradcheck(figure_eight_parametric, (t * 10, r))
    xy = torch.randn(5, 2, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(figure_eight_implicit, (xy, r))


def test_bad_input():
    with pytest.raises(ShapeError, match="xy"):
        implicit_circle(torch.zeros(4, 3))
    with pytest.raises(ShapeError, match="center"):
        circle(torch.zeros(4), center=(0.0, 1.0, 2.0))
    with pytest.raises(TypeError, match="radius"):
        cycloid(torch.zeros(4), radius="big")
    with pytest.raises(TypeError, match="t: expected a floating-point"):
        circle(torch.arange(4))
    with pytest.raises(ValueError, match="n: expected an int >= 2"):
        grid_2d(1)
