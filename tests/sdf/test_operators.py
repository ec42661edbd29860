"""CSG, smooth blends, product and transforms: hand values, exactness, gradcheck, modules."""

from __future__ import annotations

import math

import pytest
import torch

from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.sdf import operators as O
from torchgeo_cg.sdf import primitives as P


def test_csg_hand_values(device, dtype):
    a = torch.tensor([1.0, -2.0, 0.5], device=device, dtype=dtype)
    b = torch.tensor([0.5, 3.0, -1.0], device=device, dtype=dtype)
    c = torch.tensor([2.0, -3.0, 0.0], device=device, dtype=dtype)
    assert_close(O.union(a, b), torch.tensor([0.5, -2.0, -1.0]))
    assert_close(O.union(a, b, c), torch.tensor([0.5, -3.0, -1.0]))
    assert_close(O.intersection(a, b, c), torch.tensor([2.0, 3.0, 0.5]))
    assert_close(O.difference(a, b), torch.tensor([1.0, -2.0, 1.0]))
    assert_close(O.product(a, b, c), torch.tensor([1.0, 18.0, 0.0]))
    assert O.union(a, b).dtype == dtype


def test_union_of_disjoint_spheres_is_exact_outside():
    p = torch.randn(500, 3, dtype=torch.float64) * 3
    c2 = torch.tensor([4.0, 0.0, 0.0], dtype=torch.float64)
    u = O.union(P.sphere(p), P.sphere(p, 1.0, c2))
    ref = torch.minimum((p).norm(dim=-1), (p - c2).norm(dim=-1)) - 1.0
    assert_close(u, ref)


