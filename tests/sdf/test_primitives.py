"""Primitives against closed forms, brute force, gradcheck, Eikonal property and modules."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.sdf import primitives as P
from torchgeo_cg.sdf.gradients import sdf_gradient


def _box_reference(p: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance to an axis-aligned box written from the definition (numpy)."""
    inside = np.all(np.abs(p) <= b, axis=-1)
    outside_d = np.linalg.norm(p - np.clip(p, -b, b), axis=-1)
    inside_d = -np.min(b - np.abs(p), axis=-1)
    return np.where(inside, inside_d, outside_d)


def test_sphere_closed_form(device, dtype, tol):
    p = torch.randn(4, 50, 3, device=device, dtype=dtype)
    c = torch.tensor([0.5, -1.0, 2.0], device=device, dtype=dtype)
    r = torch.rand(4, device=device, dtype=dtype) + 0.5
    out = P.sphere(p, r, c)
    assert out.dtype == dtype and out.device == p.device and out.shape == (4, 50)
    assert_close(out, (p - c).norm(dim=-1) - r[:, None])


def test_box_against_reference(dtype):
    rng = np.random.default_rng(0)
    pts = rng.uniform(-3, 3, size=(500, 3))
    b = np.array([1.0, 0.5, 2.0])
    out = P.box(torch.tensor(pts, dtype=dtype), torch.tensor(b, dtype=dtype))
    assert_close(out, _box_reference(pts, b), scale=10)
    # 2D, and rectangle is the named counterpart
    p2 = torch.tensor(pts[:, :2], dtype=dtype)
    assert_close(P.rectangle(p2, torch.tensor(b[:2], dtype=dtype)),
                 _box_reference(pts[:, :2], b[:2]), scale=10)


def test_rounded_box_is_minkowski_sum():
    p = torch.randn(300, 3, dtype=torch.float64) * 2
    b = torch.tensor([1.0, 0.7, 0.4], dtype=torch.float64)
    out = P.box(p, b, radius=0.2)
    assert_close(out, P.box(p, b - 0.2) - 0.2)
    # the outer extent is half_size: the face centre (1, 0, 0) is on the surface
    assert_close(P.box(torch.tensor([[1.0, 0.0, 0.0]], dtype=torch.float64), b, 0.2),
                 torch.zeros(1))


def test_capsule_against_dense_segment():
    p = torch.randn(200, 3, dtype=torch.float64) * 2
    a = torch.tensor([0.0, -1.0, 0.5], dtype=torch.float64)
    b = torch.tensor([1.0, 1.0, 0.0], dtype=torch.float64)
    t = torch.linspace(0, 1, 20001, dtype=torch.float64)[:, None]
    seg = a + t * (b - a)
    ref = torch.cdist(p, seg).min(1).values - 0.3
    assert_close(P.capsule(p, a, b, 0.3), ref, atol=1e-4, rtol=0)
    # zero-length segment is a sphere, with finite gradients
    pp = p.clone().requires_grad_(True)
    out = P.capsule(pp, a, a, 0.3)
    assert_close(out, P.sphere(p, 0.3, a))
    out.sum().backward()
    assert torch.isfinite(pp.grad).all()


def test_plane_and_gyroid_hand_values():
    p = torch.tensor([[1.0, 2.0, 3.0]])
    assert_close(P.plane(p, torch.tensor([0.0, 3.0, 4.0]), 1.0), torch.tensor([(6 + 12) / 5 - 1]))
    assert_close(P.plane(p), torch.tensor([3.0]))
    g = math.sin(1) * math.cos(2) + math.sin(2) * math.cos(3) + math.sin(3) * math.cos(1)
    assert_close(P.gyroid(p, 1.0, 0.2), torch.tensor([abs(g) - 0.1]))
    assert_close(P.gyroid(p / 2, 2.0, 0.0), torch.tensor([abs(g) / 2]))


def test_torus_exact_vs_report_and_brute_force():
    p = torch.randn(300, 3, dtype=torch.float64)
    R, r = 1.0, 0.3
    alg = P.torus(p, R, r, exact=False)
    exact = P.torus(p, R, r)
    # report eq. 13 f = s^2 - r^2, the exact distance is s - r
    assert_close(exact, torch.sqrt(alg + r * r) - r)
    assert torch.equal(alg < 0, exact < 0)
    u, v = torch.meshgrid(torch.linspace(0, 2 * math.pi, 721, dtype=torch.float64),
                          torch.linspace(0, 2 * math.pi, 361, dtype=torch.float64), indexing="ij")
    surf = torch.stack([(R + r * v.cos()) * u.cos(), (R + r * v.cos()) * u.sin(), r * v.sin()],
                       -1).reshape(-1, 3)
    ref = torch.cdist(p, surf).min(1).values
    assert_close(exact.abs(), ref, atol=5e-3, rtol=0)


def test_2d_counterparts():
    p = torch.tensor([[3.0, 4.0], [0.0, 0.0], [1.5, 0.0]])
    assert_close(P.circle(p, 2.0), torch.tensor([3.0, -2.0, -0.5]))
    assert_close(P.annulus(p, 1.0, 0.25), torch.tensor([3.75, 0.75, 0.25]))
    assert_close(P.capsule(p, torch.zeros(2), torch.tensor([1.0, 0.0]), 0.5),
                 torch.tensor([math.hypot(2, 4) - 0.5, -0.5, 0.0]))


def test_batched_parameters():
    p = torch.randn(3, 10, 3)
    r = torch.tensor([0.5, 1.0, 2.0])
    out = P.torus(p, r + 1, r / 4)
    for i in range(3):
        assert_close(out[i], P.torus(p[i], float(r[i] + 1), float(r[i] / 4)))
    half = torch.rand(3, 3) + 0.5
    out = P.box(p, half)
    for i in range(3):
        assert_close(out[i], P.box(p[i], half[i]))


