"""Gallery figures for marching cubes (report section 1.4, Figure 6) and its soft mode."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from torchgeo_cg.core.grid import Volume
from torchgeo_cg.mesh.data import mri_phantom
from torchgeo_cg.mesh.marching_cubes import AMBIGUOUS_CASES, marching_cubes
from torchgeo_cg.sdf.grid import sample_grid
from torchgeo_cg.sdf.primitives import torus
from torchgeo_cg.viz._style import LIGHT, axes3d, plt, save, shaded_mesh
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

_LO, _HI = -1.2, 1.2


def _torus_field(n: int, R: float = 0.7, r: float = 0.3) -> Volume:
    """Torus SDF around z sampled on ``[-1.2, 1.2]^3`` (the grid convention, negative inside)."""
    return sample_grid(lambda p: torus(p, R, r), n, (_LO, _HI), dtype=torch.float64)


def _extract(field: Volume, **kwargs):
    return marching_cubes(field, **kwargs)


@figure(
    "mesh",
    "marching_cubes_torus.png",
    "Marching cubes: the torus (report Figure 6)",
    "torchgeo_cg.mesh.marching_cubes on the torus SDF (R = 0.7, r = 0.3) sampled at 24^3 "
    "(left, edges drawn) and 64^3 (right), shaded with the returned vertex normals. Both "
    "meshes are welded and watertight (Euler characteristic 0).",
)
def _torus(path: Path) -> None:
    fig = plt.figure(figsize=(10, 4.5))
    for col, n in enumerate((24, 64)):
        mesh = _extract(_torus_field(n))
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        shaded_mesh(ax, mesh, edges=n < 32)
        axes3d(ax, 0.8)
        ax.set_title(f"{n}^3 samples: {mesh.verts.shape[0]} vertices, "
                     f"{mesh.faces.shape[0]} faces", fontsize=9)
    save(fig, path)


@figure(
    "mesh",
    "marching_cubes_soft_weights.png",
    "Marching cubes soft mode: face weights on a noisy field",
    "A torus SDF plus smooth noise (32^3), coloured by face_weights, the probability of each "
    "cell's configuration when every corner is inside with p = sigmoid((iso - f) / tau). "
    "Cells whose corners sit close to the iso-value are uncertain (dark); a larger tau "
    "spreads the uncertainty. The weights are differentiable in the volume.",
)
def _soft(path: Path) -> None:
    gen = torch.Generator().manual_seed(0)
    n = 32
    noise = torch.randn(1, 1, n // 4, n // 4, n // 4, generator=gen, dtype=torch.float64)
    noise = torch.nn.functional.interpolate(noise, size=(n, n, n), mode="trilinear")[0, 0]
    base = _torus_field(n)
    field = base._replace(values=base.values + 0.12 * noise)
    fig = plt.figure(figsize=(11, 4.5))
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    cmap = plt.get_cmap("viridis")
    for col, tau in enumerate((0.005, 0.02)):
        mesh = _extract(field, temperature=tau)
        v, f = mesh.verts.numpy(), mesh.faces.numpy()
        w = mesh.face_weights.numpy()
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        ax.add_collection3d(Poly3DCollection(v[f], facecolors=cmap(w), edgecolors="none"))
        axes3d(ax, 0.85)
        ax.set_title(f"tau = {tau}: weights in [{w.min():.2f}, {w.max():.2f}], "
                     f"mean {w.mean():.2f}", fontsize=9)
    mappable = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, 1))
    fig.colorbar(mappable, ax=fig.axes, shrink=0.6, label="face weight")
    save(fig, path)


def _area(mesh) -> float:
    tri = mesh.verts.double()[mesh.faces]
    return float(torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).norm(dim=1)
                 .sum() / 2)


@figure(
    "mesh",
    "marching_cubes_ambiguity.png",
    "Marching cubes: ambiguity rules on an MRI-like volume",
    "An MRI-like uint16 volume (10 slices of 96 x 96, exact ties everywhere, as scanner data) "
    "meshed at iso 30000.25 with ambiguity=\"separate\" (left: ambiguous faces always "
    "separate the inside corners) and the default ambiguity=\"asymptotic\" (right: the "
    "asymptotic decider on faces and the Marching Cubes 33 interior test, as scikit-image's "
    "Lewiner method). Titles give the areas and, when scikit-image is installed, the gap to "
    "its Lewiner mesh; faces in cells whose case is ambiguous are drawn in blue.",
)
def _ambiguity(path: Path) -> None:

    phantom = mri_phantom()
    values = torch.from_numpy(phantom.astype(np.float64)).permute(2, 1, 0).contiguous()  # x y z
    volume = Volume(values, torch.zeros(3, dtype=torch.float64),
                    torch.tensor([1.0, 1.0, 4.0], dtype=torch.float64))  # thick slices
    iso = 30000.25
    reference = None
    try:
        from skimage.measure import marching_cubes as lewiner

        sk_v, sk_f, _, _ = lewiner(values.numpy(), iso, spacing=(1.0, 1.0, 4.0))
        tri = torch.from_numpy(sk_v.astype(np.float64))[torch.from_numpy(sk_f.astype(np.int64))]
        reference = float(torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
                          .norm(dim=1).sum() / 2)
    except ImportError:  # pragma: no cover - scikit-image is an optional peer
        pass
    ambiguous = torch.tensor(AMBIGUOUS_CASES)
    fig = plt.figure(figsize=(12, 5.5))
    for col, rule in enumerate(("separate", "asymptotic")):
        mesh = marching_cubes(volume, iso, ambiguity=rule)
        v, f = mesh.verts.numpy(), mesh.faces.numpy()
        ijk = np.floor(v[f].mean(1) / np.array([1.0, 1.0, 4.0])).astype(int)
        inside = (phantom.transpose(2, 1, 0) < iso)
        case = sum(inside[ijk[:, 0] + dx, ijk[:, 1] + dy, ijk[:, 2] + dz].astype(int) << c
                   for c, (dx, dy, dz) in enumerate(
                       [((c >> 2) & 1, (c >> 1) & 1, c & 1) for c in range(8)]))
        in_ambiguous = ambiguous[torch.from_numpy(case)].numpy()
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        n = mesh.normals.numpy()[f].mean(1)
        shade = 0.35 + 0.65 * np.abs(n @ LIGHT)  # two-sided: we look at both sides
        colour = np.where(in_ambiguous[:, None], [[0.35, 0.55, 0.95]], [[0.85, 0.65, 0.45]])
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        ax.add_collection3d(Poly3DCollection(v[f], facecolors=np.clip(shade[:, None] * colour,
                                                                        0, 1),
                                             edgecolors="none"))
        lo, hi = v.min(0), v.max(0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(tuple(hi - lo))
        ax.view_init(55, -60)
        ax.set_axis_off()
        area = _area(mesh)
        gap = "" if reference is None else f", {100 * (area / reference - 1):+.2f}% vs Lewiner"
        ax.set_title(f'ambiguity="{rule}": area {area:.0f}{gap}\n'
                     f"{len(f)} faces, {int(in_ambiguous.sum())} in ambiguous cells", fontsize=9)
    save(fig, path)
