"""Fit learnable cubic Bezier curves to the outline of a glyph with Adam.

The report (section 1.1) motivates parametric curves with smooth glyphs such as
the letter 'd'. :mod:`torchgeo_cg.viz.glyph_fit` cuts the outline of 'd' at its
corners and into pieces, and trains one cubic ``BezierCurve`` per piece so the
curves pass through the samples and join up. The least-squares solution
(``fit_bezier``) is printed for comparison.

Run: ``python examples/fit_bezier_glyph.py [--steps 400] [--plot glyph_fit.png]``
(needs the ``plot`` extra for the glyph outline and the optional figure).
"""

from __future__ import annotations

import argparse

import torch

from torchgeo_cg.curves import fit_bezier
from torchgeo_cg.viz.glyph_fit import fit_glyph, glyph_pieces, plot_glyph_fit


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--plot", default=None, help="write a PNG of the fit")
    args = parser.parse_args(argv)
    torch.manual_seed(0)
    parts = glyph_pieces("d")
    fit = fit_glyph(parts.runs, steps=args.steps)
    with torch.no_grad():
        rms = (fit.curve(fit.t) - parts.runs).norm(dim=-1).pow(2).mean().sqrt()
    least_squares = fit_bezier(parts.runs, 3).rms.pow(2).mean().sqrt()
    print(f"{len(parts.runs)} pieces, cut at {len(parts.corners)} corners")
    print(f"Adam: loss {fit.losses[0]:.4f} -> {fit.losses[-1]:.6f}; rms distance {float(rms):.4f}")
    print(f"least-squares cubic per piece (fit_bezier): rms {float(least_squares):.4f}")
    if args.plot:
        plot_glyph_fit(parts, fit, args.plot)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
