"""Numeric edge cases across core, transforms (homogeneous/modules/decompose), curves
(bezier/parametric) and sdf (primitives/operators/grid/gradients/level_set): every
scale, float16, NaN, overflow, empty input, parameter validation and mixed dtypes."""

import math

import numpy as np
import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.grid import index_to_world, world_to_index
from torchgeo_cg.core.numerics import safe_norm
from torchgeo_cg.curves.bezier import bezier_length, bezier_normal, bezier_tangent
from torchgeo_cg.curves.parametric import circle, implicit_circle
from torchgeo_cg.sdf import primitives as P
from torchgeo_cg.sdf.gradients import eikonal_loss, sdf_gradient
from torchgeo_cg.sdf.grid import grid_interpolate, sample_grid
from torchgeo_cg.sdf.level_set import zero_level_set
from torchgeo_cg.sdf.operators import Rotate, rotate, union
from torchgeo_cg.transforms.decompose import decompose_affine
from torchgeo_cg.transforms.homogeneous import (
    compose,
    compose_trs,
    homography,
    inverse,
    rotation,
    scaling,
    transform_points,
)
from torchgeo_cg.transforms.modules import TRSTransform

F64 = torch.float64


# ----------------------------------------------------------------------------- scale


@pytest.mark.parametrize("s", [1e-300, 1e-9, 1.0, 1e9, 1e300])
def test_bezier_tangent_and_normal_are_unit_at_every_scale(s):
    """|t| was 0.3 at curve scale 1e-9 (safe_norm returned 0 below 1e-12)."""
    ctrl = torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]], dtype=F64)
    t = torch.linspace(0, 1, 7, dtype=F64)
    ref_t, ref_n = bezier_tangent(ctrl, t), bezier_normal(ctrl, t)
    tan, nor = bezier_tangent(ctrl * s, t), bezier_normal(ctrl * s, t)
    torch.testing.assert_close(tan.norm(dim=-1), torch.ones(7, dtype=F64))
    torch.testing.assert_close(tan, ref_t)
    torch.testing.assert_close(nor, ref_n)
    ctrl3 = torch.tensor([[0.0, 0.0, 0.0], [1.0, 2.0, 0.5], [3.0, 2.0, -1.0], [4.0, 0.0, 0.0]],
                         dtype=F64)
    torch.testing.assert_close(bezier_normal(ctrl3 * s, t), bezier_normal(ctrl3, t))


@pytest.mark.parametrize("s", [1e-7, 1e-30, 1e30])
def test_inverse_of_scaling_is_exact(s):
    """inverse(scaling(1e-7)) returned diag(1e5, 1e5, 0.01): the determinant test was absolute."""
    m = scaling(torch.tensor(s, dtype=F64))
    torch.testing.assert_close(inverse(m), scaling(torch.tensor(1 / s, dtype=F64)),
                               rtol=1e-15, atol=0)
    # conjugated (scaled) general matrices: inverse(S M S^-1) = S inverse(M) S^-1
    mat = compose_trs(torch.tensor([2.0, -1.0], dtype=F64), 30.0, 0.5)
    mat[..., 2, :2] = torch.tensor([0.1, -0.2], dtype=F64)
    sc, sc_inv = scaling(torch.tensor(s, dtype=F64)), scaling(torch.tensor(1 / s, dtype=F64))
    got = inverse(compose(sc, mat, sc_inv))
    torch.testing.assert_close(compose(sc_inv, got, sc), inverse(mat), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("s", [1e-6, 1e6])
def test_transform_points_scale_equivariant_with_perspective(s):
    h = homography(torch.tensor([0.9, 0.1, 3.0, -0.2, 1.1, -2.0, 0.01, 0.02], dtype=F64))
    pts = torch.randn(50, 2, dtype=F64) * 10
    sc, sc_inv = scaling(torch.tensor(s, dtype=F64)), scaling(torch.tensor(1 / s, dtype=F64))
    out = transform_points(compose(sc, h, sc_inv), pts * s)
    torch.testing.assert_close(out / s, transform_points(h, pts), rtol=1e-12, atol=0)


# ----------------------------------------------------------------------------- float16


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_low_precision_w_zero_and_singular_inverse_stay_finite(dtype):
    """float16: the 1e-8/1e-12 constants underflowed: +-inf at w = 0, NaN for singular."""
    h = homography(torch.tensor([1.0, 0, 0, 0, 1, 0, 0.5, 0])).to(dtype)
    pts = torch.tensor([[-2.0, 1.0], [2.0, 4.0]], dtype=dtype)  # w = 0 and w = 2
    out = transform_points(h, pts)
    assert out.dtype == dtype and torch.isfinite(out).all()
    # "at infinity": +-(x, y) / (eps * |bottom row|), sign kept (1/eps is 1024 in float16)
    assert out[0, 0] < -50 and out[0, 1] > 50
    torch.testing.assert_close(out[1].float(), torch.tensor([1.0, 2.0]))
    singular = torch.tensor([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]], dtype=dtype)
    inv = inverse(singular)
    assert inv.dtype == dtype and torch.isfinite(inv).all()
    good = compose_trs(torch.tensor([1.0, 2.0]), 30.0, 2.0)
    torch.testing.assert_close(inverse(good.to(dtype)).float(), inverse(good), rtol=1e-2,
                               atol=1e-2)


