"""sphere_trace: accuracy against analytic shapes, implicit gradients, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch import nn

from torchgeo_cg.core import ShapeError
from torchgeo_cg.rays import sphere_trace
from torchgeo_cg.sdf import box, difference, sphere, torus

pytestmark = pytest.mark.usefixtures("one_thread")
F64 = torch.float64


def _rays(n, seed, radius=3.0, spread=0.6):
    g = torch.Generator().manual_seed(seed)
    o = radius * torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=F64), dim=-1)
    target = spread * torch.randn(n, 3, generator=g, dtype=F64)
    return o, target - o


def _sphere_t(o, d, r):
    a, b, c = (d * d).sum(-1), 2 * (o * d).sum(-1), (o * o).sum(-1) - r * r
    disc = b * b - 4 * a * c
    q = -0.5 * (b + torch.sign(b) * disc.clamp_min(0).sqrt())  # stable quadratic roots
    t = torch.minimum(q / a, c / q)
    return torch.where(disc > 0, t, torch.inf)


def _box_t(o, d, h):
    t1, t2 = (-h - o) / d, (h - o) / d
    near, far = torch.minimum(t1, t2).amax(-1), torch.maximum(t1, t2).amin(-1)
    return torch.where((near <= far) & (near > 0), near, torch.inf)


def _torus_t(o, d, big, small):
    """Smallest positive real root of the torus quartic, polished by Newton in float64."""
    out = []
    for oo, dd in zip(o.tolist(), d.tolist()):
        oo, dd = np.array(oo), np.array(dd)
        a, b, c = dd @ dd, 2 * oo @ dd, oo @ oo + big**2 - small**2
        # (|p|^2 + R^2 - r^2)^2 - 4 R^2 (x^2 + y^2) along p = o + t d
        q = np.polynomial.polynomial.polypow([c, b, a], 2)
        xy = np.array([oo[0]**2 + oo[1]**2, 2 * (oo[:2] @ dd[:2]), dd[:2] @ dd[:2]])
        coef = q - 4 * big**2 * np.pad(xy, (0, 2))
        roots = np.polynomial.polynomial.polyroots(coef)
        real = sorted(r.real for r in roots if abs(r.imag) < 1e-6 and r.real > 0)
        if not real:
            out.append(math.inf)
            continue
        t = real[0]
        for _ in range(5):
            t -= np.polynomial.polynomial.polyval(t, coef) / np.polynomial.polynomial.polyval(
                t, np.polynomial.polynomial.polyder(coef))
        out.append(t)
    return torch.tensor(out, dtype=F64)


SHAPES = {
    "sphere": (lambda p: sphere(p, 1.0), lambda o, d: _sphere_t(o, d, 1.0)),
    "box": (lambda p: box(p, torch.tensor([0.8, 0.5, 0.6], dtype=F64)),
            lambda o, d: _box_t(o, d, torch.tensor([0.8, 0.5, 0.6], dtype=F64))),
    "torus": (lambda p: torus(p, 1.0, 0.3), lambda o, d: _torus_t(o, d, 1.0, 0.3)),
}


@pytest.mark.parametrize("lipschitz", [1.0, None])
@pytest.mark.parametrize("name", list(SHAPES))
def test_analytic_shapes_to_1e_10(name, lipschitz):
    field, exact = SHAPES[name]
    o, d = _rays(300, 1)
    hits = sphere_trace(field, o, d, t_max=10.0, lipschitz=lipschitz)
    want = exact(o, d)
    both = hits.hit & torch.isfinite(want)
    assert both.sum() > 100
    assert torch.equal(hits.hit[both], torch.isfinite(want)[both])
    rel = ((hits.t[both] - want[both]).abs() / want[both]).max()
    assert rel < 1e-10, float(rel)
    missed = torch.isfinite(want) & ~hits.hit
    assert not missed.any()
    n = hits.normals[both]
    torch.testing.assert_close(n.norm(dim=-1), torch.ones(int(both.sum()), dtype=F64))
    assert bool(((n * d[both]).sum(-1) < 0).all())  # outward, against rays from outside


@pytest.mark.parametrize("s", [1e-6, 1e6])
def test_scaled_scene_gives_scaled_hits(s):
    o, d = _rays(100, 2)
    a = sphere_trace(lambda p: sphere(p, 1.0), o, d, t_max=10.0)
    b = sphere_trace(lambda p: sphere(p, s), o * s, d * s, t_max=10.0)
    assert torch.equal(a.hit, b.hit)
    torch.testing.assert_close(b.t, a.t, rtol=1e-12, atol=0)
    torch.testing.assert_close(b.points[b.hit], a.points[a.hit] * s, rtol=1e-12, atol=0)


def test_csg_and_an_origin_inside():
    field = lambda p: difference(box(p, torch.tensor([1.0, 1.0, 1.0], dtype=F64)),  # noqa: E731
                                 sphere(p, 0.5))
    o = torch.tensor([[0.0, 0.0, 3.0], [0.0, 0.0, 0.0], [0.9, 0.9, 3.0]], dtype=F64)
    d = torch.tensor([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]], dtype=F64)
    hits = sphere_trace(field, o, d, t_max=10.0)
    assert hits.hit.all()
    torch.testing.assert_close(hits.t, torch.tensor([2.0, 0.5, 2.0], dtype=F64), rtol=1e-12,
                               atol=0)


# ----------------------------------------------------------------------------- gradients


@pytest.mark.grad
def test_gradcheck_origins_directions_and_field_parameters():
    o, d = _rays(6, 3, spread=0.2)
    radius = torch.tensor(1.0, dtype=F64, requires_grad=True)

    def f(oo, dd, r):
        h = sphere_trace(lambda p: sphere(p, r), oo, dd, t_max=10.0)
        return h.t, h.points, h.normals

    args = (o.clone().requires_grad_(), d.clone().requires_grad_(), radius)
    assert torch.autograd.gradcheck(f, args, eps=1e-6, atol=1e-6)


def _fd_check(trace, params, h=1e-4):
    """Gradient of sum(t) by autograd against 4-point central differences of the traced
    t (error O(h^4) + rounding O(eps |t| / h))."""
    t = trace()
    grads = torch.autograd.grad(t.sum(), params)
    for p, g in zip(params, grads):
        flat, gflat = p.data.view(-1), g.reshape(-1)
        for i in range(min(flat.numel(), 4)):
            old = float(flat[i])
            values = []
            with torch.no_grad():
                for k in (1, -1, 2, -2):
                    flat[i] = old + k * h
                    values.append(float(trace().sum()))
                flat[i] = old
            fd = (8 * (values[0] - values[1]) - (values[2] - values[3])) / (12 * h)
            assert abs(fd - float(gflat[i])) <= 1e-6 * abs(fd) + 1e-12, (fd, float(gflat[i]))


def test_implicit_gradient_matches_finite_differences_for_torus_radii():
    o, d = _rays(40, 4, spread=0.5)
    radii = torch.tensor([1.0, 0.3], dtype=F64, requires_grad=True)

    def trace():
        h = sphere_trace(lambda p: torus(p, radii[0], radii[1]), o, d, t_max=10.0)
        return torch.where(h.hit, h.t, 0.0)

    assert sphere_trace(lambda p: torus(p, 1.0, 0.3), o, d, t_max=10.0).hit.sum() > 10
    _fd_check(trace, [radii])


def test_implicit_gradient_matches_finite_differences_for_mlp_weights():
    torch.manual_seed(0)
    net = nn.Sequential(nn.Linear(3, 16), nn.Softplus(beta=4), nn.Linear(16, 16),
                        nn.Softplus(beta=4), nn.Linear(16, 1)).double()

    def field(p):
        return sphere(p, 1.0) + 0.05 * net(p).squeeze(-1)

    o, d = _rays(30, 5, spread=0.3)
    hits0 = sphere_trace(field, o, d, t_max=10.0, lipschitz=None)
    assert hits0.hit.all()

    def trace():
        return sphere_trace(field, o, d, t_max=10.0, lipschitz=None).t

    _fd_check(trace, [net[0].weight, net[4].bias])


# ----------------------------------------------------------------------------- bad input


def test_bad_input_zero_nan_and_empty():
    field = lambda p: sphere(p, 1.0)  # noqa: E731
    o = torch.tensor([[0.0, 0.0, 3.0], [0.0, 0.0, 3.0], [math.nan, 0.0, 3.0]], dtype=F64)
    d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0]], dtype=F64)
    hits = sphere_trace(field, o, d, t_max=10.0)
    assert hits.hit.tolist() == [True, False, False]
    assert hits.t[1] == math.inf and math.isnan(hits.t[2])
    assert torch.isfinite(hits.normals).all()
    empty = sphere_trace(field, o[:0], d[:0], t_max=10.0)
    assert empty.t.shape == (0,) and empty.points.shape == (0, 3)
    with pytest.raises(ShapeError, match="origins"):
        sphere_trace(field, torch.zeros(2, 2, dtype=F64), d[:2], t_max=1.0)
    with pytest.raises(ShapeError, match="directions"):
        sphere_trace(field, o, torch.zeros(2, 3, dtype=F64), t_max=1.0)
    with pytest.raises(ShapeError, match="sdf"):
        sphere_trace(lambda p: p, o, d, t_max=1.0)
    with pytest.raises(TypeError, match="directions"):
        sphere_trace(field, o, d.float(), t_max=1.0)
    with pytest.raises(ValueError, match="t_max"):
        sphere_trace(field, o, d, t_max=math.inf)
    with pytest.raises(ValueError, match="lipschitz"):
        sphere_trace(field, o, d, t_max=1.0, lipschitz=0.0)
    with pytest.raises(TypeError, match="sdf"):
        sphere_trace(3.0, o, d, t_max=1.0)


def test_image_bundle_keeps_its_shape():
    u = torch.linspace(-0.2, 0.2, 4, dtype=F64)
    y, x = torch.meshgrid(u, u, indexing="ij")
    d = torch.stack([x, y, -torch.ones_like(x)], -1)
    o = torch.tensor([0.0, 0.0, 3.0], dtype=F64)
    hits = sphere_trace(lambda p: sphere(p, 1.0), o, d, t_max=10.0)
    assert hits.t.shape == (4, 4) and hits.normals.shape == (4, 4, 3) and hits.hit.all()
