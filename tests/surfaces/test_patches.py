"""Tensor-product patches against a brute-force de Casteljau product, geomdl NURBS surfaces,
finite-difference normals (including a sphere's poles), fits and grid meshes."""

from __future__ import annotations

import math

import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.surfaces import (
    BezierSurface,
    BSplineSurface,
    NURBSSurface,
    bezier_surface,
    bezier_surface_derivatives,
    bspline_surface,
    bspline_surface_derivatives,
    fit_bspline_surface,
    nurbs_surface,
    nurbs_surface_derivatives,
    surface_mesh,
)

F64 = torch.float64


def _de_casteljau(points, t):
    while points.shape[0] > 1:  # a loop over levels of one curve
        points = (1 - t) * points[:-1] + t * points[1:]
    return points[0]


def _brute_force(grid, u, v):
    """Bezier patch by de Casteljau along v for each row, then along u, one point at a time."""
    out = torch.empty(*u.shape, grid.shape[-1], dtype=grid.dtype)
    for b in range(u.shape[0]):
        for k in range(u.shape[1]):
            rows = torch.stack([_de_casteljau(grid[b, i], v[b, k]) for i in range(grid.shape[1])])
            out[b, k] = _de_casteljau(rows, u[b, k])
    return out


@pytest.mark.parametrize("shape", [(4, 5), (1, 3), (6, 2)])
def test_bezier_surface_matches_brute_force(shape):
    g = torch.Generator().manual_seed(sum(shape))
    grid = torch.randn(2, *shape, 3, generator=g, dtype=F64)
    u, v = torch.rand(2, 2, 9, generator=g, dtype=F64)
    assert torch.allclose(bezier_surface(grid, u, v), _brute_force(grid, u, v), atol=1e-14)


def test_clamped_bspline_patch_of_one_span_is_the_bezier_patch():
    grid = torch.randn(4, 3, 2, dtype=F64)
    u, v = torch.rand(2, 11, dtype=F64)
    assert torch.allclose(bspline_surface(grid, u, v, (3, 2)), bezier_surface(grid, u, v),
                          atol=1e-14)


def _fd(fn, u, v, h=1e-6):
    return ((fn(u + h, v) - fn(u - h, v)) / (2 * h), (fn(u, v + h) - fn(u, v - h)) / (2 * h))


def test_partial_derivatives_and_normals_against_finite_differences():
    g = torch.Generator().manual_seed(5)
    grid = torch.randn(6, 5, 3, generator=g, dtype=F64)
    w = 0.5 + torch.rand(6, 5, generator=g, dtype=F64)
    knots_u = torch.tensor([0, 0, 0, 0.2, 0.5, 0.7, 1, 1, 1], dtype=F64)
    u, v = 0.05 + 0.9 * torch.rand(2, 30, generator=g, dtype=F64)
    for fn, deriv in (
        (lambda a, b: bspline_surface(grid, a, b, (2, 3), knots_u),
         bspline_surface_derivatives(grid, u, v, (2, 3), knots_u)),
        (lambda a, b: nurbs_surface(grid, w, a, b, (2, 3), knots_u),
         nurbs_surface_derivatives(grid, w, u, v, (2, 3), knots_u)),
        (lambda a, b: bezier_surface(grid, a, b), bezier_surface_derivatives(grid, u, v)),
    ):
        du, dv = _fd(fn, u, v)
        assert torch.allclose(deriv.du, du, atol=1e-7) and torch.allclose(deriv.dv, dv, atol=1e-7)
        normal = torch.linalg.cross(du, dv)
        normal = normal / normal.norm(dim=-1, keepdim=True)
        assert torch.allclose(deriv.normals, normal, atol=1e-6)
        assert torch.allclose(deriv.points, fn(u, v), atol=1e-14)


def test_nurbs_surface_matches_geomdl():
    geomdl_nurbs = pytest.importorskip("geomdl.NURBS")
    operations = pytest.importorskip("geomdl.operations")
    g = torch.Generator().manual_seed(0)
    grid = torch.randn(6, 5, 3, generator=g, dtype=F64)
    w = 0.5 + torch.rand(6, 5, generator=g, dtype=F64)
    knots_u = [0, 0, 0, 0, 0.3, 0.6, 1, 1, 1, 1]
    knots_v = [0, 0, 0, 0.4, 0.7, 1, 1, 1]
    surface = geomdl_nurbs.Surface()
    surface.degree_u, surface.degree_v = 3, 2
    surface.ctrlpts_size_u, surface.ctrlpts_size_v = 6, 5
    surface.ctrlptsw = [[*(grid[i, j] * w[i, j]).tolist(), float(w[i, j])]
                        for i in range(6) for j in range(5)]
    surface.knotvector_u, surface.knotvector_v = knots_u, knots_v
    u, v = torch.rand(2, 25, generator=g, dtype=F64)
    ours = nurbs_surface_derivatives(grid, w, u, v, (3, 2), torch.tensor(knots_u, dtype=F64),
                                     torch.tensor(knots_v, dtype=F64))
    ref = torch.tensor([surface.derivatives(float(a), float(b), 1) for a, b in zip(u, v)],
                       dtype=F64)
    normals = torch.tensor([operations.normal(surface, (float(a), float(b)))[1]
                            for a, b in zip(u, v)], dtype=F64)
    assert torch.allclose(ours.points, ref[:, 0, 0], atol=1e-13)
    assert torch.allclose(ours.du, ref[:, 1, 0], atol=1e-12)
    assert torch.allclose(ours.dv, ref[:, 0, 1], atol=1e-12)
    assert torch.allclose(ours.normals, normals, atol=1e-12)