def test_singular_inverse_float64_finite_no_nan():
    for m in (torch.zeros(3, 3, dtype=F64),
              torch.tensor([[10.0, 0, 0], [0, 10.0, 0], [0, 0, 0]], dtype=F64),
              torch.tensor([[1.0, 2, 3], [2, 4, 6], [1, 1, 1]], dtype=F64)):
        assert torch.isfinite(inverse(m)).all()


# ----------------------------------------------------------------------------- NaN


def test_nan_propagates():
    nan = float("nan")
    m = torch.full((3, 3), nan, dtype=F64)
    d = decompose_affine(m)
    assert all(torch.isnan(x).all() for x in d)
    assert torch.isnan(inverse(m)).all()
    assert torch.isnan(transform_points(m, torch.ones(2, 2, dtype=F64))).all()
    pts = torch.tensor([[nan, 0.0, 0.0], [0.2, 0.3, 0.4]], dtype=F64)
    assert torch.isnan(P.sphere(pts)).tolist() == [True, False]
    assert torch.isnan(P.box(pts)).tolist() == [True, False]


def test_grid_interpolate_nan_inf_queries_and_nan_grid():
    """A NaN or inf query point (or NaN origin/spacing) returned a finite 0.42."""
    vol = sample_grid(lambda p: p[:, 0] + 2 * p[:, 2], 5, (0.0, 2.0), dtype=F64)
    inf, nan = float("inf"), float("nan")
    pts = torch.tensor([[nan, 0.5, 0.5], [inf, 0.5, 0.5], [-inf, 0.5, 0.5], [0.5, 0.5, 0.5]],
                       dtype=F64)
    out = grid_interpolate(vol, pts)
    assert torch.isnan(out[0])
    # +-inf read the border value, as every point outside the bounds does
    torch.testing.assert_close(out[1:], torch.tensor([3.0, 1.0, 1.5], dtype=F64))
    for origin, spacing in ((torch.tensor([nan, 0.0, 0.0]), vol.spacing),
                            (vol.origin, torch.tensor([0.5, nan, 0.5]))):
        got = grid_interpolate(vol.values, pts[3:], origin.to(F64), spacing.to(F64))
        assert torch.isnan(got).all()


# ----------------------------------------------------------------------------- overflow


@pytest.mark.parametrize("fn", [P.sphere, P.box, P.capsule, P.plane, P.torus])
def test_float32_primitives_finite_at_2e19(fn):
    """Float32 SDF primitives gave inf at |p| ~ 2e19: the sum of squares overflowed."""
    p64 = torch.tensor([[2e19, 2e19, 2e19], [-2e19, 1e19, 3e19]], dtype=F64)
    got = fn(p64.float())
    assert torch.isfinite(got).all()
    torch.testing.assert_close(got.double(), fn(p64), rtol=1e-6, atol=0)


def test_float32_2d_primitives_and_eikonal_at_2e19():
    p = torch.tensor([[2e19, 2e19], [-3e19, 1e19]])
    for fn in (P.circle, P.rectangle, P.annulus):
        torch.testing.assert_close(fn(p).double(), fn(p.double()), rtol=1e-6, atol=0)
    p3 = torch.tensor([[2e19, 2e19, 2e19]])
    grads = sdf_gradient(P.sphere, p3, create_graph=False)
    torch.testing.assert_close(grads, torch.full((1, 3), 3**-0.5))
    assert eikonal_loss(grads).item() == pytest.approx(0.0, abs=1e-6)
    assert eikonal_loss(torch.tensor([[2e19, 0.0, 0.0]]), reduction="none").isinf().all()
    assert torch.isfinite(safe_norm(torch.tensor([[2e19, 2e19, 2e19]]))).all()


def test_implicit_circle_no_intermediate_overflow():
    """(x^2 + y^2) - r^2 overflows in float32 although the value is finite."""
    xy = torch.tensor([[1.5e19, 1.5e19]])
    r = 2.1e19
    want = 2 * 1.5e19**2 - r * r  # 9e36, finite in float32
    got = implicit_circle(xy, radius=r)
    assert torch.isfinite(got).all()
    assert got.item() == pytest.approx(want, rel=1e-5)


# ----------------------------------------------------------------------------- empty


def test_eikonal_loss_of_no_points_is_zero_not_nan():
    g = torch.zeros(0, 3)
    assert eikonal_loss(g).item() == 0.0
    assert eikonal_loss(g, reduction="sum").item() == 0.0
    assert eikonal_loss(g, reduction="none").shape == (0,)
    assert eikonal_loss(torch.zeros(4, 0, 3), reduction="none").shape == (4, 0)


# ----------------------------------------------------------------------------- validation


@pytest.mark.parametrize("scale", [0.0, -1.0, torch.tensor([1.0, 0.0])])
def test_gyroid_scale_must_be_positive(scale):
    with pytest.raises(ValueError, match="scale"):
        P.gyroid(torch.zeros(2, 2, 3), scale=scale)


