"""Optimising through marching cubes: recover a torus's radii from a point cloud.

The torus SDF is sampled on a grid from its two radii ``(R, r)``;
:func:`torchgeo_cg.mesh.marching_cubes` turns it into a mesh whose vertices move
with ``R`` and ``r`` (through the edge interpolation) and whose faces carry soft
weights (``temperature``); a face-weighted two-sided chamfer distance to the target
points is minimised with Adam. ``examples/fit_torus_marching_cubes.py`` runs it from
the command line; the gallery figure ``marching_cubes_fit_torus.png`` draws it.

Convention:
    Grids use ``indexing="ij"`` (array axis 0 is x) over ``[LO, HI]^3`` with both
    bounds sampled; the SDF is negative inside; the torus lies around the z axis.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import torch

from torchgeo_cg.core.grid import Volume
from torchgeo_cg.mesh.marching_cubes import MarchingCubesResult, marching_cubes
from torchgeo_cg.sdf.grid import grid_spacing
from torchgeo_cg.viz.registry import figure

__all__ = ["TRUE_RADII", "TorusFit", "fit_torus_radii", "plot_torus_fit"]

#: The target torus ``(R, r)`` and the deliberately poor starting guess.
TRUE_RADII = (0.65, 0.25)
_START_RADII = (0.40, 0.40)
#: Grid samples per axis and its bounds.
_N, _LO, _HI = 32, -1.2, 1.2


class TorusFit(NamedTuple):
    """The result of :func:`fit_torus_radii`.

    Attributes:
        target: ``(P, 3)`` the target points.
        history: ``(steps + 1, 4)`` rows ``(step, R, r, loss)``, float64.
        before: the mesh at the start radii.
        after: the mesh at the fitted radii.
    """

    target: torch.Tensor
    history: torch.Tensor
    before: MarchingCubesResult
    after: MarchingCubesResult


def _torus_grid_sdf(R: torch.Tensor, r: torch.Tensor, n: int = _N) -> torch.Tensor:
    """Exact torus SDF around the z axis on an ``(n, n, n)`` grid over ``[LO, HI]^3``.

    Args:
        R: 0-d major radius (differentiable).
        r: 0-d minor radius (differentiable).
        n: samples per axis.

    Returns:
        ``(n, n, n)`` values, ``indexing="ij"``, negative inside, in ``R``'s dtype.

    Example:
        >>> f = _torus_grid_sdf(torch.tensor(0.65), torch.tensor(0.25), n=5)
        >>> f.shape, round(float(f[2, 2, 2]), 4)  # the centre: distance R - r to the tube
        (torch.Size([5, 5, 5]), 0.4)
    """
    x = torch.linspace(_LO, _HI, n, dtype=R.dtype, device=R.device)
    X, Y, Z = torch.meshgrid(x, x, x, indexing="ij")
    return ((X**2 + Y**2).sqrt() - R).hypot(Z) - r


def _sample_torus_surface(R: float, r: float, count: int, seed: int = 0) -> torch.Tensor:
    """``(count, 3)`` float64 points on the torus (uniform in the two angles, seeded).

    Example:
        >>> p = _sample_torus_surface(0.65, 0.25, 4)
        >>> p.shape, bool(((p[:, :2].norm(dim=1) - 0.65).hypot(p[:, 2]) - 0.25).abs().max() < 1e-12)
        (torch.Size([4, 3]), True)
    """
    gen = torch.Generator().manual_seed(seed)
    u, v = torch.rand(2, count, generator=gen, dtype=torch.float64) * 2 * math.pi
    ring = R + r * v.cos()
    return torch.stack([ring * u.cos(), ring * u.sin(), r * v.sin()], 1)


def _extract_torus(R: torch.Tensor, r: torch.Tensor, temperature: float) -> MarchingCubesResult:
    """Marching cubes of :func:`torus_grid_sdf` with soft face weights at ``temperature``."""
    origin, spacing = grid_spacing(_N, (_LO, _HI), device=R.device, dtype=R.dtype)
    return marching_cubes(Volume(_torus_grid_sdf(R, r), origin, spacing), temperature=temperature)


def _soft_chamfer(mesh: MarchingCubesResult, target: torch.Tensor) -> torch.Tensor:
    """Two-sided chamfer distance between face centroids (weighted) and ``(P, 3)`` points.

    Returns:
        0-d: the face-weighted mean squared distance of the centroids to the points
        plus the mean squared distance of the points to the centroids.
    """
    centroids = mesh.verts[mesh.faces].mean(1)  # (F, 3)
    d2_fp = torch.cdist(centroids, target).square()  # (F, P)
    w = mesh.face_weights  # (F,)
    mesh_to_target = (w * d2_fp.min(1).values).sum() / w.sum()
    target_to_mesh = d2_fp.min(0).values.mean()
    return mesh_to_target + target_to_mesh


def fit_torus_radii(
    steps: int = 60,
    lr: float = 0.03,
    temperature: float = 0.05,
    points: int = 600,
    verbose: bool = False,
) -> TorusFit:
    """Fit ``(R, r)`` from ``START_RADII`` to points of the :data:`TRUE_RADII` torus.

    Args:
        steps: Adam steps (learning rate ``lr``, decayed by 0.95 per step).
        lr: initial learning rate.
        temperature: soft marching-cubes temperature of the face weights.
        points: number of target points.
        verbose: print the loss and radii every 10 steps.

    Returns:
        :class:`TorusFit`.

    Example:
        >>> fit = fit_torus_radii(steps=2, points=50)
        >>> fit.history.shape, fit.history[0, 1:3].tolist()
        (torch.Size([3, 4]), [0.4, 0.4])
    """
    target = _sample_torus_surface(*TRUE_RADII, count=points)
    R = torch.tensor(_START_RADII[0], dtype=torch.float64, requires_grad=True)
    r = torch.tensor(_START_RADII[1], dtype=torch.float64, requires_grad=True)
    opt = torch.optim.Adam([R, r], lr=lr)
    schedule = torch.optim.lr_scheduler.ExponentialLR(opt, gamma=0.95)
    with torch.no_grad():
        before = _extract_torus(R, r, temperature)
    history = []
    for step in range(steps + 1):  # a loop over optimisation steps
        loss = _soft_chamfer(_extract_torus(R, r, temperature), target)
        history.append((step, R.item(), r.item(), loss.item()))
        if verbose and step % 10 == 0:
            print(f"step {step:3d}  loss {loss.item():.5f}  R {R.item():.4f}  r {r.item():.4f}")
        if step == steps:
            break
        opt.zero_grad()
        loss.backward()
        opt.step()
        schedule.step()
    with torch.no_grad():
        after = _extract_torus(R, r, temperature)
    return TorusFit(target, torch.tensor(history, dtype=torch.float64), before, after)


def plot_torus_fit(fit: TorusFit, path: str | Path) -> None:
    """Two shaded meshes (start, fitted) over the target points, and the radii per step.

    Needs matplotlib (the ``plot`` extra). Writes the image to ``path``.
    """
    import numpy as np
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from torchgeo_cg.viz._style import plt, save

    light = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])
    fig = plt.figure(figsize=(12, 4))
    target = fit.target.numpy()
    hist = fit.history.numpy()
    for col, (mesh, title, row) in enumerate(((fit.before, "start", 0), (fit.after, "fitted", -1))):
        v, f = mesh.verts.detach().numpy(), mesh.faces.numpy()
        shade = 0.3 + 0.7 * np.clip(mesh.normals.detach().numpy()[f].mean(1) @ light, 0, 1)
        ax = fig.add_subplot(1, 3, col + 1, projection="3d")
        ax.add_collection3d(Poly3DCollection(v[f], facecolors=shade[:, None] * [0.55, 0.7, 0.9],
                                             edgecolors="none", alpha=0.8))
        ax.scatter(*target.T, s=1, c="crimson")
        ax.set_xlim(-0.8, 0.8), ax.set_ylim(-0.8, 0.8), ax.set_zlim(-0.8, 0.8)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(35, -60)
        ax.set_axis_off()
        ax.set_title(f"{title}: R = {hist[row, 1]:.3f}, r = {hist[row, 2]:.3f}\n"
                     "(red: target points)", fontsize=10)
    ax = fig.add_subplot(1, 3, 3)
    ax.plot(hist[:, 0], hist[:, 1], label="R")
    ax.plot(hist[:, 0], hist[:, 2], label="r")
    ax.axhline(TRUE_RADII[0], ls="--", c="C0", lw=0.8)
    ax.axhline(TRUE_RADII[1], ls="--", c="C1", lw=0.8)
    ax.set_xlabel("Adam step")
    ax.set_ylabel("radius")
    ax.set_title("radii (dashed: truth)", fontsize=10)
    ax.legend(loc="center right")
    save(fig, Path(path))


@figure(
    "mesh",
    "marching_cubes_fit_torus.png",
    "Optimising through marching cubes: recovering a torus's radii",
    "torchgeo_cg.viz.torus_fit (also examples/fit_torus_marching_cubes.py): a torus SDF with "
    "learnable radii (start R = r = 0.4) is meshed by marching_cubes with soft weights, and a "
    "face-weighted chamfer distance to 600 points of the target torus (R = 0.65, r = 0.25) "
    "is minimised with Adam.",
)
def _fit_figure(path: Path) -> None:
    plot_torus_fit(fit_torus_radii(steps=40), path)
