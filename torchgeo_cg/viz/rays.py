"""Gallery figures for rays: depth and normal images through a pinhole ray bundle."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from torchgeo_cg.mesh import catmull_clark
from torchgeo_cg.mesh.data import rabbit
from torchgeo_cg.rays import render_depth
from torchgeo_cg.sdf import box, difference, smooth_union, sphere, torus
from torchgeo_cg.viz._style import plt, save
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []


def _pinhole(eye: torch.Tensor, target: torch.Tensor, size: int, fov_deg: float = 40.0):
    """``(H, W, 3)`` unit directions of a pinhole camera at ``eye`` looking at ``target``
    (y up in the image, row 0 at the top)."""
    forward = torch.nn.functional.normalize(target - eye, dim=0)
    right = torch.nn.functional.normalize(torch.linalg.cross(forward, eye.new_tensor(
        [0.0, 1.0, 0.0]), dim=0), dim=0)
    up = torch.linalg.cross(right, forward, dim=0)
    half = float(np.tan(np.radians(fov_deg) / 2))
    u = torch.linspace(-half, half, size, dtype=eye.dtype)
    y, x = torch.meshgrid(-u, u, indexing="ij")
    d = forward + x[..., None] * right + y[..., None] * up
    return torch.nn.functional.normalize(d, dim=-1)


def _csg(p: torch.Tensor) -> torch.Tensor:
    """A rounded box minus a sphere, smoothly joined with a torus."""
    carved = difference(box(p, p.new_tensor([0.7, 0.7, 0.7]), 0.08), sphere(p, 0.85))
    return smooth_union(carved, torus(p, 1.0, 0.12), 0.1)


def _show(axes, image, title):
    depth = image.depth.numpy().copy()
    depth[~image.mask.numpy()] = np.nan
    axes[0].imshow(depth, cmap="viridis_r")
    axes[0].set_title(f"{title}: depth t")
    rgb = np.where(image.mask.numpy()[..., None], image.normals.numpy() * 0.5 + 0.5, 1.0)
    axes[1].imshow(rgb)
    axes[1].set_title(f"{title}: normals (xyz as rgb)")
    for ax in axes:
        ax.set_axis_off()


@figure(
    "rays",
    "rays_depth_normals.png",
    "Depth and normal images of a mesh and of a CSG SDF",
    "render_depth through one 200 x 200 pinhole bundle: top, the rabbit (its quad cage "
    "subdivided twice, 4608 quads, 9216 triangles) by exact watertight ray casting "
    "(ray_mesh_intersect, winding normals); bottom, a rounded box minus a sphere smoothly "
    "joined with a torus by sphere tracing (sphere_trace, normalised gradient).",
)
def _depth_normals(path: Path) -> None:
    mesh = rabbit(dtype=torch.float64)
    verts, faces = catmull_clark(mesh.verts, mesh.faces, levels=2)
    centre = (verts.amax(0) + verts.amin(0)) / 2
    size = float((verts.amax(0) - verts.amin(0)).max())
    eye = centre + size * torch.tensor([1.7, 0.6, 0.5], dtype=torch.float64)
    mesh_image = render_depth((verts, faces), eye, _pinhole(eye, centre, 200))
    eye2 = torch.tensor([2.2, 1.8, 2.6], dtype=torch.float64)
    sdf_image = render_depth(_csg, eye2, _pinhole(eye2, torch.zeros(3, dtype=torch.float64),
                                                  200), t_max=10.0)
    fig, axes = plt.subplots(2, 2, figsize=(9, 9))
    _show(axes[0], mesh_image, "mesh")
    _show(axes[1], sdf_image, "SDF")
    save(fig, path)