@pytest.mark.parametrize("spacing", [[0.5, 0.0, 0.5], [0.5, -1.0, 0.5]])
def test_spacing_must_be_positive(spacing):
    vol = sample_grid(P.sphere, 4)
    pts = torch.zeros(2, 3)
    with pytest.raises(ValueError, match="spacing"):
        world_to_index(pts, torch.zeros(3), torch.tensor(spacing))
    with pytest.raises(ValueError, match="spacing"):
        index_to_world(pts, torch.zeros(3), spacing)
    with pytest.raises(ValueError, match="spacing"):
        grid_interpolate(vol.values, pts, vol.origin, torch.tensor(spacing))
    with pytest.raises(ValueError, match="spacing"):
        zero_level_set(vol.values, vol.origin, torch.tensor(spacing))


@pytest.mark.parametrize("kwargs, name", [({"max_depth": -1}, "max_depth"),
                                          ({"max_depth": 1.5}, "max_depth"),
                                          ({"rtol": 0.0}, "rtol"), ({"rtol": -1e-3}, "rtol")])
def test_bezier_length_parameters_validated(kwargs, name):
    """bezier_length(max_depth=-1) returned 0."""
    with pytest.raises(ValueError, match=name):
        bezier_length(torch.tensor([[0.0, 0.0], [1.0, 1.0]]), **kwargs)


# ----------------------------------------------------------------------------- dtypes


def test_mixed_dtypes_name_both_arguments():
    """compose/compose_trs/TRSTransform raised raw matmul errors on mixed dtypes."""
    a, b = torch.eye(3), torch.eye(3, dtype=F64)
    with pytest.raises(TypeError, match=r"matrices\[1\] is torch.float64.*matrices\[0\]"):
        compose(a, b)
    off = torch.zeros(2)
    with pytest.raises(TypeError, match="angle is torch.float64.*offset is torch.float32"):
        compose_trs(off, torch.tensor(30.0, dtype=F64), 1.0)
    with pytest.raises(TypeError, match="scale is torch.float64.*offset is torch.float32"):
        compose_trs(off, 30.0, torch.tensor(2.0, dtype=F64))
    with pytest.raises(TypeError, match="angle is torch.float64.*offset"):
        TRSTransform(off, torch.tensor(30.0, dtype=F64), torch.tensor(1.0))
    with pytest.raises(TypeError, match="sdf.1. is torch.float64.*sdf.0. is torch.float32"):
        union(torch.zeros(3), torch.zeros(3, dtype=F64))


def test_rotate_parameters_keep_their_dtype():
    """rotate/Rotate raised a raw matmul error for float64 points and a float32 matrix;
    the rule of a shape's parameters: a tensor keeps its dtype (TypeError naming both),
    numbers and lists take the points' dtype."""
    rot = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    pts = torch.randn(6, 3, dtype=F64)
    want = P.capsule(pts @ rot.double())
    with pytest.raises(TypeError, match="world_from_local is torch.float32.*points is .*float64"):
        rotate(P.capsule, rot)(pts)
    got = rotate(P.capsule, rot.double())(pts)
    assert got.dtype == F64
    torch.testing.assert_close(got, want)
    torch.testing.assert_close(rotate(P.capsule, rot.tolist())(pts), want)
    module = Rotate(P.Capsule(dtype=F64), rot)  # module state is float32: the one rule
    with pytest.raises(TypeError, match="float32"):
        module(pts)
    torch.testing.assert_close(module.double()(pts), want)


def test_numpy_scalars_and_arrays_accepted_uniformly():
    """np.float32 angles, np.int64 degrees and numpy spacing were rejected unevenly."""
    ref = rotation(torch.tensor(30.0))
    torch.testing.assert_close(rotation(np.float32(30.0)), ref)
    torch.testing.assert_close(rotation(np.int64(30)), ref)
    torch.testing.assert_close(rotation(np.float64(30.0)).float(), ref)
    off = torch.tensor([1.0, 2.0])
    torch.testing.assert_close(compose_trs(off, np.float32(30.0), np.int64(2)),
                               compose_trs(off, 30.0, 2.0))
    pts = torch.rand(5, 3)
    spacing = np.array([0.5, 0.25, 1.0])
    torch.testing.assert_close(world_to_index(pts, np.zeros(3), spacing),
                               pts / torch.tensor([0.5, 0.25, 1.0]))
    t = torch.linspace(0, math.pi, 5)
    torch.testing.assert_close(circle(t, np.array([1.0, 2.0]), np.float32(3.0)),
                               circle(t, (1.0, 2.0), 3.0))
    torch.testing.assert_close(P.sphere(pts, np.float32(0.5), np.zeros(3)), P.sphere(pts, 0.5))
    with pytest.raises(TypeError, match="angle: expected a float tensor or a number, got bool"):
        rotation(True)
    with pytest.raises(ShapeError, match="spacing"):
        world_to_index(pts, np.zeros(3), np.ones(2))