def _sphere(radius=1.0):
    """The rational biquadratic sphere: a full circle in u, a half circle pole to pole in v."""
    s = math.sqrt(0.5)
    circle = torch.tensor([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1],
                           [1, 0]], dtype=F64)
    wc = torch.tensor([1, s, 1, s, 1, s, 1, s, 1], dtype=F64)
    meridian = torch.tensor([[0, -1], [1, -1], [1, 0], [1, 1], [0, 1]], dtype=F64)  # (r, z)
    wm = torch.tensor([1, s, 1, s, 1], dtype=F64)
    grid = torch.cat([circle[:, None, :] * meridian[None, :, :1], meridian[None, :, 1:].expand(
        9, 5, 1)], -1) * radius
    weights = wc[:, None] * wm[None, :]
    knots_u = torch.tensor([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1], dtype=F64)
    knots_v = torch.tensor([0, 0, 0, 0.5, 0.5, 1, 1, 1], dtype=F64)
    return grid, weights, knots_u, knots_v


@pytest.mark.parametrize("radius", [1e-6, 1.0, 3.0, 1e6])
def test_sphere_poles_have_the_limit_normal(radius):
    grid, w, ku, kv = _sphere(radius)
    u = torch.tensor([0.1, 0.4, 0.7, 0.1, 0.4, 0.7, 0.3], dtype=F64)
    v = torch.tensor([0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.3], dtype=F64)
    d = nurbs_surface_derivatives(grid, w, u, v, 2, ku, kv)
    assert torch.allclose(d.points.norm(dim=-1) / radius, torch.ones(7, dtype=F64), atol=1e-14)
    # outward (du x dv: u around z counter-clockwise, v from south to north pole points out)
    outward = d.points / d.points.norm(dim=-1, keepdim=True)
    assert torch.allclose(d.normals, outward, atol=1e-12)
    # the limit from inside matches the normal a little off the pole
    inside = nurbs_surface_derivatives(grid, w, u[:3], v[:3] + 1e-7, 2, ku, kv).normals
    assert torch.allclose(d.normals[:3], inside, atol=1e-6)


def test_collapsed_patch_gives_zero_normal():
    grid = torch.ones(3, 3, 3, dtype=F64)
    d = bezier_surface_derivatives(grid, torch.tensor([0.5]), torch.tensor([0.5]))
    assert torch.equal(d.normals, torch.zeros(1, 3, dtype=F64))


def test_fit_bspline_surface_is_least_squares():
    g = torch.Generator().manual_seed(3)
    points = torch.randn(9, 8, 3, generator=g, dtype=F64)
    fit = fit_bspline_surface(points, (3, 2), (6, 5))
    from torchgeo_cg.curves import collocation_matrix

    a_u = collocation_matrix(fit.u, 3, fit.knots_u)
    a_v = collocation_matrix(fit.v, 2, fit.knots_v)
    design = torch.kron(a_u, a_v)  # (R S, m n): the full least-squares system
    ref = torch.linalg.lstsq(design, points.reshape(-1, 3)).solution.reshape(6, 5, 3)
    assert torch.allclose(fit.control_grid, ref, atol=1e-10)
    # exact recovery of a surface in the space
    grid = torch.randn(6, 5, 3, generator=g, dtype=F64)
    u = torch.linspace(0, 1, 12, dtype=F64)
    uu, vv = torch.meshgrid(u, u, indexing="ij")
    samples = bspline_surface(grid, uu.reshape(-1), vv.reshape(-1), (3, 2)).reshape(12, 12, 3)
    from torchgeo_cg.curves import uniform_knots

    fit = fit_bspline_surface(samples, (3, 2), knots_u=uniform_knots(6, 3, dtype=F64),
                              knots_v=uniform_knots(5, 2, dtype=F64), parametrization="uniform")
    assert torch.allclose(fit.control_grid, grid, atol=1e-10) and float(fit.rms) < 1e-12


