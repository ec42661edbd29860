"""Marching squares against skimage.measure.find_contours, plus gradients and batching."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from skimage.measure import find_contours

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.grid import Volume
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
    assert result.verts.dtype == dtype and result.verts.device.type == device.type
    assert result.closed.tolist() == [True]
    radius = (result.verts - torch.tensor([0.4, -0.2], device=device, dtype=dtype)).norm(dim=-1)
    assert (radius - 1.13).abs().max() < 5e-3  # linear interpolation error of a circle
    ref = find_contours(field.cpu().double().numpy(), 0.0)[0]
    ref_xy = np.array([-2.0, -1.5]) + ref * np.array(spacing)
    tol = 1e-6 if dtype == torch.float64 else 1e-4
    assert _edge_distance([result.verts.cpu().double().numpy()], [ref_xy]) < tol


def test_batch_and_empty():
    fields = torch.stack([torch.tensor(_smooth_field(s)) for s in range(3)]).reshape(3, 1, 48, 40)
    result = marching_squares(fields, 0.1)
    for b in range(3):
        mine = [p for p, k in zip(result.polylines(), result.batch.tolist()) if k == b]
        single = marching_squares(fields[b, 0], 0.1).polylines()
        assert len(mine) == len(single)
        assert _edge_distance([p.numpy() for p in mine], [p.numpy() for p in single]) < 1e-12
    nothing = marching_squares(torch.ones(4, 5), 0.0)
    assert nothing.verts.shape == (0, 2) and nothing.lengths.shape == (0,)
    assert marching_squares(torch.zeros(0, 4, 5)).verts.shape == (0, 2)


def test_nan_cells_are_skipped_like_skimage():
    field = _smooth_field(4)
    field[20, 20] = np.nan
    ref = find_contours(field, 0.0)
    ours = [p.numpy() for p in marching_squares(torch.tensor(field), 0.0).polylines()]
    assert _edge_distance(ours, ref) < 1e-6


def test_gradient_with_respect_to_field_values():
    field = torch.tensor(_smooth_field(5, (12, 10)), requires_grad=True)

    def vertices(f):
        return marching_squares(f, 0.1).verts

    assert torch.autograd.gradcheck(vertices, (field,))
    loss = vertices(field).sum()
    loss.backward()
    assert field.grad.isfinite().all() and field.grad.abs().sum() > 0


def test_figure_eight_crossing_is_finite():
    xy = grid_2d(101, -10.0, 10.0, dtype=torch.float64)
    field = figure_eight_implicit(xy, 5.0).requires_grad_(True)
    result = marching_squares(field, 0.0, origin=(-10.0, -10.0), spacing=(0.2, 0.2))
    assert result.verts.isfinite().all()
    result.verts.sum().backward()
    assert field.grad.isfinite().all()
    radius_left = (result.verts - torch.tensor([-5.0, 0.0], dtype=torch.float64)).norm(dim=-1)
    radius_right = (result.verts - torch.tensor([5.0, 0.0], dtype=torch.float64)).norm(dim=-1)
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
    for bad in [(0.0, 1.0), (1.0, -1.0), -2.0, (1.0, float("nan")), (float("inf"), 1.0)]:
        with pytest.raises(ValueError, match="spacing"):
            marching_squares(torch.zeros(3, 3), spacing=bad)
    with pytest.raises(ShapeError, match="spacing"):
        marching_squares(torch.zeros(3, 3), spacing=torch.ones(3))
    with pytest.raises(TypeError, match="iso"):
        marching_squares(torch.zeros(3, 3), iso="0")
    volume = Volume(torch.zeros(3, 3), torch.zeros(2), torch.ones(2))
    with pytest.raises(TypeError, match="origin"):
        marching_squares(volume, origin=(0.0, 0.0))
    with pytest.raises(ShapeError, match="field"):
        marching_squares(Volume(torch.zeros(3, 3, 2), torch.zeros(3), torch.ones(3)))


# --------------------------------------------------------- tie rule and asymptotic decider
def _is_degenerate(poly: np.ndarray) -> bool:
    return bool(np.all(poly == poly[0]) or (np.diff(poly, axis=0) == 0).all(1).any())


def test_sample_equal_to_the_level_is_high_like_marching_cubes():
    lone = torch.tensor([[1.0, 1.0, 1.0], [1.0, 0.0, 1.0], [1.0, 1.0, 1.0]])
    assert marching_squares(lone, 0.0).lengths.numel() == 0  # 0 is high: no crossing
    assert len(find_contours(lone.numpy(), 0.0)) == 0  # skimage: none either
    cell = torch.tensor([[-0.08, 0.24], [0.24, 0.0]], dtype=torch.float64)
    assert len(marching_squares(cell, 0.0).polylines()) == 1 == len(find_contours(cell.numpy(), 0))
    hole = -lone  # a high sample exactly at the level among low ones: a tiny closed loop
    result = marching_squares(hole, 0.0)
    (poly,) = [p.numpy() for p in result.polylines()]
    assert result.closed.tolist() == [True] and not _is_degenerate(poly)
    assert np.abs(poly - 1.0).max() < 1e-3  # around the sample (1, 1)


@pytest.mark.parametrize("seed", range(20))
def test_fields_with_ties_have_no_degenerate_polylines_and_close_inside(seed):
    rng = np.random.default_rng(seed)
    field = torch.tensor(rng.integers(-1, 2, (9, 8)).astype(np.float64))
    result = marching_squares(field, 0.0)
    polys = [p.numpy() for p in result.polylines()]
    assert all(not _is_degenerate(p) for p in polys)
    for poly, closed in zip(polys, result.closed.tolist()):
        on_border = lambda q: q[0] in (0, 8) or q[1] in (0, 7)  # noqa: E731
        if closed:
            assert np.array_equal(poly[0], poly[-1])
        else:  # an open polyline runs from border to border
            assert on_border(poly[0]) and on_border(poly[-1])
    # the level set of a field padded with high values is closed everywhere
    padded = torch.nn.functional.pad(field, (1, 1, 1, 1), value=1.0)
    assert marching_squares(padded, 0.0).closed.all()


def _saddle_value(cell: np.ndarray) -> float:
    """Value of the bilinear interpolant at its critical point (brute force: solve grad = 0)."""
    (a, b), (c, d) = cell  # f(x, y) = a (1-x)(1-y) + b (1-x) y + c x (1-y) + d x y
    k = a - b - c + d
    x, y = (a - b) / k, (a - c) / k  # df/dy = 0 and df/dx = 0
    return a * (1 - x) * (1 - y) + b * (1 - x) * y + c * x * (1 - y) + d * x * y


def test_asymptotic_decider_on_random_saddle_cells_against_skimage_rules():
    rng = np.random.default_rng(0)
    checked = 0
    for _ in range(200):
        mag = rng.uniform(0.05, 1.0, 4)
        sign = np.array([-1, 1, 1, -1]) * rng.choice([-1, 1])
        cell = (mag * sign).reshape(2, 2)
        iso = 0.0
        rule = "low" if _saddle_value(cell) < iso else "high"
        ref = find_contours(cell, iso, fully_connected=rule)
        ours = marching_squares(torch.tensor(cell), iso).polylines()
        assert len(ours) == 2
        assert _edge_distance([o.numpy() for o in ours], ref) < 1e-12
        checked += 1
    assert checked == 200


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_asymptotic_matches_skimage_on_smooth_fields_without_saddle_cells(seed):
    field = _smooth_field(seed)
    iso = 0.05 * seed
    result = marching_squares(torch.tensor(field), iso)
    for rule in ("low", "high"):
        ref = find_contours(field, iso, fully_connected=rule)
        assert _edge_distance([p.numpy() for p in result.polylines()], ref) < 1e-6


def test_volume_input_and_scale_invariance():
    xs = torch.linspace(-2, 2, 41, dtype=torch.float64)
    xy = torch.stack(torch.meshgrid(xs, xs, indexing="ij"), dim=-1)
    field = implicit_circle(xy, (0.4, -0.2), 1.13)
    origin, spacing = torch.full((2,), -2.0, dtype=torch.float64), torch.full((2,), 0.1,
                                                                              dtype=torch.float64)
    want = marching_squares(field, 0.0, origin=origin, spacing=spacing)
    got = marching_squares(Volume(field, origin, spacing))
    torch.testing.assert_close(got.verts, want.verts)
    one_slice = Volume(field[..., None], torch.tensor([-2.0, -2.0, 5.0], dtype=torch.float64),
                       torch.tensor([0.1, 0.1, 1.0], dtype=torch.float64))
    torch.testing.assert_close(marching_squares(one_slice).verts, want.verts)
    rng = np.random.default_rng(3)
    noisy = torch.tensor(rng.standard_normal((20, 20)))
    ref = marching_squares(noisy, 0.0)
    for s in (1e-12, 1e-6, 1e6, 1e12):
        scaled = marching_squares(noisy * s, 0.0)
        assert torch.equal(scaled.lengths, ref.lengths)
        torch.testing.assert_close(scaled.verts, ref.verts, rtol=0, atol=1e-12)


# --- contract regressions ----------------------------------------------------------------


def _ring_fields(dtype) -> torch.Tensor:
    x = torch.linspace(-1, 1, 7, dtype=torch.float64)
    r2 = x[:, None] ** 2 + x[None, :] ** 2
    return torch.stack([r2 - 0.5, 0.3 - r2]).to(dtype)


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16])
def test_low_precision_is_computed_in_float32_and_cast_back(low):
    """float16/bfloat16 fields returned float32 vertices; now the field's dtype, equal to
    the float32 computation cast back (same topology, vertices within one rounding)."""
    fields = _ring_fields(low)
    out = marching_squares(fields, origin=(0.5, -1.0), spacing=(0.25, 0.5))
    ref = marching_squares(fields.float(), origin=(0.5, -1.0), spacing=(0.25, 0.5))
    assert out.verts.dtype == low
    for got, want in zip(out[1:], ref[1:]):
        assert torch.equal(got, want)
    torch.testing.assert_close(out.verts, ref.verts.to(low), rtol=0, atol=0)


def test_vertices_keep_float32_under_a_float64_default_dtype():
    """The edge selector was a default-dtype constant: float32 fields gave float64
    vertices when the default dtype was float64."""
    previous = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        out = marching_squares(_ring_fields(torch.float32))
    finally:
        torch.set_default_dtype(previous)
    assert out.verts.dtype == torch.float32
    ref = marching_squares(_ring_fields(torch.float32))
    torch.testing.assert_close(out.verts, ref.verts, rtol=0, atol=0)


def test_nan_iso_is_rejected_and_tensor_origin_follows_the_field():
    """A NaN level silently gave no lines; now ValueError. origin/spacing tensors of
    another float dtype are cast to the field's (documented)."""
    fields = _ring_fields(torch.float64)
    with pytest.raises(ValueError, match="iso"):
        marching_squares(fields, iso=float("nan"))
    origin, spacing = torch.tensor([0.5, -1.0]), torch.tensor([0.25, 0.5])  # float32
    out = marching_squares(fields, origin=origin, spacing=spacing)
    ref = marching_squares(fields, origin=(0.5, -1.0), spacing=(0.25, 0.5))
    assert out.verts.dtype == torch.float64
    torch.testing.assert_close(out.verts, ref.verts, rtol=0, atol=0)
    unit = marching_squares(fields)  # vertex = origin + index * spacing, by hand
    torch.testing.assert_close(out.verts, origin.double() + unit.verts * spacing.double())
