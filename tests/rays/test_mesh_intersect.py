"""ray_mesh_intersect and ray_mesh_crossings: watertightness, exactness, gradients, batches."""

from __future__ import annotations

import math
from fractions import Fraction

import pytest
import torch

from tests.rays._meshes import (
    CONVEX,
    MESHES,
    QUAD_CUBE_F,
    QUAD_CUBE_V,
    adversarial_rays,
    crossing_at_target,
    icosphere,
)
from torchgeo_cg.core import ShapeError
from torchgeo_cg.mesh.faces import check_mesh
from torchgeo_cg.rays import ray_mesh_crossings, ray_mesh_intersect
from torchgeo_cg.sdf import winding_number

pytestmark = pytest.mark.usefixtures("one_thread")
F64 = torch.float64


def _gen(seed=0):
    return torch.Generator().manual_seed(seed)


def _random_rays(verts, n, g, spread=0.3):
    """Rays from a sphere around the mesh toward random points near its centre."""
    c = verts.mean(0)
    r = float((verts - c).norm(dim=-1).max())
    o = c + 3 * r * torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=F64), dim=-1)
    target = c + spread * r * torch.randn(n, 3, generator=g, dtype=F64)
    return o, target - o


def _brute_force(verts, tris, o, d):
    """Moeller-Trumbore against every face (no ties in generic position): (t, face)."""
    v0, v1, v2 = verts[tris].unbind(-2)  # (F, 3)
    e1, e2 = v1 - v0, v2 - v0
    p = torch.linalg.cross(d[:, None], e2[None].expand(d.shape[0], -1, -1), dim=-1)
    den = (e1[None] * p).sum(-1)
    s = o[:, None] - v0[None]
    u = (s * p).sum(-1) / den
    q = torch.linalg.cross(s, e1[None].expand_as(s), dim=-1)
    v = (d[:, None] * q).sum(-1) / den
    t = (e2[None] * q).sum(-1) / den
    ok = (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (den != 0)
    t = torch.where(ok, t, torch.inf)
    best, face = t.min(1)
    return best, torch.where(torch.isfinite(best), face, -1)


# ----------------------------------------------------------------------------- watertight


@pytest.mark.parametrize("name", list(MESHES))
def test_rays_through_vertices_and_edge_midpoints_never_fall_through(name):
    verts, faces = MESHES[name]()
    g = _gen(1)
    o, d, _ = adversarial_rays(verts, faces, g)
    crossing = crossing_at_target(verts, faces, o, d, g)
    assert crossing.float().mean() > 0.9  # most aimed rays really cross at their target
    hits = ray_mesh_intersect(verts, faces, o, d, backend="torch")
    assert bool(hits.hit[crossing].all())
    # at or before the target (t = 1 up to the rounding of target - origin)
    assert bool((hits.t[crossing] <= 1 + 1e-12).all())
    n = ray_mesh_crossings(verts, faces, o, d)
    assert bool((n % 2 == 0).all()), "an even number of crossings from outside"
    assert bool((n[crossing] >= 2).all())
    if name in CONVEX:
        centre = verts[check_mesh(verts, faces).unique()].mean(0).expand_as(o)
        assert bool((ray_mesh_crossings(verts, faces, centre, d) == 1).all())


def test_parity_matches_winding_numbers():
    verts, faces = MESHES["rabbit"]()
    g = _gen(2)
    lo, hi = verts.amin(0), verts.amax(0)
    p = lo + (hi - lo) * torch.rand(400, 3, generator=g, dtype=F64)
    d = torch.randn(400, 3, generator=g, dtype=F64)
    inside = winding_number(verts, faces, p).abs() > 0.5
    n = ray_mesh_crossings(verts, faces, p, d)
    assert torch.equal(n % 2 == 1, inside)


def test_a_ray_along_a_shared_edge_plane_and_through_a_vertex_of_the_cube():
    o = torch.tensor([[0.5, 0.5, 3.0], [1.0, 1.0, 3.0], [0.0, 0.5, 3.0], [-1.0, -1.0, -1.0]],
                     dtype=F64)
    d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [1.0, 1.0, 1.0]],
                     dtype=F64)
    hits = ray_mesh_intersect(QUAD_CUBE_V, QUAD_CUBE_F, o, d)
    n = ray_mesh_crossings(QUAD_CUBE_V, QUAD_CUBE_F, o, d)
    # the diagonal of the top quad, the cube's edge, the cube's corner
    assert hits.hit[[0, 3]].all()
    assert torch.equal(hits.t[[0, 3]], torch.tensor([2.0, 1.0], dtype=F64))
    assert n[0] == 2 and n[3] == 2
    assert n[1] % 2 == 0 and n[2] % 2 == 0  # touching the surface along an edge or face


