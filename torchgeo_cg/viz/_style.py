"""Shared matplotlib helpers for the gallery figures (imports matplotlib)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

__all__ = ["LIGHT", "axes3d", "closed", "save", "shaded_mesh"]

#: The direction of the light of the shaded meshes (unit).
LIGHT = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])



def save(fig, path: Path, dpi: int = 110) -> None:
    """Save ``fig`` to ``path`` tightly and close it."""
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    plt.close(fig)


def closed(points):
    """Append the first point to a (N, 2) outline so it plots closed."""
    points = np.asarray(points)
    return np.concatenate([points, points[:1]], axis=0)


def axes3d(ax, lim: float = 1.05, view=(35, -60)) -> None:
    """A cubic 3D axes box of half-width ``lim``, seen from ``view``, without axes."""
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_zlim(-lim, lim)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(*view)
    ax.set_axis_off()


def shaded_mesh(ax, mesh, color=(0.85, 0.65, 0.45), edges: bool = False) -> None:
    """Lambert shading from the marching-cubes normals (outward, unit)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    v, f = mesh.verts.detach().numpy(), mesh.faces.numpy()
    n = mesh.normals.detach().numpy()[f].mean(1)
    shade = 0.3 + 0.7 * np.clip(n @ LIGHT, 0, 1)
    ax.add_collection3d(Poly3DCollection(
        v[f], facecolors=np.clip(shade[:, None] * np.asarray(color), 0, 1),
        edgecolors=(0, 0, 0, 0.25) if edges else "none", linewidths=0.2,
    ))
