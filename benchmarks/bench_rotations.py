"""Rotation conversions on 1M rotations (float64) against roma and scipy, and batched
Procrustes (4096 problems x 100 points) against roma's ``rigid_points_registration``.

Targets at 1 thread: conversions <= 1x roma and <= 1.5x scipy ``Rotation``'s default calls
(``from_matrix`` validates and orthogonalizes its input by default; ``as_matrix`` writes a
fresh 72 MB array, most of its time); Procrustes <= 1x roma.
"""

from __future__ import annotations

import torch

from benchmarks.harness import Case
from torchgeo_cg.transforms import (
    axis_angle_to_matrix,
    find_euclidean,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    quaternion_to_matrix,
    random_rotations,
)


def cases(quick: bool = False) -> list[Case]:
    import roma
    from scipy.spatial.transform import Rotation

    n = 100_000 if quick else 1_000_000
    gen = torch.Generator().manual_seed(0)
    mat = random_rotations(n, generator=gen, dtype=torch.float64)
    quat = matrix_to_quaternion(mat)
    quat_xyzw = quat[:, [1, 2, 3, 0]].contiguous()
    rotvec = matrix_to_axis_angle(mat)
    mat_np, quat_np, rotvec_np = mat.numpy(), quat_xyzw.numpy(), rotvec.numpy()
    roma_peer, scipy_peer = f"roma {roma.__version__}", "scipy Rotation"
    size = f"{n} f64"
    out = [
        Case(f"matrix->quaternion {size}", lambda: matrix_to_quaternion(mat),
             lambda: roma.rotmat_to_unitquat(mat), roma_peer, target=1.0),
        Case(f"matrix->quaternion {size} [scipy]", lambda: matrix_to_quaternion(mat),
             lambda: Rotation.from_matrix(mat_np).as_quat(), scipy_peer, target=1.5),
        Case(f"quaternion->matrix {size}", lambda: quaternion_to_matrix(quat),
             lambda: roma.unitquat_to_rotmat(quat_xyzw), roma_peer, target=1.0),
        Case(f"quaternion->matrix {size} [scipy]", lambda: quaternion_to_matrix(quat),
             lambda: Rotation.from_quat(quat_np).as_matrix(), scipy_peer, target=1.5),
        Case(f"rotvec->matrix {size}", lambda: axis_angle_to_matrix(rotvec),
             lambda: roma.rotvec_to_rotmat(rotvec), roma_peer, target=1.0),
        Case(f"rotvec->matrix {size} [scipy]", lambda: axis_angle_to_matrix(rotvec),
             lambda: Rotation.from_rotvec(rotvec_np).as_matrix(), scipy_peer, target=1.5),
        Case(f"matrix->rotvec {size}", lambda: matrix_to_axis_angle(mat),
             lambda: roma.rotmat_to_rotvec(mat), roma_peer, target=1.0),
        Case(f"matrix->rotvec {size} [scipy]", lambda: matrix_to_axis_angle(mat),
             lambda: Rotation.from_matrix(mat_np).as_rotvec(), scipy_peer, target=1.5),
    ]
    b = 512 if quick else 4096
    src = torch.randn(b, 100, 3, generator=gen)
    rot = random_rotations(b, generator=gen)
    dst = src @ rot.mT + 0.01 * torch.randn(b, 100, 3, generator=gen)
    err = (find_euclidean(src, dst).matrix[:, :3, :3] - roma.rigid_points_registration(
        src, dst)[0]).abs().max().item()
    out.append(Case(f"procrustes {b}x100 f32", lambda: find_euclidean(src, dst),
                    lambda: roma.rigid_points_registration(src, dst), roma_peer, target=1.0,
                    extra={"max_abs_diff_vs_roma": err}))
    return out