# ----------------------------------------------------------------------------- reference


def test_matches_brute_force_on_random_rays():
    verts, faces = icosphere(2)
    g = _gen(3)
    o, d = _random_rays(verts, 500, g)
    hits = ray_mesh_intersect(verts, faces, o, d, backend="torch")
    t, face = _brute_force(verts, faces, o, d)
    assert torch.equal(hits.face, face)
    assert torch.equal(hits.hit, face >= 0)
    torch.testing.assert_close(hits.t[hits.hit], t[hits.hit], rtol=1e-12, atol=0)
    corners = verts[faces[hits.face[hits.hit]]]
    torch.testing.assert_close((hits.bary[hits.hit, :, None] * corners).sum(1),
                               hits.points[hits.hit], rtol=1e-12, atol=1e-12)
    n = torch.linalg.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], dim=-1)
    torch.testing.assert_close(hits.normals[hits.hit], torch.nn.functional.normalize(n, dim=-1))


def _exact_t(tri, o, d) -> Fraction:
    v0, v1, v2 = ([Fraction(float(x)) for x in p] for p in tri)
    o, d = [Fraction(float(x)) for x in o], [Fraction(float(x)) for x in d]
    e1 = [a - b for a, b in zip(v1, v0)]
    e2 = [a - b for a, b in zip(v2, v0)]
    n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
         e1[0] * e2[1] - e1[1] * e2[0]]
    num = sum((a - b) * c for a, b, c in zip(v0, o, n))
    return num / sum(a * c for a, c in zip(d, n))


@pytest.mark.parametrize("sine", [None, 1e-2, 1e-3, 1e-4])
def test_t_is_exact_to_1e_14_even_near_grazing(sine):
    g = _gen(4)
    tri = torch.randn(60, 3, 3, generator=g, dtype=F64)
    bary = torch.distributions.Dirichlet(torch.ones(3, dtype=F64)).sample((60,))
    p = (bary[:, :, None] * tri).sum(1)
    if sine is None:
        d = torch.randn(60, 3, generator=g, dtype=F64)
    else:  # in the plane, tilted by asin(sine) toward the normal
        n = torch.nn.functional.normalize(torch.linalg.cross(tri[:, 1] - tri[:, 0],
                                                             tri[:, 2] - tri[:, 0], dim=-1), dim=-1)
        w = torch.nn.functional.normalize(tri[:, 1] - p, dim=-1)
        d = math.sqrt(1 - sine**2) * w - sine * n
    o = p - 0.7 * d
    hits = ray_mesh_intersect(tri, torch.tensor([[0, 1, 2]]), o[:, None], d[:, None])
    assert hits.hit.all() and hits.t.shape == (60, 1)
    for i in range(60):
        exact = _exact_t(tri[i], o[i], d[i])
        assert abs(Fraction(float(hits.t[i, 0])) - exact) <= Fraction(1, 10**14) * abs(exact)


# ----------------------------------------------------------------------------- scale, ties


@pytest.mark.parametrize("s", [1e-6, 1e6])
def test_scaled_inputs_give_the_same_hits_scaled(s):
    verts, faces = icosphere(2)
    o, d = _random_rays(verts, 300, _gen(5))
    a = ray_mesh_intersect(verts, faces, o, d)
    b = ray_mesh_intersect(verts * s, faces, o * s, d * s)
    assert torch.equal(a.face, b.face)
    torch.testing.assert_close(b.t, a.t, rtol=1e-12, atol=0)
    torch.testing.assert_close(b.points, a.points * s, rtol=1e-12, atol=1e-12 * s)
    c = ray_mesh_intersect(verts * s, faces, o * s, d)  # directions keep their length
    torch.testing.assert_close(c.t, a.t * s, rtol=1e-12, atol=0)


