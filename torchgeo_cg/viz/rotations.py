"""Gallery figure for 3D rotations: a slerp path of frames."""

from __future__ import annotations

from pathlib import Path

import torch

from torchgeo_cg.transforms import (
    euler_to_matrix,
    matrix_to_quaternion,
    quaternion_slerp,
    quaternion_to_matrix,
    rotation_angle,
)
from torchgeo_cg.viz._style import plt, save
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

_F64 = torch.float64


def _frames(ax, rotations: torch.Tensor, centres: torch.Tensor, length: float) -> None:
    """Draw each rotation's columns (the frame's x, y, z axes) from its centre."""
    for axis, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
        tips = rotations[:, :, axis] * length  # (T, 3)
        ax.quiver(*centres.T.numpy(), *tips.T.numpy(), color=colour, linewidth=1.4,
                  arrow_length_ratio=0.15)


@figure(
    "transforms",
    "rotations_slerp_frames.png",
    "Slerp: a path of frames between two 3D rotations",
    "quaternion_slerp(q0, q1, t) for 11 values of t between the frames R0 = "
    "euler_to_matrix((0, 0, 0), 'ZYX') and R1 = euler_to_matrix((150, -40, 60), 'ZYX') "
    "(left; x red, y green, z blue, each frame drawn at a point of an arc for legibility). "
    "Right: the geodesic angle from R0 (rotation_angle) grows linearly in t, at constant "
    "angular speed, while normalized linear interpolation of the quaternions (nlerp) "
    "speeds up in the middle.",
)
def _slerp_frames(path: Path) -> None:
    angles = torch.tensor([[0.0, 0.0, 0.0], [150.0, -40.0, 60.0]], dtype=_F64)
    r0, r1 = euler_to_matrix(angles, "ZYX")
    q0, q1 = matrix_to_quaternion(r0), matrix_to_quaternion(r1)
    t = torch.linspace(0, 1, 11, dtype=_F64)
    path_q = quaternion_slerp(q0, q1, t)  # (11, 4)
    path_r = quaternion_to_matrix(path_q)  # (11, 3, 3)
    arc = 1.5 * torch.pi * t  # the frames are drawn along three quarters of a circle
    centres = torch.stack([2 * arc.cos(), 2 * arc.sin(), torch.zeros_like(t)], -1)

    fig = plt.figure(figsize=(12, 5.2), constrained_layout=True)
    grid = fig.add_gridspec(1, 2, width_ratios=(1.2, 1))
    ax = fig.add_subplot(grid[0], projection="3d")
    _frames(ax, path_r, centres, 0.6)
    ax.plot(*centres.T.numpy(), color="0.6", lw=0.8)
    ax.text(*(centres[0] + 0.3).tolist(), "t = 0", fontsize=8)
    ax.text(*(centres[-1] + 0.3).tolist(), "t = 1", fontsize=8)
    for lim in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        lim(-2.5, 2.5)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=35, azim=-60)
    ax.set_axis_off()
    ax.set_title("frames R(t), t = 0, 0.1, ..., 1", fontsize=10)

    dense = torch.linspace(0, 1, 101, dtype=_F64)
    slerp = rotation_angle(r0.expand(101, 3, 3),
                           quaternion_to_matrix(quaternion_slerp(q0, q1, dense)))
    nlerp_q = torch.nn.functional.normalize((1 - dense[:, None]) * q0 + dense[:, None] * q1,
                                            dim=-1)
    nlerp = rotation_angle(r0.expand(101, 3, 3), quaternion_to_matrix(nlerp_q))
    ax = fig.add_subplot(grid[1])
    ax.plot(dense.numpy(), torch.rad2deg(slerp).numpy(), label="slerp")
    ax.plot(dense.numpy(), torch.rad2deg(nlerp).numpy(), "--", label="nlerp")
    ax.set_xlabel("t")
    ax.set_ylabel("angle from R0 (degrees)")
    ax.grid(alpha=0.3)
    ax.legend()
    save(fig, path)
