"""Fit learnable cubic Bezier curves to the outline of a glyph with Adam (report section 1.1).

The report motivates parametric curves with smooth glyphs such as the letter 'd'.
The glyph's outer outline (from matplotlib's font machinery) is cut into pieces
**at its corners** (a cubic cannot turn a sharp corner without a loop, so no piece
spans one) and the smooth runs between corners into pieces of similar length; each
piece is resampled evenly. One ``BezierCurve`` with ``(P, 4, 2)`` control points,
started as straight segments, is trained with Adam on the samples (chord
parameters) plus a penalty that joins consecutive pieces.
``examples/fit_bezier_glyph.py`` runs it; the gallery figure ``curves_glyph_fit.png``
draws it. Needs matplotlib (the ``plot`` extra) for the outline.

Convention:
    Points are ``(x, y)`` with y up, in font units of a size-10 glyph; the outline
    runs in the font's orientation and is closed (the last piece ends where the
    first starts).
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from torchgeo_cg.curves import BezierCurve, fit_parameters

__all__ = ["GlyphFit", "GlyphPieces", "glyph_pieces", "fit_glyph", "plot_glyph_fit"]


class GlyphPieces(NamedTuple):
    """The outline cut into pieces.

    Attributes:
        runs: ``(P, M, 2)`` float64, each piece resampled evenly in arc length; piece
            ``k`` ends where piece ``k + 1`` starts (cyclically).
        corners: ``(C, 2)`` float64, the outline's corners (every one is a piece end).
    """

    runs: torch.Tensor
    corners: torch.Tensor


class GlyphFit(NamedTuple):
    """The result of :func:`fit_glyph`.

    Attributes:
        curve: the trained ``BezierCurve``, control points ``(P, 4, 2)``.
        start: ``(P, 4, 2)`` the initial control points (straight segments).
        t: ``(P, M)`` the chord parameters of the samples.
        losses: ``(steps,)`` float64, the loss before each step.
    """

    curve: BezierCurve
    start: torch.Tensor
    t: torch.Tensor
    losses: torch.Tensor


def _glyph_polygon(char: str = "d") -> np.ndarray:
    """``(K, 2)`` vertices of the longest (outer) outline of ``char``, not repeated at the end.

    Example:
        >>> poly = _glyph_polygon("d")
        >>> poly.ndim, poly.shape[1], bool((poly[0] != poly[-1]).any())
        (2, 2, True)
    """
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    path = TextPath((0, 0), char, size=10, prop=FontProperties(family="DejaVu Sans"))
    polygon = max(path.to_polygons(), key=len)
    if np.allclose(polygon[0], polygon[-1]):
        polygon = polygon[:-1]
    return np.asarray(polygon, dtype=np.float64)


def _turning_degrees(polygon: np.ndarray) -> np.ndarray:
    """``(K,)`` absolute turning angle at each vertex of a closed polygon."""
    incoming = polygon - np.roll(polygon, 1, axis=0)  # (K, 2)
    outgoing = np.roll(polygon, -1, axis=0) - polygon
    cross = incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]
    dot = (incoming * outgoing).sum(1)
    return np.degrees(np.abs(np.arctan2(cross, dot)))


def glyph_pieces(
    char: str = "d", pieces: int = 14, samples: int = 40, corner_degrees: float = 35.0
) -> GlyphPieces:
    """Cut the outline of ``char`` at its corners, then into about ``pieces`` pieces.

    Args:
        char: the glyph.
        pieces: the number of pieces to aim for (each corner-to-corner run gets at
            least one, in proportion to its length).
        samples: points per piece, both ends included.
        corner_degrees: a vertex turning more than this is a corner.

    Returns:
        :class:`GlyphPieces`.

    Example:
        >>> parts = glyph_pieces("d")
        >>> parts.runs.shape[1:], len(parts.corners) >= 4  # the stem's corners at least
        (torch.Size([40, 2]), True)
        >>> bool(torch.allclose(parts.runs[:-1, -1], parts.runs[1:, 0]))  # joined
        True
    """
    polygon = _glyph_polygon(char)
    closed = np.concatenate([polygon, polygon[:1]])  # (K + 1, 2)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    total = arc[-1]
    corner_index = np.flatnonzero(_turning_degrees(polygon) > corner_degrees)
    breaks = arc[corner_index] if len(corner_index) else np.array([0.0])  # (C,)
    spans = np.diff(np.concatenate([breaks, breaks[:1] + total]))  # (C,) run lengths
    counts = np.maximum(1, np.round(spans / total * pieces)).astype(int)  # pieces per run
    # piece boundaries: each run split evenly into its count (a loop over corners, not points)
    bounds = np.concatenate(
        [b + s * np.arange(c) / c for b, s, c in zip(breaks, spans, counts)] + [[breaks[0] + total]]
    )  # (P + 1,)
    u = np.linspace(0.0, 1.0, samples)  # (M,)
    s = (bounds[:-1, None] + (bounds[1:] - bounds[:-1])[:, None] * u) % total  # (P, M)
    xy = np.stack([np.interp(s, arc, closed[:, 0]), np.interp(s, arc, closed[:, 1])], -1)
    return GlyphPieces(torch.tensor(xy), torch.tensor(polygon[corner_index]))


def fit_glyph(runs: torch.Tensor, steps: int = 400, lr: float = 0.05) -> GlyphFit:
    """Train one cubic per piece on ``runs (P, M, 2)`` with Adam, from straight segments.

    The loss is the mean squared distance of the curves at the chord parameters to
    the samples, plus the mean squared gap between each piece's end and the next
    piece's start (C0 joins; pieces meet at corners, so no tangent continuity).

    Example:
        >>> fit = fit_glyph(glyph_pieces("d").runs, steps=50)
        >>> fit.curve.control_points.shape, bool(fit.losses[-1] < fit.losses[0] / 5)
        (torch.Size([16, 4, 2]), True)
    """
    t = fit_parameters(runs, "chord")  # (P, M), fixed during training
    ends = runs[:, [0, -1]]  # (P, 2, 2)
    weights = torch.linspace(0, 1, 4, dtype=runs.dtype)[:, None]  # (4, 1)
    start = torch.lerp(ends[:, :1], ends[:, 1:], weights)  # (P, 4, 2): straight segments
    curve = BezierCurve(start, learnable=True)
    optimizer = torch.optim.Adam(curve.parameters(), lr=lr)
    losses = []
    for _ in range(steps):  # a loop over optimisation steps
        optimizer.zero_grad()
        cp = curve.control_points
        data = (curve(t) - runs).pow(2).sum(-1).mean()
        joins = (cp[:, -1] - cp.roll(-1, dims=0)[:, 0]).pow(2).sum(-1).mean()
        loss = data + joins
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    return GlyphFit(curve, start, t, torch.tensor(losses, dtype=torch.float64))


def plot_glyph_fit(parts: GlyphPieces, fit: GlyphFit, path: str | Path) -> None:
    """Left: samples, corners, start and fitted curves with their control points; right: loss."""
    from torchgeo_cg.viz._style import plt, save

    fig, axes = plt.subplots(1, 2, figsize=(10, 6), gridspec_kw={"width_ratios": [1, 1.2]},
                             layout="constrained")
    ax = axes[0]
    samples = parts.runs.reshape(-1, 2)
    ax.plot(*samples.T, ".", ms=2, color="0.65", label="outline samples")
    dense = torch.linspace(0, 1, 60, dtype=parts.runs.dtype)
    start_xy = BezierCurve(fit.start, learnable=False)(dense)  # (P, 60, 2)
    with torch.no_grad():
        fitted_xy = fit.curve(dense)
        cp = fit.curve.control_points.detach()  # (P, 4, 2)
    for k in range(len(cp)):  # a loop over the pieces drawn
        ax.plot(*start_xy[k].T, ":", color="C1", lw=1, label="start" if k == 0 else None)
        ax.plot(*cp[k].T, "-", color="C2", lw=0.6, alpha=0.7,
                label="control polygons" if k == 0 else None)
        ax.plot(*fitted_xy[k].T, "C0-", lw=1.6, label="fitted cubics" if k == 0 else None)
    ax.plot(*cp[:, 1:3].reshape(-1, 2).T, "o", color="C2", ms=3, label="inner control points")
    ax.plot(*cp[:, 0].T, "s", color="k", ms=3.5, label="piece ends (shared)")
    ax.plot(*parts.corners.T, "o", mfc="none", mec="C3", ms=9, mew=1.2,
            label="corners (pieces end there)")
    ax.set_aspect("equal")
    ax.set_title(f"glyph 'd': {len(cp)} cubic pieces")
    fig.legend(fontsize=9, loc="outside lower center", ncol=4)
    axes[1].semilogy(fit.losses.numpy())
    axes[1].set_xlabel("Adam step")
    axes[1].set_ylabel("loss (squared distance + joins)")
    axes[1].set_title("training loss")
    save(fig, Path(path))