def test_ties_go_to_the_smaller_face_and_ray_order_does_not_matter():
    verts, faces = icosphere(2)
    faces2 = torch.cat([faces[5:], faces[:5], faces[:5]])  # exact duplicates: equal t
    o, d = _random_rays(verts, 400, _gen(6))
    hits = ray_mesh_intersect(verts, faces2, o, d)
    first = hits.face[hits.hit]
    dup = first >= faces.shape[0]
    assert not dup.any() or bool((first[dup] < faces.shape[0] - 5 + 5).all())
    assert not bool((hits.face >= faces2.shape[0] - 5).any())  # the later copy never wins
    perm = torch.randperm(400, generator=_gen(7))
    again = ray_mesh_intersect(verts, faces2, o[perm], d[perm])
    assert torch.equal(again.face, hits.face[perm]) and torch.equal(again.t, hits.t[perm])


# ----------------------------------------------------------------------------- gradients


@pytest.mark.grad
def test_gradcheck_vertices_origins_directions():
    verts, faces = icosphere(1)
    o, d = _random_rays(verts, 12, _gen(8), spread=0.2)
    hits = ray_mesh_intersect(verts, faces, o, d)
    assert hits.hit.all()

    def f(v, oo, dd):
        h = ray_mesh_intersect(v, faces, oo, dd)
        return h.t, h.bary, h.points, h.normals

    args = (verts.clone().requires_grad_(), o.clone().requires_grad_(),
            d.clone().requires_grad_())
    assert torch.autograd.gradcheck(f, args, eps=1e-7, atol=1e-6)


def test_misses_give_zero_gradients_not_nan():
    verts, faces = icosphere(1)
    o = torch.tensor([[5.0, 5.0, 5.0], [0.0, 0.0, 3.0], [1.0, 2.0, 3.0]], dtype=F64,
                     requires_grad=True)
    d = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]], dtype=F64,
                     requires_grad=True)
    hits = ray_mesh_intersect(verts, faces, o, d)
    assert hits.hit.tolist() == [False, True, False]
    assert hits.t[0] == math.inf and hits.t[2] == math.inf  # a zero direction: no hit
    (torch.where(hits.hit, hits.t, 0.0).sum() + hits.points.sum() + hits.normals.sum()).backward()
    assert torch.isfinite(o.grad).all() and torch.isfinite(d.grad).all()
    assert o.grad[0].abs().sum() == 0


# ----------------------------------------------------------------------------- batches


def test_a_batch_of_64_deformed_copies_matches_one_by_one():
    verts, faces = icosphere(2)
    g = _gen(9)
    scale = 1 + 0.2 * torch.rand(64, 1, 3, generator=g, dtype=F64)
    batch = verts * scale + 0.05 * torch.randn(64, *verts.shape, generator=g, dtype=F64)
    o, d = _random_rays(verts, 50, g)
    hits = ray_mesh_intersect(batch, faces, o, d)
    n = ray_mesh_crossings(batch, faces, o, d)
    assert hits.t.shape == (64, 50) and n.shape == (64, 50)
    for b in (0, 17, 63):
        one = ray_mesh_intersect(batch[b], faces, o, d)
        assert torch.equal(one.face, hits.face[b]) and torch.equal(one.t, hits.t[b])
        assert torch.equal(ray_mesh_crossings(batch[b], faces, o, d), n[b])


def test_an_image_shaped_bundle_keeps_its_shape():
    verts, faces = icosphere(1)
    o = torch.tensor([0.0, 0.0, 4.0], dtype=F64)
    u = torch.linspace(-0.15, 0.15, 5, dtype=F64)
    y, x = torch.meshgrid(u, u, indexing="ij")
    d = torch.stack([x, y, -torch.ones_like(x)], -1)  # (5, 5, 3)
    hits = ray_mesh_intersect(verts, faces, o.expand(5, 5, 3), d)
    assert hits.t.shape == (5, 5) and hits.points.shape == (5, 5, 3)
    assert hits.hit.all()


