"""NaN in an argument other than the first is never swallowed.

The contract suite puts NaN into each callable's primary argument; these cases put it
where a selection or a comparison could drop it: a triangle corner, a volume
sample, the time of a constant transform.
"""

from __future__ import annotations

import math

import pytest
import torch

from torchgeo_cg.sdf import closest_point_on_triangle, zero_level_set
from torchgeo_cg.sdf.grid import sample_grid
from torchgeo_cg.transforms import FixedTransform, translation

F64 = torch.float64


@pytest.mark.parametrize("corner", [0, 1, 2])
def test_closest_point_on_triangle_nan_vertex(corner):
    tri = [torch.tensor(v, dtype=F64) for v in ([0.0, 0, 0], [1.0, 0, 0], [0.0, 1, 0])]
    points = torch.tensor([[0.2, 0.2, 1.0], [3.0, -1.0, 0.0], [-1.0, 5.0, 2.0]], dtype=F64)
    tri[corner] = torch.tensor([math.nan, 0.0, 0.0], dtype=F64)
    out = closest_point_on_triangle(points, *tri)
    assert out.points.shape == (3, 3)
    assert bool(torch.isnan(out.points).all())
    # a NaN in one batch item leaves the others alone
    good = [torch.tensor(v, dtype=F64) for v in ([0.0, 0, 0], [1.0, 0, 0], [0.0, 1, 0])]
    both = [torch.stack([g, t]) for g, t in zip(good, tri)]
    out = closest_point_on_triangle(points[:2], *both)
    torch.testing.assert_close(out.points[0], torch.tensor([0.2, 0.2, 0.0], dtype=F64))
    assert bool(torch.isnan(out.points[1]).all())


def test_zero_level_set_nan_sample_raises():
    vol = sample_grid(lambda p: p[:, 0] - 0.5, 5, (0.0, 1.0))
    values = vol.values.clone()
    values[4, 4, 4] = math.nan  # far from the surface: a comparison would drop it silently
    with pytest.raises(ValueError, match="volume.*NaN.*1 of 125"):
        zero_level_set(vol._replace(values=values))
    with pytest.raises(ValueError, match="volume"):
        zero_level_set(values[None].expand(2, 5, 5, 5), vol.origin, vol.spacing)
    assert zero_level_set(vol).points.shape == (25, 3)


def test_fixed_transform_at_nan_theta():
    fixed = FixedTransform(translation(torch.tensor([1.0, 2.0], dtype=F64)))
    theta = torch.tensor([0.0, math.nan, 3.0], dtype=F64)
    out = fixed(theta)
    assert out.shape == (3, 3, 3)
    assert bool(torch.isnan(out[1]).all())
    torch.testing.assert_close(out[[0, 2]], fixed.matrix.expand(2, 3, 3))
