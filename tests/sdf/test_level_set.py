"""The report's zero-level-set extraction against numpy isclose/where, as the report did it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.sdf.grid import grid_points, sample_grid
from torchgeo_cg.sdf.level_set import zero_level_set
from torchgeo_cg.sdf.primitives import torus


def test_matches_numpy_isclose_where():
    res, bounds, tol = 41, (-1.5, 1.5), 2e-3
    vol = sample_grid(lambda p: torus(p, 1.0, 0.5, exact=False), res, bounds, dtype=torch.float64)
    ls = zero_level_set(vol, tol=tol)
    # the report: numpy isclose (|f| <= atol) and where on the same grid
    g = grid_points(res, bounds, dtype=torch.float64).numpy()
    x, y, z = g[..., 0], g[..., 1], g[..., 2]
    f = (np.sqrt(x**2 + y**2) - 1.0) ** 2 + z**2 - 0.25
    idx = np.stack(np.where(np.isclose(f, 0.0, atol=tol, rtol=0)), -1)
    assert len(idx) > 0
    assert np.array_equal(ls.indices.numpy(), idx)
    assert_close(ls.points, g[tuple(idx.T)])
    assert ls.counts.tolist() == [len(idx)] and (ls.batch == 0).all()
    f_at = torus(ls.points, 1.0, 0.5, exact=False)
    assert (f_at.abs() < tol).all()


def test_batched_and_plain_tensor():
    vals = torch.tensor([[[[0.0, 1.0], [1.0, 1.0]], [[1.0, 1.0], [1.0, 0.0]]],
                         [[[1.0, 1.0], [1.0, 1.0]], [[1.0, 1.0], [1.0, 1.0]]]])
    ls = zero_level_set(vals, torch.zeros(3), torch.full((3,), 0.5))
    assert ls.counts.tolist() == [2, 0]
    assert_close(ls.points, torch.tensor([[0.0, 0.0, 0.0], [0.5, 0.5, 0.5]]))


def test_fixed_tolerance_misses_surface_at_coarse_resolution():
    """Why |f| < 1e-4 is a poor surface: almost no sample falls in the thin band."""
    fine = zero_level_set(sample_grid(lambda p: torus(p, exact=False), 64, (-1.5, 1.5)))
    assert fine.points.shape[0] < 50  # a 64^3 grid has ~10^4 samples next to the surface


def test_bad_input():
    with pytest.raises(TypeError, match="origin and spacing"):
        zero_level_set(torch.zeros(2, 2, 2))
    with pytest.raises(ShapeError, match="volume"):
        zero_level_set(torch.zeros(2, 2), torch.zeros(3), torch.ones(3))
    with pytest.raises(ValueError, match="tol"):
        zero_level_set(torch.zeros(2, 2, 2), torch.zeros(3), torch.ones(3), tol=0.0)
