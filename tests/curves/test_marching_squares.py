"""Marching squares against skimage.measure.find_contours, plus gradients and batching."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from skimage.measure import find_contours

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.curves import (
    figure_eight_implicit,
    grid_2d,
    implicit_circle,
    marching_squares,
)
from torchgeo_cg.curves._marching_squares_tables import SEGMENTS


def _directed_edges(polylines) -> np.ndarray:
    """All (from, to) vertex pairs, sorted: equal iff same vertices, topology and direction."""
    pairs = [np.concatenate([p[k], p[k + 1]]) for p in polylines for k in range(len(p) - 1)]
    pairs = np.array(pairs).reshape(-1, 4)
    return pairs[np.lexsort(pairs.T[::-1])]


def _edge_distance(ours, ref) -> float:
    """Hausdorff distance between the directed-edge sets (inf if the counts differ)."""
    a, b = _directed_edges(ours), _directed_edges(ref)
    if a.shape != b.shape:
        return float("inf")
    if a.size == 0:
        return 0.0
    d = np.abs(a[:, None, :] - b[None, :, :]).max(-1)
    return float(max(d.min(0).max(), d.min(1).max()))


def _smooth_field(seed: int, shape=(48, 40)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = np.linspace(-3, 3, shape[0])[:, None]
    y = np.linspace(-2, 2.5, shape[1])[None, :]
    a, b, c = rng.uniform(0.5, 2.0, 3)
    return np.sin(a * x) * np.cos(b * y) + 0.3 * c * x * y + 0.1 * rng.standard_normal()


@pytest.mark.parametrize("fully_connected", ["low", "high"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_skimage_find_contours(seed, fully_connected):
    field = _smooth_field(seed)
    iso = 0.05 * seed
    ref = find_contours(field, iso, fully_connected=fully_connected)
    result = marching_squares(torch.tensor(field), iso, fully_connected=fully_connected)
    ours = [p.numpy() for p in result.polylines()]
    assert len(ours) == len(ref)
    assert sorted(map(len, ours)) == sorted(map(len, ref))
    assert _edge_distance(ours, ref) < 1e-6
    # Closed flags agree with repeated endpoints, as in skimage.
    for poly, closed in zip(ours, result.closed.tolist()):
        assert closed == bool(np.allclose(poly[0], poly[-1]))


def test_table_reproduces_skimage_on_every_2x2_case():
    offsets = np.array([[0.1, 0.2], [0.3, 0.05]])
    for fc in ("low", "high"):
        for case in range(16):
            bits = [(case >> k) & 1 for k in range(4)]
            cell = np.array([[bits[0], bits[1]], [bits[2], bits[3]]], float) * 2 - 1 + offsets
            ref = find_contours(cell, 0.0, fully_connected=fc)
            ours = marching_squares(torch.tensor(cell), 0.0, fully_connected=fc).polylines()
            count = sum(s[0] >= 0 for s in SEGMENTS[fc][case])
            assert len(ref) == len(ours) == count
            if count:
                assert _edge_distance([o.numpy() for o in ours], ref) < 1e-12


def test_origin_spacing_and_axis_convention(device, dtype):
    # Circle of radius 1.13 centred at (0.4, -0.2) on a grid with different x/y spacing.
    xs = torch.linspace(-2, 2, 41, device=device, dtype=dtype)
    ys = torch.linspace(-1.5, 1.5, 61, device=device, dtype=dtype)
    xy = torch.stack(torch.meshgrid(xs, ys, indexing="ij"), dim=-1)
    field = implicit_circle(xy, (0.4, -0.2), 1.13)
    spacing = (float(xs[1] - xs[0]), float(ys[1] - ys[0]))
    result = marching_squares(field, 0.0, origin=(-2.0, -1.5), spacing=spacing)
    assert result.vertices.dtype == dtype and result.vertices.device.type == device.type
    assert result.closed.tolist() == [True]
    radius = (result.vertices - torch.tensor([0.4, -0.2], device=device, dtype=dtype)).norm(dim=-1)
    assert (radius - 1.13).abs().max() < 5e-3  # linear interpolation error of a circle
    ref = find_contours(field.cpu().double().numpy(), 0.0)[0]
    ref_xy = np.array([-2.0, -1.5]) + ref * np.array(spacing)
    tol = 1e-6 if dtype == torch.float64 else 1e-4
    assert _edge_distance([result.vertices.cpu().double().numpy()], [ref_xy]) < tol


def test_batch_and_empty():
    fields = torch.stack([torch.tensor(_smooth_field(s)) for s in range(3)]).reshape(3, 1, 48, 40)
    result = marching_squares(fields, 0.1)
    for b in range(3):
        mine = [p for p, k in zip(result.polylines(), result.batch.tolist()) if k == b]
        single = marching_squares(fields[b, 0], 0.1).polylines()
        assert len(mine) == len(single)
        assert _edge_distance([p.numpy() for p in mine], [p.numpy() for p in single]) < 1e-12
    nothing = marching_squares(torch.ones(4, 5), 0.0)
    assert nothing.vertices.shape == (0, 2) and nothing.lengths.shape == (0,)
    assert marching_squares(torch.zeros(0, 4, 5)).vertices.shape == (0, 2)


def test_nan_cells_are_skipped_like_skimage():
    field = _smooth_field(4)
    field[20, 20] = np.nan
    ref = find_contours(field, 0.0)
    ours = [p.numpy() for p in marching_squares(torch.tensor(field), 0.0).polylines()]
    assert _edge_distance(ours, ref) < 1e-6


def test_gradient_with_respect_to_field_values():
    field = torch.tensor(_smooth_field(5, (12, 10)), requires_grad=True)

    def vertices(f):
        return marching_squares(f, 0.1).vertices

    assert torch.autograd.gradcheck(vertices, (field,))
    loss = vertices(field).sum()
    loss.backward()
    assert field.grad.isfinite().all() and field.grad.abs().sum() > 0


def test_figure_eight_crossing_is_finite():
    xy = grid_2d(101, -10.0, 10.0, dtype=torch.float64)
    field = figure_eight_implicit(xy, 5.0).requires_grad_(True)
    result = marching_squares(field, 0.0, origin=(-10.0, -10.0), spacing=(0.2, 0.2))
    assert result.vertices.isfinite().all()
    result.vertices.sum().backward()
    assert field.grad.isfinite().all()
    radius_left = (result.vertices - torch.tensor([-5.0, 0.0], dtype=torch.float64)).norm(dim=-1)
    radius_right = (result.vertices - torch.tensor([5.0, 0.0], dtype=torch.float64)).norm(dim=-1)
    on_a_circle = torch.minimum((radius_left - 5).abs(), (radius_right - 5).abs())
    assert on_a_circle.max() < 0.1


def test_bad_input():
    with pytest.raises(ShapeError, match="H, W >= 2"):
        marching_squares(torch.zeros(1, 5))
    with pytest.raises(ShapeError, match="field"):
        marching_squares(torch.zeros(5))
    with pytest.raises(TypeError, match="field: expected a floating-point"):
        marching_squares(torch.zeros(3, 3, dtype=torch.long))
    with pytest.raises(ValueError, match="fully_connected"):
        marching_squares(torch.zeros(3, 3), fully_connected="diag")
    with pytest.raises(ShapeError, match="origin"):
        marching_squares(torch.zeros(3, 3), origin=(0.0, 0.0, 0.0))
    with pytest.raises(TypeError, match="spacing"):
        marching_squares(torch.zeros(3, 3), spacing="wide")
