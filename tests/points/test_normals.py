"""estimate_normals against analytic sphere and plane normals; orientation, ragged."""

from __future__ import annotations

import math

import pytest
import torch

from torchgeo_cg.core import ShapeError
from torchgeo_cg.points import estimate_normals


def _sphere(n, g, dtype=torch.float64):
    p = torch.randn(n, 3, generator=g, dtype=dtype)
    return p / p.norm(dim=-1, keepdim=True)


def _angle_deg(a, b):
    return torch.rad2deg(torch.acos((a * b).sum(-1).clamp(-1, 1)))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_sphere_outward_within_the_neighbourhood_cap(dtype):
    g = torch.Generator().manual_seed(0)
    p = _sphere(3000, g, dtype)
    n = estimate_normals(p, 10)
    assert n.dtype == dtype
    torch.testing.assert_close(n.norm(dim=-1), torch.ones(3000, dtype=dtype))
    # every neighbour lies within the k-th neighbour distance r_k of the point, so the
    # fitted plane's normal is within the cap's angular radius of the true normal p
    r_k = torch.cdist(p, p).sort(-1).values[:, 9]
    assert bool((torch.deg2rad(_angle_deg(n, p)) <= r_k).all())  # outward, too


def test_plane_normals_exact_and_viewpoint():
    g = torch.Generator().manual_seed(1)
    uv = torch.rand(500, 2, generator=g, dtype=torch.float64)
    axis_u = torch.tensor([1.0, 2.0, 2.0], dtype=torch.float64) / 3
    axis_v = torch.tensor([2.0, 1.0, -2.0], dtype=torch.float64) / 3
    normal = torch.linalg.cross(axis_u, axis_v)
    p = uv[:, :1] * axis_u + uv[:, 1:] * axis_v + torch.tensor([1.0, -2.0, 0.5])
    for sign in (1.0, -1.0):
        view = p.mean(0) + sign * 10 * normal
        n = estimate_normals(p, 8, viewpoint=view)
        torch.testing.assert_close(n, (sign * normal).expand_as(n), atol=1e-12, rtol=0)


def test_ragged_equals_each_cloud_and_padding_is_zero():
    g = torch.Generator().manual_seed(2)
    p = torch.stack([_sphere(300, g), 2 * _sphere(300, g) + 1])
    lengths = torch.tensor([300, 170])
    n = estimate_normals(p, 10, lengths)
    torch.testing.assert_close(n[0], estimate_normals(p[0], 10))
    torch.testing.assert_close(n[1, :170], estimate_normals(p[1, :170], 10))
    assert (n[1, 170:] == 0).all()


def test_scale_free_and_nan():
    g = torch.Generator().manual_seed(3)
    p = _sphere(200, g)
    ref = estimate_normals(p, 8)
    for s in (1e-6, 1e6):
        torch.testing.assert_close(estimate_normals(p * s, 8), ref, atol=1e-12, rtol=0)
    bad = p.clone()
    bad[5, 1] = math.nan
    assert estimate_normals(bad, 8).isnan().all()
    assert not estimate_normals(p, 8).isnan().any()


def test_degenerate_neighbourhood_is_unit_not_nan():
    n = estimate_normals(torch.zeros(5, 3), 3)
    torch.testing.assert_close(n.norm(dim=-1), torch.ones(5))


def test_bad_arguments():
    with pytest.raises(ShapeError, match="points"):
        estimate_normals(torch.zeros(4, 1), 3)
    with pytest.raises(ValueError, match="k"):
        estimate_normals(torch.zeros(4, 3), 1)
    with pytest.raises(ShapeError, match="viewpoint"):
        estimate_normals(torch.zeros(4, 3), 3, viewpoint=torch.zeros(2))
    with pytest.raises(TypeError, match="viewpoint"):
        estimate_normals(torch.zeros(4, 3), 3, viewpoint=torch.zeros(3, dtype=torch.float64))
