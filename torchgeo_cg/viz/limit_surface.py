"""Gallery figure: points on the Catmull-Clark limit surface against uniform subdivision."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

import numpy as np
import torch
from scipy.spatial import cKDTree

from torchgeo_cg.mesh.io import load_mesh
from torchgeo_cg.mesh.subdivision import (
    CatmullClark,
    catmull_clark_operator,
    limit_surface,
    sample_limit_surface,
)
from torchgeo_cg.viz._style import plt, save
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

_LIGHT = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])


@figure(
    "mesh",
    "limit_surface_rabbit.png",
    "Limit-surface samples on the rabbit against level-5 subdivision",
    "Left: 20,000 points drawn uniformly by area on the Catmull-Clark limit surface of the "
    "shipped rabbit (sample_limit_surface, shaded by their limit normals). Right: the "
    "distance from the limit surface to the vertices of uniform subdivision at levels 1-5, "
    "evaluated at the same (ptex face, u, v) as each vertex (limit_surface at dyadic "
    "points), relative to the rabbit's size: it falls by a factor of 3-4 per level, as the "
    "refined vertices converge to the limit.",
)
def _limit_rabbit(path: Path) -> None:
    rabbit = load_mesh(files("torchgeo_cg.mesh.data") / "rabbit.obj", dtype=torch.float64)
    verts, faces = rabbit.verts, rabbit.faces
    op = catmull_clark_operator(faces, len(verts), dtype=torch.float64)
    drawn = sample_limit_surface(op, verts, 20000, generator=torch.Generator().manual_seed(0))
    p, n = drawn.positions.numpy(), drawn.normals.numpy()
    fig = plt.figure(figsize=(11, 4.6))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    shade = 0.3 + 0.7 * np.clip(n @ _LIGHT, 0, 1)
    ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=0.6, c=shade, cmap="copper", vmin=0, vmax=1)
    ax.set_box_aspect(np.ptp(p, 0))
    ax.view_init(12, -65)
    ax.set_axis_off()
    ax.set_title("20k limit-surface samples")
    size = float(np.ptp(verts.numpy(), 0).max())
    levels, errors = [], []
    for level in range(1, 6):  # a loop over levels
        m = 2 ** (level - 1)  # level-l vertices on face f's level-1 children: dyadic uv
        grid = torch.arange(m + 1, dtype=torch.float64) / m
        uv = torch.stack(torch.meshgrid(grid, grid, indexing="ij"), -1).reshape(-1, 2)
        fid = torch.arange(faces.shape[0]).repeat_interleave(uv.shape[0])
        on = limit_surface(op, verts, fid, uv.repeat(faces.shape[0], 1)).positions
        refined = CatmullClark(faces, len(verts), levels=level, dtype=torch.float64)(verts)
        d, _ = cKDTree(refined.numpy()).query(on.numpy())  # nearest refined vertex
        levels.append(level)
        errors.append(float(d.max()) / size)
    ax = fig.add_subplot(1, 2, 2)
    ax.semilogy(levels, errors, "o-")
    ax.set_xlabel("uniform subdivision level")
    ax.set_ylabel("max distance to the limit / size")
    ax.set_title("uniform subdivision converges to limit_surface")
    ax.grid(True, which="both", alpha=0.3)
    save(fig, path)
