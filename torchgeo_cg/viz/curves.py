"""Gallery figures for curves (report section 1.1-1.3, Figures 1-4, and a glyph fit)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from torchgeo_cg.curves import (
    BezierCurve,
    cubic_bezier,
    cycloid,
    figure_eight_implicit,
    figure_eight_parametric,
    grid_2d,
    hermite,
    marching_squares,
    quartic_bezier,
)
from torchgeo_cg.viz._style import plt, save
from torchgeo_cg.viz.glyph_fit import fit_glyph, glyph_pieces, plot_glyph_fit
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

_F64 = torch.float64


@figure(
    "curves",
    "curves_figure_eight.png",
    "Figure-eight: implicit product versus parametric stitch (report Figure 1)",
    "Left: sign of the product of two circle fields on the report's 2000x2000 grid over "
    "[-10, 10]^2 (blue: f < 0, inside one circle; red: f > 0) and its zero set by marching "
    "squares. Middle: the touching point on a coarse grid, where f = 0 and grad f = 0 "
    "(f ~ y^4 - 4 r^2 x^2): the positive sliver between the two arcs (outside both circles) "
    "is thinner than a cell, the samples there are products of two tiny numbers, and the "
    "contour has to resolve a saddle; anything dividing by |grad f| gets 0/0 (the report's "
    "invalid values). Right: the parametric stitch, continuous with a continuous tangent.",
)
def _figure_eight(path: Path) -> None:
    n, low, high = 2000, -10.0, 10.0
    spacing = (high - low) / (n - 1)
    field = figure_eight_implicit(grid_2d(n, low, high, dtype=_F64), 5.0)  # (n, n), axis 0 = x
    contours = marching_squares(field, 0.0, origin=(low, low), spacing=(spacing, spacing))
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    extent = (low, high, low, high)
    sign = np.sign(field.numpy()).T  # imshow wants rows = y
    axes[0].imshow(sign, origin="lower", extent=extent, cmap="coolwarm", vmin=-3, vmax=3)
    for poly in contours.polylines():
        axes[0].plot(*poly.numpy().T, "k-", lw=1)
    count = len(contours.lengths)
    axes[0].set_title(f"implicit product: {count} polyline{'' if count == 1 else 's'}")
    # Zoom on the touching point with a coarse grid so cells are visible.
    zn, zl = 41, 0.6
    zspacing = 2 * zl / (zn - 1)
    zfield = figure_eight_implicit(grid_2d(zn, -zl, zl, dtype=_F64), 5.0)
    zoom = marching_squares(zfield, 0.0, origin=(-zl, -zl), spacing=(zspacing, zspacing))
    axes[1].imshow(np.sign(zfield.numpy()).T, origin="lower", extent=(-zl, zl, -zl, zl),
                   cmap="coolwarm", vmin=-3, vmax=3)
    for poly in zoom.polylines():
        axes[1].plot(*poly.numpy().T, "k.-", lw=1, ms=3)
    theta = torch.linspace(-0.2, 0.2, 200, dtype=_F64)
    for cx in (-5.0, 5.0):
        x = cx - math.copysign(5.0, cx) * torch.cos(theta)
        axes[1].plot(x, 5.0 * torch.sin(theta), "g--", lw=1)
    axes[1].set_xlim(-zl, zl)
    axes[1].set_ylim(-zl, zl)
    axes[1].set_title("the touching point: grad f = 0\n(dashed: true circles; red sliver: f > 0)",
                      fontsize=11)
    from matplotlib.patches import Patch

    axes[0].legend(handles=[Patch(color=plt.get_cmap("coolwarm")(1 / 3), label="f < 0"),
                            Patch(color=plt.get_cmap("coolwarm")(2 / 3), label="f > 0")],
                   loc="lower center", ncol=2, fontsize=9)
    t = torch.linspace(0, 4 * math.pi, 800, dtype=_F64)
    points = figure_eight_parametric(t, 5.0)
    axes[2].scatter(*points.T, c=t, cmap="viridis", s=3)
    axes[2].set_title("parametric stitch, colour = t in [0, 4 pi]")
    for ax in axes:
        ax.set_aspect("equal")
    axes[2].set_xlim(-10, 10)
    axes[2].set_ylim(-10, 10)
    save(fig, path)


@figure(
    "curves",
    "curves_cycloid.png",
    "Cycloid over [0, 4 pi] (report Figure 2)",
    "x = R (t - sin t), y = R (1 - cos t) with R = 1: two arches, cusps where the speed "
    "vanishes (t = 0, 2 pi, 4 pi), with the rolling wheel drawn at t = 3 pi / 2.",
)
def _cycloid(path: Path) -> None:
    t = torch.linspace(0, 4 * math.pi, 600, dtype=_F64)
    points = cycloid(t, 1.0)
    fig, ax = plt.subplots(figsize=(10, 3))
    ax.plot(*points.T, "C0-", lw=2)
    s = 3 * math.pi / 2
    wheel = torch.linspace(0, 2 * math.pi, 100, dtype=_F64)
    ax.plot(s + torch.cos(wheel), 1 + torch.sin(wheel), "0.5", lw=1)
    ax.plot(*cycloid(torch.tensor([s], dtype=_F64), 1.0).T, "ro")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_aspect("equal")
    save(fig, path)


@figure(
    "curves",
    "curves_bezier.png",
    "Cubic and quartic Bezier curves (report Figure 3)",
    "cubic_bezier and quartic_bezier (explicit Appendix A bases) with their control "
    "polygons; degree + 1 control points each. The arrow is the unit tangent at t = 0.5; "
    "titles give the arc length (adaptive Gauss-Kronrod).",
)
def _bezier(path: Path) -> None:
    cubic = torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]], dtype=_F64)
    quartic = torch.tensor([[0.0, 0.0], [1.0, 3.0], [2.0, -1.0], [3.0, 3.0], [4.0, 0.0]],
                           dtype=_F64)
    t = torch.linspace(0, 1, 200, dtype=_F64)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, cp, fn, name in ((axes[0], cubic, cubic_bezier, "cubic"),
                             (axes[1], quartic, quartic_bezier, "quartic")):
        ax.plot(*cp.T, "o--", color="0.5", label="control polygon")
        ax.plot(*fn(cp, t).T, "C0-", lw=2, label=f"{name} Bezier")
        curve = BezierCurve(cp, learnable=False)
        half = torch.tensor([0.5], dtype=_F64)
        p, tan = curve(half)[0], curve.tangent(half)[0]
        ax.annotate("", xy=(p + 0.8 * tan).tolist(), xytext=p.tolist(),
                    arrowprops={"arrowstyle": "->", "color": "C3"})
        length = float(curve.length())
        ax.set_title(f"{name}: {cp.tolist()}\nlength {length:.4f}", fontsize=8)
        ax.set_aspect("equal")
        ax.legend(loc="best", fontsize=8)
    save(fig, path)


#: Report Figure 4 tangent variants, endpoints (0, 0) -> (1, 0).
_HERMITE_VARIANTS = {
    "original": ((1.0, 1.0), (1.0, -1.0)),
    "exaggerated": ((5.0, 5.0), (5.0, -5.0)),
    "vertical": ((0.0, 3.0), (0.0, -3.0)),
    "parallel": ((2.0, 0.0), (2.0, 0.0)),
}


@figure(
    "curves",
    "curves_hermite.png",
    "Hermite tangent variants (report Figure 4)",
    "One cubic Hermite segment from (0, 0) to (1, 0) with four pairs of end tangents "
    "(red arrows, drawn at a fifth of their length m/5 from each end point): original, "
    "exaggerated (5x), vertical and parallel. hermite() with the Appendix A basis H00, H10, "
    "H01, H11. All panels share one scale.",
)
def _hermite(path: Path) -> None:
    p0 = torch.tensor([0.0, 0.0], dtype=_F64)
    p1 = torch.tensor([1.0, 0.0], dtype=_F64)
    t = torch.linspace(0, 1, 100, dtype=_F64)
    variants = [(name, torch.tensor(m0, dtype=_F64), torch.tensor(m1, dtype=_F64))
                for name, (m0, m1) in _HERMITE_VARIANTS.items()]
    curves = [hermite(p0, p1, m0, m1, t) for _, m0, m1 in variants]  # each (100, 2)
    tips = [torch.stack([p0 + 0.2 * m0, p1 + 0.2 * m1]) for _, m0, m1 in variants]  # (2, 2)
    extent = torch.cat([*curves, *tips, torch.stack([p0, p1])])  # every point drawn
    low, high = extent.amin(0) - 0.15, extent.amax(0) + 0.15  # arrows stay inside
    fig, axes = plt.subplots(2, 2, figsize=(9, 8), layout="constrained")
    for ax, (name, m0, m1), curve in zip(axes.flat, variants, curves):
        ax.plot(*curve.T, "C0-", lw=2)
        for p, m in ((p0, m0), (p1, m1)):
            ax.annotate("", xy=(p + 0.2 * m).tolist(), xytext=p.tolist(),
                        arrowprops={"arrowstyle": "->", "color": "C3", "lw": 1.5})
        ax.plot(*torch.stack([p0, p1]).T, "ko")
        ax.set_title(f"{name}: m0 = {m0.tolist()}, m1 = {m1.tolist()}", fontsize=10)
        ax.set_xlim(float(low[0]), float(high[0]))
        ax.set_ylim(float(low[1]), float(high[1]))
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    save(fig, path)


@figure(
    "curves",
    "curves_glyph_fit.png",
    "A learnable BezierCurve fitted to the glyph 'd'",
    "The outline of 'd' is cut at its corners (red circles: a cubic cannot turn a sharp "
    "corner without looping) and into pieces of similar length; one BezierCurve module with "
    "(P, 4, 2) control points starts as straight segments (orange dots) and is trained with "
    "Adam on chord-parametrised samples plus a penalty joining consecutive pieces "
    "(torchgeo_cg.viz.glyph_fit, also examples/fit_bezier_glyph.py). Green: each piece's "
    "control polygon and inner control points; black squares: the shared piece ends. "
    "Right: the loss.",
)
def _glyph(path: Path) -> None:

    parts = glyph_pieces("d")
    plot_glyph_fit(parts, fit_glyph(parts.runs), path)