EXACT = {
    "sphere": lambda p: P.sphere(p, 0.8, torch.tensor([0.1, 0.2, -0.1], dtype=p.dtype)),
    "box": lambda p: P.box(p, torch.tensor([0.6, 0.4, 0.9], dtype=p.dtype), 0.1),
    "capsule": lambda p: P.capsule(p, radius=0.3),
    "plane": lambda p: P.plane(p, torch.tensor([1.0, 2.0, 2.0], dtype=p.dtype), 0.3),
    "torus": lambda p: P.torus(p, 1.0, 0.3),
}


@pytest.mark.parametrize("name", sorted(EXACT))
@given(seed=st.integers(0, 2**31 - 1), spread=st.floats(0.1, 3.0))
def test_exact_sdfs_have_unit_gradient(name, seed, spread):
    g = torch.Generator().manual_seed(seed)
    p = torch.randn(64, 3, generator=g, dtype=torch.float64) * spread
    grad = sdf_gradient(EXACT[name], p, create_graph=False)
    assert_close(grad.norm(dim=-1), torch.ones(64, dtype=torch.float64), atol=1e-9, rtol=0)


@given(x=st.floats(-3, 3), y=st.floats(-3, 3), z=st.floats(-3, 3))
def test_torus_unit_gradient_hypothesis_points(x, y, z):
    p = torch.tensor([[x, y, z]], dtype=torch.float64)
    s = P.torus(p, 1.0, 0.3) + 0.3
    rho = math.hypot(x, y)
    if rho < 1e-6 or float(s) < 1e-6:  # the axis and the core circle are singular
        return
    g = sdf_gradient(lambda q: P.torus(q, 1.0, 0.3), p, create_graph=False)
    assert abs(float(g.norm()) - 1.0) < 1e-9


@pytest.mark.parametrize("fn,params", [
    (P.sphere, (0.7, [0.1, 0.2, 0.3])),
    (P.box, ([0.5, 0.6, 0.7], 0.1, [0.0, 0.1, 0.0])),
    (P.capsule, ([0.0, 0.0, 0.0], [0.3, 0.2, 1.0], 0.4)),
    (P.plane, ([0.3, 0.5, 1.0], 0.2)),
    (P.torus, (1.0, 0.3)),
    (P.gyroid, (1.3, 0.2)),
])
def test_gradcheck_points_and_parameters(fn, params):
    torch.manual_seed(0)
    p = (torch.randn(6, 3, dtype=torch.float64) * 1.5).requires_grad_(True)
    tensors = [torch.tensor(x, dtype=torch.float64, requires_grad=True) for x in params]
    assert torch.autograd.gradcheck(lambda q, *t: fn(q, *t), (p, *tensors))


def test_2d_gradcheck():
    p = torch.randn(5, 2, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda q: P.annulus(q, 1.0, 0.2), (p,))
    assert torch.autograd.gradcheck(lambda q: P.rectangle(q, torch.tensor([0.5, 0.3],
                                    dtype=torch.float64), 0.1), (p,))


MODULES = [
    (P.Sphere, P.sphere, 3), (P.Box, P.box, 3), (P.Capsule, P.capsule, 3),
    (P.Plane, P.plane, 3), (P.Torus, P.torus, 3), (P.Gyroid, P.gyroid, 3),
    (P.Circle, P.circle, 2), (P.Rectangle, P.rectangle, 2), (P.Annulus, P.annulus, 2),
]


@pytest.mark.parametrize("module,fn,dim", MODULES, ids=[m[0].__name__ for m in MODULES])
def test_module_equals_function_with_same_defaults(module, fn, dim):
    p = torch.randn(2, 20, dim)
    assert_close(module()(p).detach(), fn(p))
    mod_sig = inspect.signature(module.__init__).parameters
    for name, par in inspect.signature(fn).parameters.items():
        if name == "points":
            continue
        assert name in mod_sig, f"{module.__name__} lacks {name}"
        if par.default is not None:
            assert mod_sig[name].default == par.default, name


def test_module_moves_with_to_and_learns():
    m = P.Torus().to(torch.float64)
    assert m.major_radius.dtype == torch.float64
    out = m(torch.tensor([[2.0, 0.0, 0.0]], dtype=torch.float64))
    out.sum().backward()
    assert_close(m.major_radius.grad, torch.tensor(-1.0, dtype=torch.float64))
    assert_close(m.minor_radius.grad, torch.tensor(-1.0, dtype=torch.float64))


def test_bad_input():
    with pytest.raises(ShapeError):
        P.sphere(torch.zeros(3))
    with pytest.raises(ShapeError, match=r"points: expected shape \(\*, N, 2\|3\), got \(4, 5\)"):
        P.sphere(torch.zeros(4, 5))
    with pytest.raises(ShapeError, match=r"points: expected shape \(\*, N, 3\), got \(4, 2\)"):
        P.torus(torch.zeros(4, 2))
    with pytest.raises(ShapeError, match=r"points: expected shape \(\*, N, 2\)"):
        P.circle(torch.zeros(4, 3))
    with pytest.raises(TypeError, match="floating-point"):
        P.sphere(torch.zeros(4, 3, dtype=torch.long))
    with pytest.raises(TypeError, match="radius"):
        P.sphere(torch.zeros(4, 3), radius="1")
    with pytest.raises(ShapeError, match="center"):
        P.sphere(torch.zeros(4, 3), center=torch.zeros(2))
    with pytest.raises(ValueError, match="nonzero"):
        P.plane(torch.zeros(4, 3), torch.zeros(3))
