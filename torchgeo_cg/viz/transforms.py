"""Gallery figures for homogeneous transforms and articulated motion (report section 2)."""

from __future__ import annotations

import math
from pathlib import Path

import torch

from torchgeo_cg.transforms import (
    compose,
    compose_trs,
    rotation,
    scaling,
    solar_system,
    transform_points,
    translation,
)
from torchgeo_cg.viz._style import closed, plt, save
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

#: A small asymmetric "house" outline, so rotations and reflections are visible.
_HOUSE = torch.tensor(
    [
        [0.0, 0.0],
        [1.0, 0.0],
        [1.0, 1.0],
        [0.5, 1.6],
        [0.0, 1.0],
        [0.0, 0.6],
        [0.3, 0.6],
        [0.3, 0.0],
    ],
    dtype=torch.float64,
)


@figure(
    "transforms",
    "transforms_basic.png",
    "Translation, rotation and scaling",
    "The same outline (grey) under T(2, 1), R(30°) about the origin (counter-clockwise, "
    "y up) and uniform S(1.5): report Table 1 as homogeneous 3x3 matrices.",
)
def _basic(path: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), layout="constrained")
    cases = [
        ("T(2, 1)", translation(torch.tensor([2.0, 1.0], dtype=torch.float64))),
        ("R(30°)", rotation(torch.tensor(30.0, dtype=torch.float64))),
        ("S(1.5)", scaling(torch.tensor(1.5, dtype=torch.float64))),
    ]
    for ax, (name, m) in zip(axes, cases):
        moved = transform_points(m, _HOUSE)
        ax.fill(*closed(_HOUSE).T, color="0.8", label="start")
        ax.plot(*closed(moved).T, "C0-", lw=2, label="transformed")
        ax.plot(0, 0, "k+", ms=12, label="origin")
        ax.set_aspect("equal")
        ax.set_xlim(-1.5, 3.5)
        ax.set_ylim(-0.5, 3)
        ax.grid(alpha=0.3)
        ax.set_title(name)
    # one legend for the three panels, below them, so it covers no data
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3)
    save(fig, path)


@figure(
    "transforms",
    "transforms_pre_post.png",
    "Pre- versus post-multiplied compounds",
    "T·S·R acting on column vectors and Rᵀ·Sᵀ·Tᵀ acting on row vectors "
    "land on the same points (crosses on the line); applying translation before "
    "rotation instead (dashed) rotates about the wrong pivot.",
)
def _pre_post(path: Path) -> None:
    offset = torch.tensor([2.0, 1.0], dtype=torch.float64)
    angle, scale = torch.tensor(60.0, dtype=torch.float64), torch.tensor(0.8, dtype=torch.float64)
    pre = compose_trs(offset, angle, scale)
    post = compose_trs(offset, angle, scale, row_vectors=True)
    rows = torch.cat([_HOUSE, torch.ones(len(_HOUSE), 1, dtype=torch.float64)], dim=1)
    by_rows = rows @ post  # (N, 3) row vectors
    wrong = compose(rotation(angle), scaling(scale), translation(offset))  # R·S·T
    fig, ax = plt.subplots(figsize=(6, 5))
    ax.fill(*closed(_HOUSE).T, color="0.85", label="start")
    ax.plot(*closed(transform_points(pre, _HOUSE)).T, "C0-", lw=2, label="T·S·R · p (columns)")
    ax.plot(by_rows[:, 0], by_rows[:, 1], "C3x", ms=10, mew=2, label="pᵀ · Rᵀ·Sᵀ·Tᵀ (rows)")
    ax.plot(*closed(transform_points(wrong, _HOUSE)).T, "C2--", label="R·S·T (wrong order)")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title("pre- and post-multiplied forms agree")
    save(fig, path)


@figure(
    "transforms",
    "solar_system.gif",
    "Articulated motion: a planet with three moons",
    "solar_system(): moon 1 at distance 2 once per cycle, moon 2 at distance 3 twice as fast, "
    "and moon 3 at distance 1 round moon 2 by the report's T_moon3 = T_moon2(θ)·R(θ)·T([1, 0]): "
    "once per cycle in moon 2's turning frame (the grey arm), so its trail loops round moon "
    "2's orbit. All 48 frames come from one world_transforms(theta) call: "
    "(4 nodes, 48 times, 3, 3).",
)
def _solar_gif(path: Path) -> None:
    from matplotlib.animation import FuncAnimation, PillowWriter

    frames = 48
    theta = torch.linspace(0, 2 * math.pi, frames + 1, dtype=torch.float64)[:-1]
    dense = torch.linspace(0, 2 * math.pi, 400, dtype=torch.float64)
    scene = solar_system().to(torch.float64)
    pos = scene.world_transforms(theta).positions().numpy()  # (4, T, 2)
    trail = scene.world_transforms(dense).positions().numpy()
    colors = ["gold", "C0", "C1", "C2"]
    sizes = [18, 7, 8, 5]
    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    for k in range(1, 4):
        ax.plot(trail[k, :, 0], trail[k, :, 1], color=colors[k], lw=0.6, alpha=0.5)
    arm = ax.plot([], [], "-", color="0.4", lw=1)[0]  # moon 2 -> moon 3, the child's frame
    dots = [ax.plot([], [], "o", color=c, ms=s)[0] for c, s in zip(colors, sizes)]
    for k, name in enumerate(("planet", "moon 1", "moon 2", "moon 3")):
        dots[k].set_label(name)
    fig.legend(loc="lower center", fontsize=8, ncol=4, frameon=False, handlelength=1,
               columnspacing=0.8)
    fig.subplots_adjust(left=0.03, right=0.97, top=0.92, bottom=0.09)
    ax.set_xlim(-4.6, 4.6)
    ax.set_ylim(-4.6, 4.6)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    title = ax.set_title("")

    def draw(i):
        arm.set_data(pos[2:, i, 0], pos[2:, i, 1])
        for k, dot in enumerate(dots):
            dot.set_data([pos[k, i, 0]], [pos[k, i, 1]])
        title.set_text(f"θ = {theta[i]:.2f} rad")
        return [arm, *dots]

    anim = FuncAnimation(fig, draw, frames=frames, blit=False)
    anim.save(path, writer=PillowWriter(fps=16), dpi=70)
    plt.close(fig)
