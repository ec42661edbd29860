"""Tests for torchgeo_cg.transforms.decompose."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

import torchgeo_cg.transforms.decompose as dec
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.transforms import (
    compose,
    decompose_affine,
    report_shapes,
    rotation,
    scale_x,
    scale_y,
    scaling,
    shear,
    translation,
)


def recompose(d):
    return compose(translation(d.offset), rotation(d.angle_degrees),
                   shear(d.shear, torch.zeros_like(d.shear)), scaling(d.scale_xy, per_axis=True))


def test_public_surface():
    assert set(dec.__all__) == {"AffineDecomposition", "decompose_affine"}


def test_round_trip_random_float64():
    gen = torch.Generator().manual_seed(0)
    m = torch.randn(1000, 3, 3, generator=gen, dtype=torch.float64) * 3
    m[:, 2] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    d = decompose_affine(m)
    assert (recompose(d) - m).abs().max() < 1e-10
    assert (d.scale_xy[:, 0] >= 0).all()
    assert (d.angle_degrees.abs() <= 180).all()


def test_recovers_known_parameters(device, dtype, tol):
    off = torch.tensor([[4.0, 14.0], [-1.0, 2.0]], device=device, dtype=dtype)
    ang = torch.tensor([-135.0, 30.0], device=device, dtype=dtype)
    sc = torch.tensor([[0.4, 0.8], [2.0, -0.5]], device=device, dtype=dtype)  # reflection in sy
    sh = torch.tensor([0.0, 0.7], device=device, dtype=dtype)
    m = compose(translation(off), rotation(ang), shear(sh, torch.zeros_like(sh)),
                scaling(sc, per_axis=True))
    d = decompose_affine(m)
    for got, want in zip(d, (off, ang, sc, sh)):
        assert got.dtype == dtype and got.device.type == device.type
        assert_close(got, want, scale=100)


def test_report_chains_round_trip():
    shapes = report_shapes(dtype=torch.float64)
    m = shapes.matrices[:7]
    assert (recompose(decompose_affine(m)) - m).abs().max() < 1e-10
    # hand-derived: F = T(4,14)·R(-135°)·Xs(0.4)·Ys(0.8) has no shear
    d = decompose_affine(m[5])
    assert_close(d.angle_degrees, torch.tensor(-135.0, dtype=torch.float64))
    assert_close(d.scale_xy, torch.tensor([0.4, 0.8], dtype=torch.float64))
    assert abs(float(d.shear)) < 1e-12
    # G's two-term shear chain comes back canonical but equal as a matrix
    g = compose(translation(torch.tensor([8.0, 8.0], dtype=torch.float64)),
                rotation(torch.tensor(22.5, dtype=torch.float64)),
                shear(torch.tensor(0.01, dtype=torch.float64), torch.tensor(1.05,
                                                                           dtype=torch.float64)),
                scale_y(torch.tensor(0.685, dtype=torch.float64)),
                scale_x(torch.tensor(0.95, dtype=torch.float64)))
    assert (recompose(decompose_affine(g)) - g).abs().max() < 1e-12


def test_singular_input_is_finite_with_finite_gradient():
    m = torch.zeros(3, 3, 3, dtype=torch.float64)
    m[:, 2, 2] = 1
    m[1, 0, 0] = 2.0  # rank 1: sy = 0
    m[2, 0, 1] = 1.0  # first column zero: sx = 0
    m.requires_grad_(True)
    d = decompose_affine(m)
    assert all(torch.isfinite(t).all() for t in d)
    assert_close(d.scale_xy[1].detach(), torch.tensor([2.0, 0.0], dtype=torch.float64))
    sum(t.sum() for t in d).backward()
    assert torch.isfinite(m.grad).all()


def test_gradcheck():
    gen = torch.Generator().manual_seed(1)
    m = torch.randn(4, 3, 3, generator=gen, dtype=torch.float64)
    m[:, 2] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    m.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: tuple(decompose_affine(x)), (m,))


@given(
    st.floats(-100, 100), st.floats(-100, 100), st.floats(-179.0, 179.0),
    st.floats(0.05, 20), st.floats(-20, 20).filter(lambda v: abs(v) > 0.05), st.floats(-5, 5),
)
def test_property_round_trip(tx, ty, angle, sx, sy, sh):
    d = dec.AffineDecomposition(torch.tensor([tx, ty], dtype=torch.float64),
                                torch.tensor(angle, dtype=torch.float64),
                                torch.tensor([sx, sy], dtype=torch.float64),
                                torch.tensor(sh, dtype=torch.float64))
    m = recompose(d)
    back = decompose_affine(m)
    assert (recompose(back) - m).abs().max() < 1e-10 * max(1.0, float(m.abs().max()))
    for got, want in zip(back, d):
        assert_close(got, want, rtol=1e-8, atol=1e-8)


def test_errors():
    with pytest.raises(ShapeError, match="matrix"):
        decompose_affine(torch.eye(2))
    with pytest.raises(TypeError, match="matrix"):
        decompose_affine(torch.eye(3, dtype=torch.long))