def test_smooth_union_properties():
    a = torch.linspace(-2, 2, 101, dtype=torch.float64)
    b = torch.flip(a, [0]) * 0.7
    k = 0.3
    s = O.smooth_union(a, b, k)
    m = torch.minimum(a, b)
    assert (s <= m + 1e-15).all()
    far = (a - b).abs() >= k
    assert_close(s[far], m[far])
    # the deepest blend, at a == b, is k / 4 below
    assert_close(O.smooth_union(torch.zeros(1), torch.zeros(1), k), torch.tensor([-k / 4]))
    si = O.smooth_intersection(a, b, k)
    assert (si >= torch.maximum(a, b) - 1e-15).all()
    # the blend is C1: gradcheck through the polynomial region
    x = torch.tensor([0.05, -0.1], dtype=torch.float64, requires_grad=True)
    y = torch.tensor([0.0, 0.0], dtype=torch.float64, requires_grad=True)
    kk = torch.tensor(0.4, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(O.smooth_union, (x, y, kk))
    assert torch.autograd.gradcheck(O.smooth_intersection, (x, y, kk))


def test_transforms_keep_distances_exact():
    p = torch.randn(200, 3, dtype=torch.float64) * 2
    off = torch.tensor([1.0, -2.0, 0.5], dtype=torch.float64)
    assert_close(O.translate(P.sphere, off)(p), P.sphere(p, 1.0, off))
    # rotation by 90 degrees about z maps the capsule axis (+z) to itself; use x instead
    ang = math.pi / 3
    R = torch.tensor([[1, 0, 0], [0, math.cos(ang), -math.sin(ang)],
                      [0, math.sin(ang), math.cos(ang)]], dtype=torch.float64)
    end = R @ torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    assert_close(O.rotate(P.capsule, R)(p), P.capsule(p, None, end, 0.5))
    assert_close(O.scale(P.sphere, 2.5)(p), P.sphere(p, 2.5))
    assert_close(O.scale(lambda q: P.box(q), 2.0)(p),
                 P.box(p, torch.full((3,), 2.0, dtype=torch.float64)))
    # batched: one offset / factor per shape
    pb = torch.randn(2, 30, 3, dtype=torch.float64)
    offs = torch.randn(2, 3, dtype=torch.float64)
    moved = O.translate(P.sphere, offs)(pb)
    for i in range(2):
        assert_close(moved[i], P.sphere(pb[i], 1.0, offs[i]))
    sc = O.scale(P.sphere, torch.tensor([1.0, 3.0], dtype=torch.float64))(pb)
    assert_close(sc[1], P.sphere(pb[1], 3.0))


def test_transform_gradcheck():
    p = torch.randn(5, 3, dtype=torch.float64, requires_grad=True)
    off = torch.randn(3, dtype=torch.float64, requires_grad=True)
    s = torch.tensor(1.7, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda q, o: O.translate(lambda x: P.torus(x), o)(q), (p, off))
    assert torch.autograd.gradcheck(lambda q, f: O.scale(lambda x: P.torus(x), f)(q), (p, s))


def test_modules_equal_functions():
    p = torch.randn(40, 3)
    a, b = P.Sphere(1.0), P.Sphere(0.8, [1.0, 0.0, 0.0])
    fa, fb = P.sphere(p), P.sphere(p, 0.8, torch.tensor([1.0, 0.0, 0.0]))
    with torch.no_grad():
        assert_close(O.Union(a, b)(p), O.union(fa, fb))
        assert_close(O.Intersection(a, b)(p), O.intersection(fa, fb))
        assert_close(O.Difference(a, b)(p), O.difference(fa, fb))
        assert_close(O.SmoothUnion(a, b)(p), O.smooth_union(fa, fb))
        assert_close(O.SmoothIntersection(a, b, k=0.2)(p), O.smooth_intersection(fa, fb, 0.2))
        assert_close(O.Product(a, b)(p), O.product(fa, fb))
        off = torch.tensor([0.0, 1.0, 0.0])
        assert_close(O.Translate(a, off)(p), O.translate(P.sphere, off)(p))
        assert_close(O.Scale(a, 2.0)(p), O.scale(P.sphere, 2.0)(p))
        R = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        assert_close(O.Rotate(b, R)(p), O.rotate(lambda q: P.sphere(q, 0.8, torch.tensor(
            [1.0, 0.0, 0.0])), R)(p))
    # smooth blend default k matches
    assert O.SmoothUnion(a, b).k.item() == pytest.approx(0.1)
    import inspect
    assert inspect.signature(O.smooth_union).parameters["k"].default == 0.1
    m = O.Rotate(b, R).to(torch.float64)
    assert m.world_from_local.dtype == torch.float64


def test_bad_input():
    a = torch.zeros(3)
    with pytest.raises(ValueError, match="k"):
        O.smooth_union(a, a, 0.0)
    with pytest.raises(TypeError, match="k"):
        O.smooth_union(a, a, "1")
    with pytest.raises(TypeError, match="floating-point"):
        O.union(a, torch.zeros(3, dtype=torch.long))
    for op in (O.union, O.intersection, O.difference, O.smooth_union, O.product):
        with pytest.raises(ValueError, match=r"do not broadcast: sdf\[0\] \(3\), sdf\[1\] \(4\)"):
            op(a, torch.zeros(4))
    assert O.union(a, torch.zeros(2, 1)).shape == (2, 3)  # broadcasting stays allowed
    with pytest.raises(ValueError, match="factor"):
        O.scale(P.sphere, -1.0)
    with pytest.raises(ValueError, match="factor"):
        O.scale(P.sphere, torch.tensor([1.0, 0.0]))
    with pytest.raises(TypeError, match="offset"):
        O.translate(P.sphere, "1, 0, 0")
    pts = torch.randn(5, 3)  # lists and numpy are accepted like tensors (one coercion rule)
    torch.testing.assert_close(O.translate(P.sphere, [1.0, 0.0, 0.0])(pts),
                               O.translate(P.sphere, torch.tensor([1.0, 0.0, 0.0]))(pts))
    with pytest.raises(ValueError, match="world_from_local"):
        O.rotate(P.sphere, torch.eye(3)[:2])
    with pytest.raises(ValueError, match="at least 2"):
        O.Union(P.Sphere())