def test_surface_mesh_is_wound_along_du_cross_dv():
    grid, w, ku, kv = _sphere()
    mesh = surface_mesh(NURBSSurface(grid, w, 2, ku, kv), (17, 9))
    verts = mesh.verts.detach()
    a, b, c = (verts[mesh.faces[:, k]] for k in range(3))
    normal = torch.linalg.cross(b - a, c - a)
    centre = (a + b + c) / 3
    keep = normal.norm(dim=-1) > 1e-9 * normal.norm(dim=-1).max()  # the poles: degenerate
    assert bool(((normal * centre).sum(-1)[keep] > 0).all())  # outward, as the normals
    volume = (torch.linalg.cross(a, b) * c).sum() / 6
    assert 0.9 * 4 / 3 * math.pi < float(volume) < 4 / 3 * math.pi


def test_surface_mesh_feeds_save_mesh_and_chamfer(tmp_path):
    from torchgeo_cg.mesh import load_mesh, save_mesh
    from torchgeo_cg.points import chamfer_distance

    patch = BSplineSurface(torch.randn(5, 5, 3, dtype=F64), 3)
    mesh = surface_mesh(patch, 6)
    save_mesh(tmp_path / "patch.obj", mesh.verts.detach(), mesh.faces)
    loaded = load_mesh(tmp_path / "patch.obj")
    assert torch.allclose(loaded[0].to(F64), mesh.verts.detach(), atol=1e-6)
    loss = chamfer_distance(mesh.verts[None], torch.randn(1, 20, 3, dtype=F64))
    loss = loss[0] if isinstance(loss, tuple) else loss
    loss.sum().backward()
    assert patch.control_grid.grad.abs().sum() > 0


def test_modules_match_functions():
    grid = torch.randn(4, 4, 3, dtype=F64)
    w = 0.5 + torch.rand(4, 4, dtype=F64)
    u, v = torch.rand(2, 5, dtype=F64)
    assert torch.equal(BezierSurface(grid)(u, v), bezier_surface(grid, u, v))
    assert torch.equal(BSplineSurface(grid, 2)(u, v), bspline_surface(grid, u, v, 2))
    assert torch.equal(NURBSSurface(grid, w, 2)(u, v), nurbs_surface(grid, w, u, v, 2))
    assert torch.equal(NURBSSurface(grid, w, 2).derivatives(u, v).normals,
                       nurbs_surface_derivatives(grid, w, u, v, 2).normals)


def test_errors():
    grid = torch.randn(3, 3, 3)
    with pytest.raises(ShapeError, match="control_grid"):
        bspline_surface(grid, torch.rand(4), torch.rand(4), 3)
    with pytest.raises(ShapeError, match="v"):
        bezier_surface(grid, torch.rand(4), torch.rand(5))
    with pytest.raises(ValueError, match="weights"):
        nurbs_surface(grid, -torch.ones(3, 3), torch.rand(4), torch.rand(4), 2)
    with pytest.raises(ValueError, match="knots_u"):
        bspline_surface(grid, torch.rand(4), torch.rand(4), 1, torch.tensor([0.0, 0, 1, 0.5, 1]))


@pytest.mark.grad
def test_gradcheck():
    grid = torch.randn(4, 3, 3, dtype=F64, requires_grad=True)
    w = (0.5 + torch.rand(4, 3, dtype=F64)).requires_grad_()
    u = torch.tensor([0.1, 0.4, 0.8], dtype=F64, requires_grad=True)  # off the knot 0.5
    v = torch.tensor([0.3, 0.6, 0.2], dtype=F64, requires_grad=True)

    def fn(g, ww, a, b):
        d = nurbs_surface_derivatives(g, ww, a, b, 2)
        return d.points, d.du, d.dv, d.normals

    assert torch.autograd.gradcheck(fn, (grid, w, u, v))


def test_chunked_evaluation_equals_one_recorded_pass(monkeypatch):
    patches = __import__("torchgeo_cg.surfaces.patches", fromlist=["_CHUNK"])
    monkeypatch.setattr(patches, "_CHUNK", 14)  # several chunks of 7 parameters per patch
    g = torch.Generator().manual_seed(11)
    grid = torch.randn(2, 6, 5, 3, generator=g, dtype=F64)
    w = 0.5 + torch.rand(2, 6, 5, generator=g, dtype=F64)
    u, v = torch.rand(2, 2, 31, generator=g, dtype=F64)
    chunked = nurbs_surface_derivatives(grid, w, u, v, (3, 2))
    recorded = nurbs_surface_derivatives(grid.clone().requires_grad_(True), w, u, v, (3, 2))
    for a, b in zip(chunked, recorded):  # the same operations: bit for bit
        assert torch.equal(a, b.detach())
    for k in range(2):  # and each patch alone, unbatched, agrees to rounding
        alone = nurbs_surface_derivatives(grid[k], w[k], u[k], v[k], (3, 2))
        for a, b in zip(chunked, alone):
            assert torch.allclose(a[k], b, rtol=1e-13, atol=1e-13)