# ----------------------------------------------------------------------------- bad input


def test_bad_input():
    verts, faces = icosphere(1)
    o, d = torch.zeros(4, 3, dtype=F64), torch.ones(4, 3, dtype=F64)
    with pytest.raises(ShapeError, match="origins"):
        ray_mesh_intersect(verts, faces, torch.zeros(4, 2, dtype=F64), d)
    with pytest.raises(ShapeError, match="directions"):
        ray_mesh_crossings(verts, faces, o, torch.zeros(3, 3, dtype=F64))
    with pytest.raises(ShapeError, match="verts"):
        ray_mesh_intersect(verts[:, :2], faces, o, d)
    with pytest.raises(TypeError, match="directions"):
        ray_mesh_intersect(verts, faces, o, d.float())
    with pytest.raises(ValueError, match="t_min"):
        ray_mesh_intersect(verts, faces, o, d, t_min=2.0, t_max=1.0)
    bad = verts.clone()
    bad[3, 1] = math.nan
    with pytest.raises(ValueError, match="verts"):
        ray_mesh_intersect(bad, faces, o, d)
    with pytest.raises(ValueError, match="backend"):
        ray_mesh_intersect(verts, faces, o, d, backend="embree")


def test_nan_rays_and_empty_bundles():
    verts, faces = icosphere(1)
    o = torch.tensor([[0.0, 0.0, 3.0], [math.nan, 0.0, 3.0]], dtype=F64)
    d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]], dtype=F64)
    hits = ray_mesh_intersect(verts, faces, o, d)
    assert hits.hit.tolist() == [True, False] and math.isnan(hits.t[1])
    assert torch.isnan(hits.points[1]).all()
    assert ray_mesh_crossings(verts, faces, o, d).tolist() == [2, 0]
    empty = ray_mesh_intersect(verts, faces, o[:0], d[:0])
    assert empty.t.shape == (0,) and empty.points.shape == (0, 3)
    assert ray_mesh_crossings(verts, faces, o[:0], d[:0]).shape == (0,)


def test_t_limits_and_float32():
    verts, faces = icosphere(2)
    o = torch.tensor([[0.0, 0.0, 3.0]], dtype=F64)
    d = torch.tensor([[0.0, 0.0, -1.0]], dtype=F64)
    near = ray_mesh_intersect(verts, faces, o, d)
    far = ray_mesh_intersect(verts, faces, o, d, t_min=float(near.t) + 0.1)
    assert far.hit.all() and far.t > 3.5
    assert not ray_mesh_intersect(verts, faces, o, d, t_max=1.0).hit.any()
    assert ray_mesh_crossings(verts, faces, o, d, t_min=3.0).tolist() == [1]
    f32 = ray_mesh_intersect(verts.float(), faces, o.float(), d.float())
    assert f32.t.dtype == torch.float32 and torch.equal(f32.face, near.face)


@pytest.mark.parametrize("backend", ["torch", "auto"])
def test_far_origins_and_extreme_direction_lengths(backend):
    verts, faces = icosphere(2)
    o = torch.tensor([[0.01, 0.02, 1e20], [0.01, 0.02, 3.0], [0.01, 0.02, 3.0],
                      [0.01, 0.02, -1e9]], dtype=F64)
    d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1e-300], [0.0, 0.0, -1e300],
                      [0.0, 0.0, 1.0]], dtype=F64)
    hits = ray_mesh_intersect(verts, faces, o, d, backend=backend)
    near = ray_mesh_intersect(verts, faces, o[1:2], d[:1])
    assert hits.hit.all()
    assert hits.t[0] == 1e20  # 1e20 - 0.99...: within the rounding of the origin
    torch.testing.assert_close(hits.t[1:3], near.t * torch.tensor([1e300, 1e-300], dtype=F64),
                               rtol=1e-15, atol=0)
    torch.testing.assert_close(hits.t[3] - 1e9, near.t[0] - 3.0, rtol=0, atol=1e-6)
    assert torch.equal(ray_mesh_crossings(verts, faces, o, d), torch.tensor([2, 2, 2, 2]))
