"""The grid convention: round trips, chunked sampling, trilinear lookup vs scipy."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from scipy.interpolate import RegularGridInterpolator

from torchgeo_cg.core import grid as CG
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.sdf import grid as G
from torchgeo_cg.sdf.primitives import sphere, torus

BOUNDS = ((-1.0, -2.0, 0.0), (1.0, 1.0, 0.5))


@given(i=st.integers(0, 4), j=st.integers(0, 6), k=st.integers(0, 2))
def test_index_world_round_trip(i, j, k):
    res = (5, 7, 3)
    pts = G.grid_points(res, BOUNDS, dtype=torch.float64)
    origin, spacing = G.grid_spacing(res, BOUNDS, dtype=torch.float64)
    ijk = torch.tensor([i, j, k])
    assert_close(pts[i, j, k], CG.index_to_world(ijk, origin, spacing))
    assert_close(CG.world_to_index(pts[i, j, k], origin, spacing), ijk.double())
    # axis 0 is x, 1 is y, 2 is z; both bounds are samples
    assert_close(pts[-1, -1, -1], torch.tensor(BOUNDS[1]))
    assert_close(pts[0, 0, 0], torch.tensor(BOUNDS[0]))


def test_grid_points_matches_meshgrid_ij_and_xy(device, dtype):
    res = (4, 3, 2)
    g = G.grid_points(res, BOUNDS, device=device, dtype=dtype)
    xs = [torch.linspace(BOUNDS[0][a], BOUNDS[1][a], res[a], device=device, dtype=dtype)
          for a in range(3)]
    assert g.dtype == dtype and g.device == xs[0].device and g.shape == (4, 3, 2, 3)
    assert_close(g, torch.stack(torch.meshgrid(*xs, indexing="ij"), -1))
    gxy = G.grid_points(res, BOUNDS, indexing="xy", device=device, dtype=dtype)
    assert gxy.shape == (3, 4, 2, 3)
    assert_close(gxy, g.transpose(0, 1))


@pytest.mark.parametrize("chunk", [1, 7, 1 << 18])
def test_sample_grid_equals_dense_evaluation(chunk):
    res = (9, 6, 5)
    vol = G.sample_grid(lambda p: torus(p, 0.6, 0.2), res, BOUNDS, chunk=chunk,
                        dtype=torch.float64)
    dense = torus(G.grid_points(res, BOUNDS, dtype=torch.float64), 0.6, 0.2)
    assert vol.values.shape == res
    assert_close(vol.values, dense)
    origin, spacing = G.grid_spacing(res, BOUNDS, dtype=torch.float64)
    assert_close(vol.origin, origin)
    assert_close(vol.spacing, spacing)


def test_sample_grid_batched_shapes():
    radii = torch.tensor([0.3, 0.5, 0.9])
    vol = G.sample_grid(lambda p: sphere(p.expand(3, -1, -1), radii), 6, (-1.0, 1.0), chunk=40)
    assert vol.values.shape == (3, 6, 6, 6)
    dense = G.grid_points(6, (-1.0, 1.0)).norm(dim=-1)
    for b in range(3):
        assert_close(vol.values[b], dense - radii[b])


def test_sample_grid_grad_mode():
    r = torch.tensor(0.5, requires_grad=True)
    vol = G.sample_grid(lambda p: sphere(p, r), 4, chunk=16, grad=True)
    vol.values.sum().backward()
    assert_close(r.grad, torch.tensor(-64.0))
    assert not G.sample_grid(lambda p: sphere(p, r), 4).values.requires_grad


def test_grid_interpolate_matches_scipy(dtype):
    res = (7, 5, 6)
    vol = G.sample_grid(lambda p: torus(p, 0.6, 0.2), res, BOUNDS, dtype=torch.float64)
    axes = [np.linspace(BOUNDS[0][a], BOUNDS[1][a], res[a]) for a in range(3)]
    ref = RegularGridInterpolator(axes, vol.values.numpy(), method="linear")
    rng = np.random.default_rng(0)
    q = rng.uniform(BOUNDS[0], BOUNDS[1], size=(2, 50, 3))
    out = G.grid_interpolate(CG.Volume(vol.values.to(dtype), vol.origin.to(dtype),
                                      vol.spacing.to(dtype)), torch.tensor(q, dtype=dtype))
    assert out.shape == (2, 50) and out.dtype == dtype
    assert_close(out, ref(q.reshape(-1, 3)).reshape(2, 50), scale=10)


def test_grid_interpolate_reproduces_linear_fields_and_border():
    vol = G.sample_grid(lambda p: 1 + p[:, 0] - 2 * p[:, 1] + 3 * p[:, 2], (3, 4, 5), BOUNDS,
                        dtype=torch.float64)
    q = torch.rand(100, 3, dtype=torch.float64) * (torch.tensor(BOUNDS[1], dtype=torch.float64)
                                                   - torch.tensor(BOUNDS[0])) + torch.tensor(
        BOUNDS[0])
    exact = 1 + q[:, 0] - 2 * q[:, 1] + 3 * q[:, 2]
    assert_close(G.grid_interpolate(vol, q), exact)
    # plain tensor + origin/spacing, and clamping outside
    outside = torch.tensor([[5.0, -1.0, 0.25]], dtype=torch.float64)
    clamped = torch.tensor([[1.0, -1.0, 0.25]], dtype=torch.float64)
    assert_close(G.grid_interpolate(vol.values, outside, vol.origin, vol.spacing),
                 G.grid_interpolate(vol, clamped))


def test_grid_interpolate_batched_and_gradcheck():
    vals = torch.randn(2, 4, 3, 5, dtype=torch.float64, requires_grad=True)
    origin = torch.tensor([0.0, 0.0, 0.0], dtype=torch.float64)
    spacing = torch.tensor([0.5, 1.0, 0.25], dtype=torch.float64)
    pts = (torch.rand(2, 6, 3, dtype=torch.float64) * torch.tensor([1.5, 2.0, 1.0],
                                                                   dtype=torch.float64))
    pts.requires_grad_(True)
    out = G.grid_interpolate(vals, pts, origin, spacing)
    assert out.shape == (2, 6)
    single = G.grid_interpolate(vals[1], pts[1], origin, spacing)
    assert_close(out[1], single)
    assert torch.autograd.gradcheck(lambda v, p: G.grid_interpolate(v, p, origin, spacing),
                                    (vals, pts))


def test_bad_input():
    with pytest.raises(ValueError, match="at least 2"):
        G.grid_points(1)
    with pytest.raises(ValueError, match="at least 2"):
        G.sample_grid(sphere, (4, 1, 4))
    with pytest.raises(TypeError, match="resolution"):
        G.grid_points((4, 4))
    with pytest.raises(ValueError, match="lo < hi"):
        G.grid_points(4, (1.0, -1.0))
    with pytest.raises(ShapeError, match="bounds"):
        G.grid_points(4, ((0.0, 0.0), (1.0, 1.0)))
    with pytest.raises(ValueError, match="indexing"):
        G.grid_points(4, indexing="xyz")
    with pytest.raises(ValueError, match="chunk"):
        G.sample_grid(sphere, 4, chunk=0)
    with pytest.raises(ShapeError, match="sdf_fn"):
        G.sample_grid(lambda p: p, 4)
    with pytest.raises(TypeError, match="origin and spacing"):
        G.grid_interpolate(torch.zeros(3, 3, 3), torch.zeros(1, 3))
    with pytest.raises(ShapeError, match="volume"):
        G.grid_interpolate(torch.zeros(3, 3), torch.zeros(1, 3), torch.zeros(3), torch.ones(3))
    with pytest.raises(ShapeError, match="points"):
        G.grid_interpolate(torch.zeros(2, 3, 3, 3), torch.zeros(3, 1, 3), torch.zeros(3),
                           torch.ones(3))


def test_sample_grid_progress_bar(capsys):
    quiet = G.sample_grid(sphere, 9, (-1.0, 1.0), chunk=81)
    shown = G.sample_grid(sphere, 9, (-1.0, 1.0), chunk=81, progress=True)  # one slab a chunk
    assert torch.equal(quiet.values, shown.values)
    err = capsys.readouterr().err
    assert "sample_grid" in err and "9/9" in err
    assert "sample_grid" not in capsys.readouterr().err  # nothing more, and off by default
