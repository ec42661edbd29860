"""gradcheck in float64 for project, unproject, undistort and pixel_rays, in every tensor
input (the inverse's gradients come by implicit differentiation)."""

from __future__ import annotations

import pytest
import torch
from torch.autograd import gradcheck

import torchgeo_cg.cameras as C
from tests.cameras.lenses import pose

F64 = torch.float64
LENS = {4: [-0.2, 0.05, 1e-3, -2e-3], 5: [-0.2, 0.05, 1e-3, -2e-3, 0.01],
        8: [-0.3, 0.08, 1e-3, -5e-4, -0.01, 0.05, 0.01, 2e-3],
        14: [-0.25, 0.06, 8e-4, -6e-4, -0.008, 0.04, 0.008, 1e-3, 1e-3, -5e-4, 8e-4, 3e-4,
             0.01, -0.02]}


def _inputs(length: int, fisheye: bool = False):
    g = torch.Generator().manual_seed(length)
    K = torch.tensor([[500.0, 0.5, 320.0], [0.0, 480.0, 240.0], [0.0, 0.0, 1.0]], dtype=F64)
    dist = torch.tensor([0.05, -0.02, 0.003, -5e-4] if fisheye else LENS[length], dtype=F64)
    ext = pose()
    pts = torch.randn(2, 5, 3, generator=g, dtype=F64)
    pts[..., 2] = pts[..., 2].abs() + 2
    return [t.clone().requires_grad_(True) for t in (pts, K, dist, ext)]


SLOW = pytest.mark.slow


@pytest.mark.grad
@pytest.mark.parametrize("length", [4, pytest.param(5, marks=SLOW), pytest.param(8, marks=SLOW),
                                    pytest.param(14, marks=SLOW)])
def test_gradcheck_project_and_unproject(length):
    pts, K, dist, ext = _inputs(length)
    assert gradcheck(lambda p, k, d, e: C.project_points(p, k, d, e), (pts, K, dist, ext))
    px = C.project_points(pts, K, dist, ext).detach().requires_grad_(True)
    depth = torch.full((2, 5), 3.0, dtype=F64, requires_grad=True)
    assert gradcheck(lambda p, z, k, d, e: C.unproject_points(p, z, k, d, e).points,
                     (px, depth, K, dist, ext))


@pytest.mark.grad
@pytest.mark.parametrize("length", [4, pytest.param(8, marks=SLOW), pytest.param(14, marks=SLOW)])
def test_gradcheck_undistort_and_pixel_rays(length):
    pts, K, dist, ext = _inputs(length)
    g = torch.Generator().manual_seed(9)
    xy = (0.4 * torch.rand(7, 2, generator=g, dtype=F64) - 0.2).requires_grad_(True)
    assert gradcheck(lambda x, d: C.undistort_points(x, d).points, (xy, dist))
    px = C.project_points(pts, K, dist, ext).detach().requires_grad_(True)
    assert gradcheck(lambda p, k, d, e: C.pixel_rays(p, k, d, e)[:2], (px, K, dist, ext))


@pytest.mark.grad
@pytest.mark.slow
def test_gradcheck_fisheye():
    pts, K, dist, ext = _inputs(4, fisheye=True)
    assert gradcheck(lambda p, k, d, e: C.project_points(p, k, d, e, "fisheye"),
                     (pts, K, dist, ext))
    px = C.project_points(pts, K, dist, ext, "fisheye").detach().requires_grad_(True)
    depth = torch.full((2, 5), 3.0, dtype=F64, requires_grad=True)
    for ray_distance in (False, True):
        assert gradcheck(lambda p, z, k, d, e, r=ray_distance: C.unproject_points(
            p, z, k, d, e, "fisheye", r).points, (px, depth, K, dist, ext))
    assert gradcheck(lambda p, k, d, e: C.pixel_rays(p, k, d, e, "fisheye")[:2],
                     (px, K, dist, ext))
    xy = torch.tensor([[0.3, -0.2], [0.0, 0.0], [1.0, 0.5]], dtype=F64, requires_grad=True)
    assert gradcheck(lambda x, d: C.fisheye_undistort_points(x, d).points, (xy, dist))


@pytest.mark.grad
def test_gradient_matches_finite_difference_of_the_forward_map():
    """d undistort / d xy is the inverse of d distort / d x at the solution."""
    dist = torch.tensor(LENS[14], dtype=F64)
    x = torch.tensor([[0.3, -0.25]], dtype=F64)
    jac_fwd = torch.autograd.functional.jacobian(lambda a: C.distort_points(a, dist), x)
    xd = C.distort_points(x, dist)
    jac_inv = torch.autograd.functional.jacobian(lambda a: C.undistort_points(a, dist).points,
                                                 xd)
    eye = jac_inv[0, :, 0, :] @ jac_fwd[0, :, 0, :]
    assert torch.allclose(eye, torch.eye(2, dtype=F64), atol=1e-12)


def test_no_nan_gradient_at_the_principal_point_and_where_invalid():
    K = torch.eye(3, dtype=F64)
    dist = torch.tensor([-0.45, 0.05, 0.0, 0.0], dtype=F64, requires_grad=True)
    px = torch.tensor([[0.0, 0.0], [0.9, 0.0], [0.3, 0.1]], dtype=F64, requires_grad=True)
    rays = C.pixel_rays(px, K, dist)
    assert rays.valid.tolist() == [True, False, True]
    rays.directions.sum().backward()
    assert px.grad.isfinite().all() and dist.grad.isfinite().all()
