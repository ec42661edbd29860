"""Gallery figures for B-splines, NURBS and tensor-product surfaces."""

from __future__ import annotations

import math
from pathlib import Path

import torch

from torchgeo_cg.curves import nurbs, nurbs_derivative
from torchgeo_cg.surfaces import BSplineSurface, surface_mesh
from torchgeo_cg.viz._style import plt, save
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

_F64 = torch.float64


def _circle():
    corners = torch.tensor([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1],
                            [1, -1], [1, 0]], dtype=_F64)
    weights = torch.tensor([1, math.sqrt(0.5)] * 4 + [1], dtype=_F64)
    knots = torch.tensor([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1], dtype=_F64)
    return corners, weights, knots


@figure(
    "splines",
    "splines_nurbs_circle.png",
    "A NURBS circle: the rational quadratic with nine control points",
    "Left: the curve, its control polygon (a square) and the weights (1 at the edge "
    "midpoints, sqrt(1/2) at the corners); the dots are the curve at 16 uniform parameters, "
    "denser where the speed is lowest (at the edge midpoints). Right: |C(t)| - 1 over the "
    "parameter, at the level of float64 rounding (the curve is exactly a circle), and the "
    "speed |C'(t)| from the exact rational derivative.",
)
def _nurbs_circle(path: Path) -> None:
    cp, w, knots = _circle()
    t = torch.linspace(0, 1, 2001, dtype=_F64)
    points = nurbs(cp, w, t, 2, knots)
    speed = nurbs_derivative(cp, w, t, 2, 1, knots).norm(dim=-1)
    dots = nurbs(cp, w, torch.linspace(0, 1, 17, dtype=_F64)[:-1], 2, knots)
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5.5))
    ax.plot(*points.numpy().T, "C0-", lw=2, label="NURBS curve")
    ax.plot(*cp.numpy().T, "k--o", lw=1, ms=5, label="control polygon")
    ax.plot(*dots.numpy().T, "C3o", ms=4, label="16 uniform t")
    for (x, y), weight in zip(cp[:-1].tolist(), w[:-1].tolist()):
        ax.annotate(f"w={weight:.3f}", (x, y), textcoords="offset points", xytext=(6, 6),
                    fontsize=8)
    ax.set_aspect("equal")
    ax.legend(loc="center", fontsize=8)
    ax.set_title("degree 2, knots 0 0 0 ¼ ¼ ½ ½ ¾ ¾ 1 1 1")
    ax2.plot(t.numpy(), (points.norm(dim=-1) - 1).numpy(), "C0-", lw=1)
    ax2.set_xlabel("t")
    ax2.set_ylabel("|C(t)| - 1", color="C0")
    ax3 = ax2.twinx()
    ax3.plot(t.numpy(), speed.numpy(), "C1-", lw=1)
    ax3.set_ylabel("|C'(t)|", color="C1")
    ax2.set_title("radius error (float64) and speed")
    save(fig, path)


@figure(
    "splines",
    "splines_bspline_surface.png",
    "A bicubic B-spline patch with its unit normals",
    "A 6 x 6 control grid (black) of a bicubic B-spline surface with clamped uniform knots, "
    "tessellated by surface_mesh at 40 x 40 samples; the arrows are the unit normals "
    "du x dv from bspline_surface_derivatives on an 8 x 8 parameter grid.",
)
def _bspline_surface(path: Path) -> None:
    x = torch.linspace(-1, 1, 6, dtype=_F64)
    gx, gy = torch.meshgrid(x, x, indexing="ij")
    gz = 0.6 * torch.sin(2.0 * gx) * torch.cos(1.5 * gy)
    grid = torch.stack([gx, gy, gz], -1)
    patch = BSplineSurface(grid, 3, learnable=False)
    mesh = surface_mesh(patch, 40)
    s = torch.linspace(0.05, 0.95, 8, dtype=_F64)
    u, v = (a.reshape(-1) for a in torch.meshgrid(s, s, indexing="ij"))
    d = patch.derivatives(u, v)
    fig = plt.figure(figsize=(8, 7))
    ax = fig.add_subplot(projection="3d")
    verts = mesh.verts.numpy()
    ax.plot_trisurf(verts[:, 0], verts[:, 1], verts[:, 2], triangles=mesh.faces.numpy(),
                    cmap="viridis", alpha=0.8, linewidth=0)
    for i in range(6):
        ax.plot(*grid[i].numpy().T, "k-", lw=0.6)
        ax.plot(*grid[:, i].numpy().T, "k-", lw=0.6)
    p, n = d.points.numpy(), d.normals.numpy()
    ax.quiver(p[:, 0], p[:, 1], p[:, 2], n[:, 0], n[:, 1], n[:, 2], length=0.25, color="C3")
    ax.set_title("bicubic B-spline patch, normals du x dv")
    save(fig, path)
