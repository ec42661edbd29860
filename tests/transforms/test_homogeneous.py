"""Homogeneous 2D transforms: hand-derived values, live kornia, gradcheck, properties, errors."""

import math

import kornia
import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.transforms import (
    compose,
    compose_trs,
    homography,
    inverse,
    rotation,
    scale_x,
    scale_y,
    scaling,
    shear,
    transform_points,
    translation,
)

F64 = torch.float64


def t64(*x):
    """A float64 tensor: 0-d for one number, 1-d for several."""
    return torch.tensor(x[0] if len(x) == 1 else x, dtype=F64)


# ---------------------------------------------------------------- hand-derived values
def test_matrices_match_report_tables(dtype, device):
    kw = {"dtype": dtype, "device": device}
    assert_close(
        translation(torch.tensor([5.0, 1.0], **kw)),
        [[1, 0, 5], [0, 1, 1], [0, 0, 1]],
    )
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    assert_close(rotation(torch.tensor(30.0, **kw)), [[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert_close(
        rotation(torch.tensor(math.pi / 6, **kw), degrees=False), [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    )
    assert_close(scaling(torch.tensor(2.5, **kw)), [[2.5, 0, 0], [0, 2.5, 0], [0, 0, 1]])
    assert_close(scaling(torch.tensor([1.2, 0.4], **kw)), [[1.2, 0, 0], [0, 0.4, 0], [0, 0, 1]])
    assert_close(scale_x(torch.tensor(0.4, **kw)), [[0.4, 0, 0], [0, 1, 0], [0, 0, 1]])
    assert_close(scale_y(torch.tensor(0.8, **kw)), [[1, 0, 0], [0, 0.8, 0], [0, 0, 1]])
    assert_close(
        shear(torch.tensor(0.01, **kw), torch.tensor(1.05, **kw)),
        [[1, 0.01, 0], [1.05, 1, 0], [0, 0, 1]],
    )
    h = torch.tensor([0.27, 0, -0.85, -0.25, -0.2, 5.65, -0.02, -0.09], **kw)
    assert_close(homography(h), [[0.27, 0, -0.85], [-0.25, -0.2, 5.65], [-0.02, -0.09, 1]])
    for m in (translation(torch.zeros(2, **kw)), rotation(torch.tensor(1.0, **kw))):
        assert m.dtype == dtype and m.device.type == device.type


def test_rotation_is_counter_clockwise_y_up():
    # (1, 0) rotated by +90° lands on (0, 1); by -90° on (0, -1)
    p = t64(1.0, 0.0)[None]
    assert_close(transform_points(rotation(t64(90.0)), p), [[0.0, 1.0]], atol=1e-15)
    assert_close(transform_points(rotation(t64(-90.0)), p), [[0.0, -1.0]], atol=1e-15)


def test_scaling_per_axis_inference_and_override():
    two = t64(2.0, 3.0)
    assert_close(scaling(two)[..., :2, :2], [[2, 0], [0, 3]])  # (2,) read as (sx, sy)
    batch = scaling(two, per_axis=False)  # a batch of two uniform factors
    assert batch.shape == (2, 3, 3)
    assert_close(batch[1, :2, :2], [[3, 0], [0, 3]])


def test_compose_trs_pre_and_post_multiplied_hand_case():
    # E = T(2,10)·R(45°)·S(0.5) from the report; uniform scale commutes with rotation
    m = compose_trs(t64(2.0, 10.0), 45.0, 0.5)
    r = 0.5 / math.sqrt(2)
    assert_close(m, [[r, -r, 2], [r, r, 10], [0, 0, 1]])
    assert_close(compose_trs(t64(2.0, 10.0), 45.0, 0.5, row_vectors=True), m.mT)


def test_transform_points_perspective_divide_hand_case():
    h = homography(t64(1, 0, 0, 0, 1, 0, 0.5, 0))  # w = 0.5 x + 1
    pts = t64(2.0, 4.0, 0.0, 3.0).reshape(2, 2)
    assert_close(transform_points(h, pts), [[1.0, 2.0], [0.0, 3.0]])


def test_compose_is_left_to_right():
    a, b, c = translation(t64(1.0, 2.0)), rotation(t64(20.0)), scaling(t64(1.5, 0.5))
    torch.testing.assert_close(compose(a, b, c), a @ b @ c)
    torch.testing.assert_close(compose(a), a)


def test_broadcasting_between_matrix_and_points():
    m = rotation(torch.linspace(0, 90, 5, dtype=F64))  # (5, 3, 3)
    p = torch.randn(7, 2, dtype=F64)  # (7, 2)
    out = transform_points(m, p)
    assert out.shape == (5, 7, 2)
    ref = torch.stack([transform_points(m[i], p) for i in range(5)])
    torch.testing.assert_close(out, ref)


# ---------------------------------------------------------------- against kornia, live
def test_transform_points_matches_kornia(dtype, device, tol):
    g = torch.Generator().manual_seed(0)
    m = (torch.eye(3) + 0.1 * torch.randn(4, 3, 3, generator=g)).to(device, dtype)
    p = torch.randn(4, 50, 2, generator=g).to(device, dtype)
    ours = transform_points(m, p)
    ref = kornia.geometry.linalg.transform_points(m, p)
    torch.testing.assert_close(ours, ref, **tol)


def test_kornia_rotation_convention():
    """kornia's get_rotation_matrix2d(c, a, s) == T(c)·R(-a)·S(s)·T(-c) in our terms.

    kornia works in pixel coordinates (y down): its positive angle is counter-clockwise
    *as displayed*, which is our clockwise (y up). It also rotates about ``center``.
    """
    c, a, s = t64(1.5, -2.0)[None], t64(30.0)[None], t64(2.0, 0.5)[None]
    ref = kornia.geometry.transform.get_rotation_matrix2d(c, a, s)  # (1, 2, 3)
    ours = compose(translation(c), rotation(-a), scaling(s), translation(-c))
    torch.testing.assert_close(ours[:, :2], ref)


def test_kornia_shear_convention():
    """kornia's get_shear_matrix2d(c, sx, sy) takes angles in radians, negative tangents,
    x-shear first: T(c)·SH(0, -tan sy)·SH(-tan sx, 0)·T(-c). Our shear(a, b) is the report's
    single matrix [[1, a], [b, 1]]; the two agree only when one factor is 0."""
    c, sx, sy = t64(1.5, -2.0)[None], t64(0.3)[None], t64(-0.7)[None]
    ref = kornia.geometry.transform.get_shear_matrix2d(c, sx, sy)
    zero = torch.zeros_like(sx)
    ours = compose(
        translation(c), shear(zero, -torch.tan(sy)), shear(-torch.tan(sx), zero), translation(-c)
    )
    torch.testing.assert_close(ours, ref)
    # single-axis shear about the origin equals ours exactly
    ref_x = kornia.geometry.transform.get_shear_matrix2d(torch.zeros(1, 2, dtype=F64), sx, zero)
    torch.testing.assert_close(shear(-torch.tan(sx), zero), ref_x)


def test_kornia_affine_convention():
    """kornia's get_affine_matrix2d negates its angle, so its positive angle is our
    counter-clockwise rotation: T(t)·T(c)·R(a)·S(s)·T(-c)·shear_kornia."""
    t, c, s, a = t64(3.0, 4.0)[None], t64(1.5, -2.0)[None], t64(2.0, 0.5)[None], t64(30.0)[None]
    sx, sy = t64(0.3)[None], t64(-0.7)[None]
    ref = kornia.geometry.transform.get_affine_matrix2d(t, c, s, a, sx, sy)
    zero = torch.zeros_like(sx)
    kshear = compose(
        translation(c), shear(zero, -torch.tan(sy)), shear(-torch.tan(sx), zero), translation(-c)
    )
    ours = compose(translation(t), translation(c), rotation(a), scaling(s), translation(-c), kshear)
    torch.testing.assert_close(ours, ref)


def test_inverse_matches_torch_linalg(dtype, device, tol):
    g = torch.Generator().manual_seed(1)
    m = (torch.eye(3) + 0.3 * torch.randn(6, 3, 3, generator=g)).to(device, dtype)
    torch.testing.assert_close(
        inverse(m), torch.linalg.inv(m), rtol=tol["rtol"] * 100, atol=tol["atol"] * 100
    )


def test_row_vector_form_matches_numpy():
    """(T·S·R·p)ᵀ = pᵀ·Rᵀ·Sᵀ·Tᵀ, checked with plain NumPy row vectors."""
    pre = compose_trs(t64(4.0, 14.0), -135.0, t64(0.4, 0.8)).numpy()
    post = compose_trs(t64(4.0, 14.0), -135.0, t64(0.4, 0.8), row_vectors=True).numpy()
    rows = np.array([[0.0, 0.0, 1.0], [1.0, 2.0, 1.0], [-3.0, 0.5, 1.0]])
    np.testing.assert_allclose(rows @ post, (pre @ rows.T).T, atol=1e-12)


# ---------------------------------------------------------------- w ≈ 0
def test_points_at_infinity_are_finite_forward_and_backward(dtype, device):
    m = homography(torch.tensor([1, 0, 0, 0, 1, 0, 1, 0], dtype=dtype, device=device))
    m.requires_grad_(True)
    p = torch.tensor(
        [[-1.0, 2.0], [-1.0, 0.0], [3.0, 1.0]], dtype=dtype, device=device, requires_grad=True
    )  # w = x + 1 = 0 for the first two
    out = transform_points(m, p)
    out.sum().backward()
    assert torch.isfinite(out).all()
    assert torch.isfinite(m.grad).all() and torch.isfinite(p.grad).all()
    assert_close(out[2], [0.75, 0.25])


def test_nan_in_nan_out():
    p = t64(float("nan"), 1.0, 2.0, 3.0).reshape(2, 2)
    out = transform_points(rotation(t64(10.0)), p)
    assert torch.isnan(out[0]).all() and torch.isfinite(out[1]).all()
    assert torch.isnan(translation(t64(float("nan"), 0.0))[0, 2])


# ---------------------------------------------------------------- gradcheck (float64)
def test_gradcheck_all_builders():
    gc = torch.autograd.gradcheck
    assert gc(translation, (torch.randn(3, 2, dtype=F64, requires_grad=True),))
    assert gc(rotation, (torch.randn(3, dtype=F64, requires_grad=True),))
    assert gc(
        lambda a: rotation(a, degrees=False), (torch.randn(3, dtype=F64, requires_grad=True),)
    )
    assert gc(scaling, (torch.rand(3, 2, dtype=F64, requires_grad=True),))
    assert gc(scale_x, (torch.rand(3, dtype=F64, requires_grad=True),))
    assert gc(scale_y, (torch.rand(3, dtype=F64, requires_grad=True),))
    assert gc(
        shear,
        (
            torch.randn(3, dtype=F64, requires_grad=True),
            torch.randn(3, dtype=F64, requires_grad=True),
        ),
    )
    assert gc(homography, (torch.randn(2, 8, dtype=F64, requires_grad=True),))
    assert gc(
        compose_trs,
        (
            torch.randn(2, 2, dtype=F64, requires_grad=True),
            torch.randn(2, dtype=F64, requires_grad=True),
            torch.rand(2, dtype=F64, requires_grad=True) + 0.5,
        ),
    )


def test_gradcheck_transform_points_compose_inverse():
    g = torch.Generator().manual_seed(2)
    m = (torch.eye(3) + 0.1 * torch.randn(2, 3, 3, generator=g)).to(F64).requires_grad_()
    p = torch.randn(2, 5, 2, generator=g).to(F64).requires_grad_()
    assert torch.autograd.gradcheck(transform_points, (m, p))
    m2 = (torch.eye(3) + 0.1 * torch.randn(2, 3, 3, generator=g)).to(F64).requires_grad_()
    assert torch.autograd.gradcheck(compose, (m, m2))
    assert torch.autograd.gradcheck(inverse, (m,))


# ---------------------------------------------------------------- hypothesis properties
finite = st.floats(-50, 50, allow_nan=False, allow_infinity=False)
angles = st.floats(-720, 720, allow_nan=False)
scales = st.floats(0.1, 5.0)


def _affine(draw_t, draw_a, draw_s):
    return compose_trs(t64(*draw_t), t64(draw_a), t64(draw_s))


@given(st.lists(st.tuples(st.tuples(finite, finite), angles, scales), min_size=3, max_size=3))
def test_compose_is_associative(params):
    a, b, c = (_affine(*p) for p in params)
    torch.testing.assert_close(
        compose(compose(a, b), c), compose(a, compose(b, c)), rtol=1e-9, atol=1e-9
    )


@given(
    st.tuples(finite, finite),
    angles,
    st.tuples(scales, scales),
    st.lists(st.tuples(finite, finite), min_size=1, max_size=6),
)
def test_inverse_round_trip(offset, angle, scale, pts):
    m = compose_trs(t64(*offset), t64(angle), t64(*scale))
    p = torch.tensor(pts, dtype=F64)
    torch.testing.assert_close(
        transform_points(inverse(m), transform_points(m, p)), p, rtol=1e-9, atol=1e-8
    )
    torch.testing.assert_close(compose(m, inverse(m)), torch.eye(3, dtype=F64), rtol=0, atol=1e-9)


@given(
    st.tuples(finite, finite),
    angles,
    st.tuples(scales, scales),
    st.lists(st.tuples(finite, finite), min_size=1, max_size=6),
)
def test_pre_and_post_multiplied_forms_agree(offset, angle, scale, pts):
    """(T·S·R·p)ᵀ = pᵀ·Rᵀ·Sᵀ·Tᵀ (report eqs. 3 and 4)."""
    pre = compose_trs(t64(*offset), t64(angle), t64(*scale))
    post = compose_trs(t64(*offset), t64(angle), t64(*scale), row_vectors=True)
    rows = torch.cat([torch.tensor(pts, dtype=F64), torch.ones(len(pts), 1, dtype=F64)], dim=1)
    torch.testing.assert_close((pre @ rows.mT).mT, rows @ post, rtol=1e-12, atol=1e-10)


# ---------------------------------------------------------------- error paths
@pytest.mark.parametrize(
    "call, exc, match",
    [
        (
            lambda: translation(torch.zeros(4)),
            ShapeError,
            r"offset: expected shape \(\*, 2\) or \(\*, 3\), got \(4\)",
        ),
        (
            lambda: translation(torch.zeros(2, dtype=torch.long)),
            TypeError,
            "offset: expected a floating",
        ),
        (lambda: rotation(torch.tensor(1)), TypeError, "angle: expected a floating"),
        (lambda: rotation("90"), TypeError, "angle: expected a float tensor or a number, got str"),
        (
            lambda: scaling(torch.zeros(4, 3), per_axis=True),
            ShapeError,
            r"factor: expected shape \(\*, 2\)",
        ),
        (lambda: shear(torch.tensor([1.0]), torch.tensor(2)), TypeError, "b: expected a floating"),
        (lambda: homography(torch.zeros(9)), ShapeError, r"h: expected shape \(\*, 8\), got \(9\)"),
        (lambda: compose(), ValueError, "at least one"),
        (lambda: compose(torch.eye(3), torch.eye(2)), ShapeError, r"matrices\[1\]: expected shape"),
        (
            lambda: transform_points(torch.eye(3), torch.zeros(5, 3)),
            ShapeError,
            r"points: expected shape \(\*, N, 2\), got \(5, 3\)",
        ),
        (
            lambda: transform_points(torch.eye(2), torch.zeros(5, 2)),
            ShapeError,
            r"matrix: expected shape \(\*, 3, 3\)",
        ),
        (
            lambda: transform_points(torch.eye(3), torch.zeros(5, 2, dtype=torch.int64)),
            TypeError,
            "points: expected a floating",
        ),
        (
            lambda: transform_points(torch.eye(3), torch.zeros(5, 2, dtype=F64)),
            TypeError,
            "matrix is torch.float32",
        ),
        (
            lambda: transform_points(torch.eye(3).expand(4, 3, 3), torch.zeros(3, 5, 2)),
            ShapeError,
            r"batch dims do not broadcast: matrix \(4\), points \(3\)",
        ),
        (
            lambda: compose(torch.eye(3).expand(4, 3, 3), torch.eye(3).expand(2, 3, 3)),
            ShapeError,
            r"matrices\[0\] \(4\), matrices\[1\] \(2\)",
        ),
        (
            lambda: shear(torch.zeros(3), torch.zeros(2)),
            ShapeError,
            r"a \(3\), b \(2\)",
        ),
        (
            lambda: compose_trs(torch.zeros(3, 2), torch.zeros(2), 1.0),
            ShapeError,
            r"offset \(3\), angle \(2\)",
        ),
        (
            lambda: inverse(torch.zeros(3, 4)),
            ShapeError,
            r"matrix: expected shape \(\*, 3, 3\) or \(\*, 4, 4\), got \(3, 4\)",
        ),
        (
            lambda: compose_trs(torch.zeros(2), torch.tensor(1), 1.0),
            TypeError,
            "angle: expected a floating",
        ),
    ],
)
def test_error_paths(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_singular_inverse_is_finite():
    out = inverse(torch.zeros(3, 3, dtype=F64))
    assert torch.isfinite(out).all()
