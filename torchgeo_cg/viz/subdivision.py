"""Gallery figures for Catmull-Clark subdivision and the shipped control mesh (report 1.5)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from torchgeo_cg.mesh import data as sample_data
from torchgeo_cg.mesh.faces import pad_faces
from torchgeo_cg.mesh.io import to_trimesh
from torchgeo_cg.mesh.subdivision import SchemeOptions, catmull_clark
from torchgeo_cg.viz._style import plt, save
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

_CUBE_V = torch.tensor(
    [[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)], dtype=torch.float64
)
_CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
_LIGHT = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])


def _draw(ax, verts, faces, color=(0.85, 0.7, 0.5), edges=True, view=(20, -60)):
    """Lambert-shaded polygons (padded faces drawn as polygons, not triangles)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    verts = np.asarray(verts.detach().cpu() if isinstance(verts, torch.Tensor) else verts)
    faces_fk = pad_faces(faces).cpu().numpy()
    valid = faces_fk >= 0
    polys = [verts[f[m]] for f, m in zip(faces_fk, valid)]  # plotting only
    # Newell normal of each polygon (works for any size)
    p = verts[np.where(valid, faces_fk, faces_fk[:, :1])]
    q = np.roll(p, -1, axis=1)
    normal = np.stack(
        [((p[..., 1] - q[..., 1]) * (p[..., 2] + q[..., 2])).sum(1),
         ((p[..., 2] - q[..., 2]) * (p[..., 0] + q[..., 0])).sum(1),
         ((p[..., 0] - q[..., 0]) * (p[..., 1] + q[..., 1])).sum(1)], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    shade = 0.35 + 0.65 * np.clip(normal @ _LIGHT, 0, 1)
    colors = np.clip(shade[:, None] * np.asarray(color)[None, :], 0, 1)
    coll = Poly3DCollection(polys, facecolors=colors,
                            edgecolors=(0, 0, 0, 0.6) if edges else "none", linewidths=0.4)
    ax.add_collection3d(coll)
    lo, hi = verts.min(0), verts.max(0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2 * 1.05
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(*view)
    ax.set_axis_off()


@figure(
    "mesh",
    "subdivision_cube_levels.png",
    "Catmull-Clark on the unit cube, levels 0-3",
    "The report's Figure 7: the cube [0,1]^3 after 0, 1, 2 and 3 levels of "
    "catmull_clark (OpenSubdiv Catmark rules). After one level the corners sit at "
    "2/9 and 7/9; the shape tends to a rounded, sphere-like surface.",
)
def _cube_levels(path: Path) -> None:
    fig = plt.figure(figsize=(12, 3.4))
    for level in range(4):
        v, f = catmull_clark(_CUBE_V, _CUBE_F, levels=level)
        ax = fig.add_subplot(1, 4, level + 1, projection="3d")
        _draw(ax, v, f, color=(0.55, 0.7, 0.9))
        ax.set_title(f"level {level}: {f.shape[0]} quads")
    save(fig, path)


@figure(
    "mesh",
    "subdivision_rabbit_vs_loop.png",
    "The shipped rabbit: our Catmull-Clark vs trimesh's Loop",
    "Top: torchgeo_cg.mesh.data/rabbit.obj (288 quads, made by _make_rabbit.py) at "
    "Catmull-Clark levels 0-3. Bottom: the same mesh fan-triangulated and refined by "
    "trimesh.remesh.subdivide_loop, a different (triangle) scheme, for comparison.",
)
def _rabbit(path: Path) -> None:
    import trimesh

    rabbit = sample_data.rabbit(dtype=torch.float64)

    tri = to_trimesh(rabbit)
    fig = plt.figure(figsize=(13, 6.4))
    view = (12, -65)
    for level in range(4):
        v, f = catmull_clark(rabbit.verts, rabbit.faces, levels=level)
        ax = fig.add_subplot(2, 4, level + 1, projection="3d")
        _draw(ax, v, f, edges=level < 2, view=view)
        ax.set_title(f"Catmull-Clark level {level}")
        if level == 0:
            lv, lf = tri.vertices, tri.faces
        else:
            lv, lf = trimesh.remesh.subdivide_loop(tri.vertices, tri.faces, iterations=level)
        ax = fig.add_subplot(2, 4, level + 5, projection="3d")
        _draw(ax, lv, lf, color=(0.6, 0.8, 0.6), edges=level < 2, view=view)
        ax.set_title(f"trimesh Loop level {level}")
    save(fig, path)


@figure(
    "mesh",
    "subdivision_open_boundary_modes.png",
    "An open mesh in both boundary modes",
    "A 3x3 open quad grid with a raised middle, subdivided 3 levels. "
    "boundary='edge_only' (OpenSubdiv's default) rounds the valence-2 corners; "
    "'edge_and_corner' keeps them fixed. Boundary edges follow cubic B-splines in both.",
)
def _open_modes(path: Path) -> None:
    n = 3
    xs, ys = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0), indexing="ij")
    zs = np.where((xs > 0) & (xs < n) & (ys > 0) & (ys < n), 1.2, 0.0)
    verts = torch.tensor(np.c_[xs.ravel(), ys.ravel(), zs.ravel()])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    faces = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    fig = plt.figure(figsize=(11, 4.2))
    for k, mode in enumerate(("edge_only", "edge_and_corner")):
        v, f = catmull_clark(verts, torch.from_numpy(faces), levels=3,
                             options=SchemeOptions(boundary=mode))
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        _draw(ax, v, f, edges=False, view=(35, -60))
        ctrl = verts.numpy()
        for quad in faces:  # the control net, for reference (plotting only)
            loop = ctrl[np.r_[quad, quad[:1]]]
            ax.plot(loop[:, 0], loop[:, 1], loop[:, 2], color="k", lw=0.6, alpha=0.7)
        ax.set_title(f"boundary='{mode}'")
    save(fig, path)
