"""Gallery figure for sparse marching cubes: where the field is evaluated, and the mesh."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from torchgeo_cg.mesh.marching_cubes import sparse_marching_cubes
from torchgeo_cg.sdf.primitives import torus
from torchgeo_cg.viz._style import axes3d, plt, save, shaded_mesh
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

_N, _BLOCK = 65, 8


@figure(
    "mesh",
    "sparse_marching_cubes.png",
    "Sparse marching cubes: only blocks near the surface are sampled",
    "sparse_marching_cubes on the torus SDF (R = 0.7, r = 0.3) at 65^3 with blocks of 8^3 "
    "cells and lipschitz = 1. Left: the SDF on the slice z = 0 and, in black, the samples of "
    "that slice the field was evaluated at (the active blocks; the coarse-to-fine block "
    "centres are not drawn). Right: the mesh, identical to marching_cubes on the full grid.",
)
def _sparse_figure(path: Path) -> None:
    seen: list[torch.Tensor] = []

    def field(p: torch.Tensor) -> torch.Tensor:
        seen.append(p)
        return torus(p, 0.7, 0.3)

    bounds = torch.tensor([-1.2, 1.2], dtype=torch.float64)
    mesh = sparse_marching_cubes(field, bounds, _N, block=_BLOCK)
    pts = torch.cat(seen)
    on_slice = pts[pts[:, 2] == 0.0]
    x = torch.linspace(-1.2, 1.2, _N, dtype=torch.float64)
    X, Y = torch.meshgrid(x, x, indexing="ij")
    values = torus(torch.stack([X, Y, torch.zeros_like(X)], -1).view(-1, 3), 0.7, 0.3)
    fig = plt.figure(figsize=(10, 4.6))
    ax = fig.add_subplot(1, 2, 1)
    ax.imshow(values.view(_N, _N).numpy().T, origin="lower", extent=(-1.2, 1.2, -1.2, 1.2),
              cmap="RdBu")
    ax.contour(X.numpy(), Y.numpy(), values.view(_N, _N).numpy(), [0.0], colors="k")
    ax.plot(on_slice[:, 0].numpy(), on_slice[:, 1].numpy(), "k.", ms=1.2)
    ticks = np.linspace(-1.2, 1.2, (_N - 1) // _BLOCK + 1)
    ax.set_xticks(ticks, minor=True)
    ax.set_yticks(ticks, minor=True)
    ax.grid(which="minor", color="0.5", lw=0.4)
    share = pts.shape[0] / _N**3
    ax.set_title(f"slice z = 0: evaluated samples ({100 * share:.0f}% of the grid in all)")
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    shaded_mesh(ax3, mesh)
    axes3d(ax3)
    ax3.set_title(f"{mesh.faces.shape[0]} faces, watertight")
    save(fig, path)
