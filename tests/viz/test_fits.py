"""The gallery's fitting figures: glyph pieces end at the corners, the fits converge."""

import numpy as np
import pytest
import torch

pytest.importorskip("matplotlib")

from torchgeo_cg.viz.glyph_fit import _glyph_polygon, fit_glyph, glyph_pieces  # noqa: E402
from torchgeo_cg.viz.torus_fit import TRUE_RADII, fit_torus_radii  # noqa: E402


def _segment_distance(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Brute force: distance of each point to the closed polygon's edges."""
    a, b = polygon, np.roll(polygon, -1, axis=0)  # (K, 2) edges a -> b
    ab = b - a
    t = ((points[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1)  # (N, K)
    closest = a + np.clip(t, 0, 1)[..., None] * ab
    return np.linalg.norm(points[:, None] - closest, axis=-1).min(1)


def test_every_corner_is_a_piece_end_and_pieces_lie_on_the_outline():
    parts = glyph_pieces("d")
    ends = parts.runs[:, 0].numpy()  # (P, 2)
    for corner in parts.corners.numpy():  # a corner inside a piece would force a loop
        assert np.linalg.norm(ends - corner, axis=1).min() < 1e-9
    assert np.allclose(parts.runs[:, -1], parts.runs.roll(-1, 0)[:, 0])  # closed chain
    on_outline = _segment_distance(parts.runs.reshape(-1, 2).numpy(), _glyph_polygon("d"))
    assert on_outline.max() < 1e-9


def _turning_degrees(fit) -> np.ndarray:
    """``(P,)`` total absolute turning of each fitted piece's tangent, from dense samples."""
    with torch.no_grad():
        xy = fit.curve(torch.linspace(0, 1, 400, dtype=torch.float64)).numpy()  # (P, T, 2)
    step = np.diff(xy, axis=1)
    heading = np.arctan2(step[..., 1], step[..., 0])
    return np.degrees(np.abs(np.angle(np.exp(1j * np.diff(heading, axis=1)))).sum(1))


def test_fitted_glyph_follows_the_outline_without_loops():
    parts = glyph_pieces("d")
    fit = fit_glyph(parts.runs, steps=300)
    # a loop turns the tangent by ~360°; between corners the outline turns < 60° per piece
    assert _turning_degrees(fit).max() < 120
    with torch.no_grad():
        dense = fit.curve(torch.linspace(0, 1, 200, dtype=torch.float64)).reshape(-1, 2)
    height = np.ptp(_glyph_polygon("d")[:, 1])
    assert _segment_distance(dense.numpy(), _glyph_polygon("d")).max() < 0.02 * height
    assert fit.losses[-1] < fit.losses[0] / 50
    # the check can fail: pieces spanning the stem corners (no corner split) do loop
    spanning = fit_glyph(glyph_pieces("d", corner_degrees=180).runs, steps=300)
    assert _turning_degrees(spanning).max() > 180


@pytest.mark.slow
def test_torus_fit_recovers_the_radii():
    fit = fit_torus_radii(steps=40)
    R, r = fit.history[-1, 1:3].tolist()
    assert abs(R - TRUE_RADII[0]) < 0.01 and abs(r - TRUE_RADII[1]) < 0.01
    assert fit.history[-1, 3] < fit.history[0, 3] / 10
