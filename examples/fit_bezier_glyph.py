"""Fit learnable cubic Bezier curves to the outline of a glyph with Adam.

The report (section 1.1) motivates parametric curves with smooth glyphs such as
the letter 'd'. Here the outer outline of 'd' (from matplotlib's font machinery)
is sampled evenly, cut into consecutive pieces, and one cubic ``BezierCurve`` per
piece is trained by gradient descent so the curves pass through the samples and
join up. The least-squares solution (``fit_bezier``) is printed for comparison.

Run: ``python examples/fit_bezier_glyph.py [--steps 400] [--plot glyph_fit.png]``
(needs the ``plot`` extra for the glyph outline and the optional figure).
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from torchgeo_cg.curves import BezierCurve, fit_bezier, fit_parameters


def glyph_outline(char: str = "d", samples: int = 480) -> torch.Tensor:
    """``(samples, 2)`` points evenly spaced along the longest outline of ``char``."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    path = TextPath((0, 0), char, size=10, prop=FontProperties(family="DejaVu Sans"))
    polygon = max(path.to_polygons(), key=len)  # the outer outline, closed
    steps = np.linalg.norm(np.diff(polygon, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(steps)])
    s = np.linspace(0, arc[-1], samples, endpoint=False)
    points = np.stack([np.interp(s, arc, polygon[:, 0]), np.interp(s, arc, polygon[:, 1])], -1)
    return torch.tensor(points, dtype=torch.float64)


def fit_glyph(points: torch.Tensor, pieces: int = 12, steps: int = 400, lr: float = 0.05):
    """Train ``pieces`` cubic curves on consecutive runs of ``points``; returns (curve, losses)."""
    closed = torch.cat([points, points[:1]])  # (N + 1, 2): the outline is a loop
    size = len(points) // pieces
    # Consecutive runs sharing their end samples: (P, M, 2), M = size + 1.
    runs = closed[: pieces * size + 1].unfold(0, size + 1, size).transpose(1, 2)
    t = fit_parameters(runs, "chord")  # (P, M), fixed during training
    # Start from straight segments between the run ends: a deliberately poor guess.
    ends = runs[:, [0, -1]]
    weights = torch.linspace(0, 1, 4, dtype=points.dtype)[:, None]  # (4, 1)
    start = torch.lerp(ends[:, :1], ends[:, 1:], weights)  # (P, 4, 2)
    curve = BezierCurve(start, learnable=True)  # control points (P, 4, 2)
    optimizer = torch.optim.Adam(curve.parameters(), lr=lr)
    losses = []
    for _ in range(steps):
        optimizer.zero_grad()
        fitted = curve(t)  # (P, M, 2): per-piece parameters
        cp = curve.control_points
        data = (fitted - runs).pow(2).sum(-1).mean()
        joins = (cp[:, -1] - cp.roll(-1, dims=0)[:, 0]).pow(2).sum(-1).mean()  # C0 between pieces
        loss = data + joins
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    return curve, runs, t, losses


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--plot", default=None, help="write a PNG of the fit")
    args = parser.parse_args(argv)
    torch.manual_seed(0)
    points = glyph_outline("d")
    curve, runs, t, losses = fit_glyph(points, steps=args.steps)
    with torch.no_grad():
        rms = (curve(t) - runs).norm(dim=-1).pow(2).mean().sqrt()
    least_squares = fit_bezier(runs, 3).rms.pow(2).mean().sqrt()
    print(f"Adam: loss {losses[0]:.4f} -> {losses[-1]:.6f}; rms distance {float(rms):.4f}")
    print(f"least-squares cubic per piece (fit_bezier): rms {float(least_squares):.4f}")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(4, 6))
        ax.plot(*points.T, ".", ms=2, color="0.6", label="glyph samples")
        dense = curve(torch.linspace(0, 1, 50, dtype=points.dtype)).detach()
        for piece in dense:
            ax.plot(*piece.T, "C0-")
        ax.set_aspect("equal")
        fig.savefig(args.plot, dpi=110, bbox_inches="tight")


if __name__ == "__main__":
    main()
