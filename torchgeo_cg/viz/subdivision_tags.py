"""Gallery figures for subdivision tags and face-varying data: creases at
OpenSubdiv sharpness 0, 1, 2 and infinity, a hole, and a UV checkerboard carried
through Catmull-Clark by the face-varying operator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from torchgeo_cg.mesh.subdivision import SchemeOptions, catmull_clark
from torchgeo_cg.mesh.subdivision.face_varying import face_varying_subdivide
from torchgeo_cg.mesh.subdivision.tags import INFINITELY_SHARP, SubdivisionTags
from torchgeo_cg.viz._style import plt, save
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

# the cube [-1, 1]^3: vertex 4x + 2y + z, outward-wound quads
_CUBE_V = torch.tensor(
    [[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)],
    dtype=torch.float64,
)
_CUBE_F = torch.tensor(
    [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
)
_CUBE_EDGES = torch.tensor(
    [[0, 1], [0, 2], [0, 4], [1, 3], [1, 5], [2, 3], [2, 6], [3, 7], [4, 5], [4, 6], [5, 7],
     [6, 7]]
)
_LIGHT = np.array([0.45, -0.55, 0.7]) / np.linalg.norm([0.45, -0.55, 0.7])
_VIEW = (24, -58)


def _polys(verts, faces) -> np.ndarray:
    """``(F, K, 3)`` corner positions of quads (plotting only)."""
    return np.asarray(verts.detach().cpu())[np.asarray(faces.cpu())]


def _draw_polys(ax, polys, colors, edge_alpha=0.5, lw=0.3) -> None:
    """Lambert-shaded polygons ``(N, K, 3)`` with base colours ``(N, 3)``."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    p, q = polys, np.roll(polys, -1, axis=1)
    normal = np.stack(  # Newell normal of each polygon
        [((p[..., 1] - q[..., 1]) * (p[..., 2] + q[..., 2])).sum(1),
         ((p[..., 2] - q[..., 2]) * (p[..., 0] + q[..., 0])).sum(1),
         ((p[..., 0] - q[..., 0]) * (p[..., 1] + q[..., 1])).sum(1)], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    shade = 0.35 + 0.65 * np.clip(normal @ _LIGHT, 0, 1)
    faces_rgb = np.clip(shade[:, None] * colors, 0, 1)
    # edge_alpha None: edges in the face colour (no hairline gaps between texture pieces)
    edge = faces_rgb if edge_alpha is None else (0, 0, 0, edge_alpha)
    ax.add_collection3d(Poly3DCollection(
        list(polys), facecolors=faces_rgb, edgecolors=edge, linewidths=lw))


def _frame(ax, half: float = 1.05, view=_VIEW) -> None:
    for setter in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        setter(-half, half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(*view)
    ax.set_axis_off()


def _control_net(ax, edges=_CUBE_EDGES, color="k", style="--") -> None:
    v = _CUBE_V.numpy()
    for a, b in edges.tolist():  # twelve segments, plotting only
        ax.plot(*v[[a, b]].T, color=color, ls=style, lw=0.8, alpha=0.8)


@figure(
    "mesh",
    "subdivision_creases.png",
    "Creased cube edges at sharpness 0, 1, 2 and infinity",
    "The cube's 12 edges tagged as creases (SubdivisionTags, OpenSubdiv semantics) and "
    "refined 3 levels by catmull_clark. Sharpness 0 is the smooth surface; a semi-sharp "
    "crease of sharpness s uses the sharp rule for s levels (decreasing by 1 per level) "
    "and then smooths, so 1 and 2 give increasingly tight rounded edges; sharpness >= 10 "
    "(INFINITELY_SHARP) keeps the edges as cubic B-spline creases and the valence-3 "
    "vertices (3 sharp edges) as corners: the control cube itself. Dashed: the control net.",
)
def _creases(path: Path) -> None:
    fig = plt.figure(figsize=(13, 3.6))
    for k, sharp in enumerate((0.0, 1.0, 2.0, INFINITELY_SHARP)):
        tags = SubdivisionTags.empty(torch.float64)._replace(
            creases=_CUBE_EDGES,
            crease_sharpness=torch.full((12,), sharp, dtype=torch.float64),
        )
        v, f = catmull_clark(_CUBE_V, _CUBE_F, levels=3, tags=tags)
        ax = fig.add_subplot(1, 4, k + 1, projection="3d")
        _draw_polys(ax, _polys(v, f), np.array([0.55, 0.7, 0.9]), edge_alpha=0.25)
        _control_net(ax)
        _frame(ax)
        label = "∞ (INFINITELY_SHARP = 10)" if sharp >= INFINITELY_SHARP else f"{sharp:g}"
        ax.set_title(f"crease sharpness {label}", fontsize=10)
    fig.suptitle("Catmull-Clark, 3 levels, all 12 cube edges creased", fontsize=11)
    save(fig, path)


@figure(
    "mesh",
    "subdivision_hole.png",
    "A hole: the tagged face has no children",
    "Left: the control cube with its top face (z = 1) tagged as a hole (red outline, "
    "SubdivisionTags.holes = [5]). Middle: 3 levels of catmull_clark without the tag. "
    "Right: with it, the hole's 64 child quads are left out, but its vertices still "
    "move by the smooth rules, so the rest of the surface is unchanged (the rim is "
    "where the middle surface was, not a sharp boundary).",
)
def _hole(path: Path) -> None:
    hole = SubdivisionTags.empty(torch.float64)._replace(holes=torch.tensor([5]))
    view = (48, -58)
    fig = plt.figure(figsize=(11, 3.9))
    ax = fig.add_subplot(1, 3, 1, projection="3d")
    ax.computed_zorder = False  # draw the hole's outline on top
    _draw_polys(ax, _polys(_CUBE_V, _CUBE_F[:5]), np.array([0.85, 0.7, 0.5]), 0.8, 0.8)
    top = _CUBE_V.numpy()[_CUBE_F[5].tolist() + [int(_CUBE_F[5, 0])]]
    ax.plot(*top.T, color="red", lw=2.5, zorder=10)
    _frame(ax, view=view)
    ax.set_title("control cube, face 5 is a hole", fontsize=10)
    for k, tags in enumerate((None, hole)):
        v, f = catmull_clark(_CUBE_V, _CUBE_F, levels=3, tags=tags)
        ax = fig.add_subplot(1, 3, k + 2, projection="3d")
        _draw_polys(ax, _polys(v, f), np.array([0.85, 0.7, 0.5]), edge_alpha=0.25)
        _frame(ax, half=0.8, view=view)
        ax.set_title(f"level 3, {'no tags' if tags is None else 'holes=[5]'}: "
                     f"{f.shape[0]} quads", fontsize=10)
    save(fig, path)


def _cross_uvs() -> tuple[torch.Tensor, torch.Tensor]:
    """The cube's cross-shaped UV layout (14 UVs, 4 x 3 unit squares): the side faces
    in a row, the top above and the bottom below the front face (y = -1)."""
    x, y, z = ((_CUBE_V[_CUBE_F] + 1) / 2).unbind(-1)  # (6, 4) each, in [0, 1]
    face = torch.arange(6).unsqueeze(1).expand(6, 4)
    u = torch.where(face == 2, x, torch.where(face == 1, 1 + y, torch.where(
        face == 3, 3 - x, torch.where(face == 0, 4 - y, x))))
    v = torch.where(face == 5, 2 + y, torch.where(face == 4, 1 - y, 1 + z))
    uv_corner = torch.stack([u, v], -1).reshape(-1, 2)
    uvs, uv_faces = torch.unique(uv_corner, dim=0, return_inverse=True)
    return uvs, uv_faces.reshape(6, 4)


def _checker(uv: np.ndarray, per_unit: int = 4) -> np.ndarray:
    """``(..., 3)`` colours of a checkerboard with ``per_unit`` squares per cube face."""
    odd = (np.floor(uv[..., 0] * per_unit) + np.floor(uv[..., 1] * per_unit)) % 2
    return np.where(odd[..., None] > 0, [0.15, 0.2, 0.45], [0.95, 0.85, 0.35])


def _textured(ax, verts, faces, uvs, uv_faces, samples: int) -> None:
    """Texture-map each quad: split it ``samples x samples`` bilinearly in position and
    UV, colour each piece by the checkerboard at its UV centre."""
    p = np.asarray(verts)[np.asarray(faces)]  # (F, 4, 3)
    t = np.asarray(uvs)[np.asarray(uv_faces)]  # (F, 4, 2)
    s = np.linspace(0, 1, samples + 1)
    a, b = np.meshgrid(s, s, indexing="ij")

    def bilerp(c):  # corners (F, 4, D) at (a, b) -> (F, n+1, n+1, D)
        w = [(1 - a) * (1 - b), a * (1 - b), a * b, (1 - a) * b]
        return sum(w_k[None, ..., None] * c[:, None, None, k] for k, w_k in enumerate(w))

    gp, gt = bilerp(p), bilerp(t)
    quad = lambda g: np.stack([g[:, :-1, :-1], g[:, 1:, :-1], g[:, 1:, 1:], g[:, :-1, 1:]],  # noqa: E731
                              axis=3)
    polys = quad(gp).reshape(-1, 4, 3)
    centres = quad(gt).mean(3).reshape(-1, 2)
    _draw_polys(ax, polys, _checker(centres), edge_alpha=None, lw=0.4)


@figure(
    "mesh",
    "subdivision_uv_checkerboard.png",
    "A UV checkerboard through 2 levels (face-varying data with seams)",
    "The cube with a cross-shaped UV layout (left: 14 UVs, 7 seam edges, dashed; the "
    "level-2 UV mesh in black) textured with a checkerboard of 4 x 4 squares per face. "
    "The positions go through catmull_clark, the UVs through face_varying_subdivide: "
    "the child UV faces line up with the child position faces, so the texture follows "
    "the rounded surface. Top: interpolation='corners_only' (OpenSubdiv's "
    "FVAR_LINEAR_CORNERS_ONLY): island corners stay, seams are smooth boundary curves "
    "of the UV mesh, and the seams that end at the front face's right corners "
    "(OpenSubdiv's 'darts') pull the UVs there, so the checks swirl. Bottom: "
    "interpolation='boundaries': seam UVs stay on the layout, the checks meet along the seams.",
)
def _uv_checkerboard(path: Path) -> None:
    uvs, uv_faces = _cross_uvs()
    fig = plt.figure(figsize=(14, 7.4))
    grid = np.stack(np.meshgrid(np.linspace(0, 4, 321), np.linspace(0, 3, 241)), -1)
    inside = np.zeros(grid.shape[:2], bool)
    for f in range(6):  # shade only the six unit squares of the layout
        lo = uvs[uv_faces[f]].min(0).values.numpy()
        inside |= np.all((grid >= lo) & (grid <= lo + 1), axis=-1)
    image = np.where(inside[..., None], 0.45 + 0.55 * _checker(grid), 1.0)  # lightened
    for row, mode in enumerate(("corners_only", "boundaries")):
        ax = fig.add_subplot(2, 4, 4 * row + 1)
        ax.imshow(image, origin="lower", extent=(0, 4, 0, 3), interpolation="nearest")
        uv2, uvf2 = face_varying_subdivide(uvs, _CUBE_F, uv_faces, 8, levels=2,
                                           options=SchemeOptions(fvar_interpolation=mode))
        for quad in uv2[uvf2].numpy():
            ax.fill(*quad.T, fill=False, ec=(0.0, 0.0, 0.0, 0.7), lw=0.5)
        for quad in uvs[uv_faces].numpy():
            ax.fill(*quad.T, fill=False, ec="k", lw=1.2, ls="--")
        ax.set_aspect("equal")
        ax.set_title(f"interpolation='{mode}'\nUV layout, level-2 UV mesh", fontsize=10)
        ax.set_xlabel("u")
        ax.set_ylabel("v")
        for level in range(3):
            v, f = catmull_clark(_CUBE_V, _CUBE_F, levels=level)
            uv_l, uvf_l = face_varying_subdivide(uvs, _CUBE_F, uv_faces, 8, levels=level,
                                                 options=SchemeOptions(fvar_interpolation=mode))
            ax = fig.add_subplot(2, 4, 4 * row + level + 2, projection="3d")
            _textured(ax, v.numpy(), f.numpy(), uv_l.numpy(), uvf_l.numpy(),
                      samples=(16, 8, 4)[level])
            _frame(ax, half=1.0 if level == 0 else 0.8)
            ax.set_title(f"level {level}: {f.shape[0]} quads", fontsize=10)
    save(fig, path)


@figure(
    "mesh",
    "subdivision_fvar_modes.png",
    "Face-varying interpolation modes in UV space",
    "The cube's cross UV layout (dashed) refined 2 levels by face_varying_subdivide in "
    "four of OpenSubdiv's FVarLinearInterpolation modes. 'none': the UV islands are "
    "smoothed everywhere, their corners pulled in. 'corners_only': island corners (values "
    "in one face) stay. 'boundaries': every seam value stays and seam edges are linear. "
    "'all': bilinear, the child UVs stay on the control faces.",
)
def _fvar_modes(path: Path) -> None:
    uvs, uv_faces = _cross_uvs()
    fig, axes = plt.subplots(1, 4, figsize=(14, 3.2))
    for ax, mode in zip(axes, ("none", "corners_only", "boundaries", "all")):
        uv2, uvf2 = face_varying_subdivide(uvs, _CUBE_F, uv_faces, 8, levels=2,
                                           options=SchemeOptions(fvar_interpolation=mode))
        for quad in uv2[uvf2].numpy():
            ax.fill(*quad.T, fc=(0.55, 0.7, 0.9, 0.5), ec=(0.1, 0.2, 0.4), lw=0.5)
        for quad in uvs[uv_faces].numpy():
            ax.fill(*quad.T, fill=False, ec="k", lw=1.0, ls="--")
        ax.set_aspect("equal")
        ax.set_xlim(-0.1, 4.1)
        ax.set_ylim(-0.1, 3.1)
        ax.set_title(f"interpolation='{mode}'", fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
    save(fig, path)
