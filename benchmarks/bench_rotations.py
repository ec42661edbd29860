"""Rotation conversions on 1M rotations (float64) against roma and scipy, and batched
Procrustes (4096 problems x 100 points) against roma's ``rigid_points_registration``.

Targets at 1 thread: conversions <= 1x roma and <= 1.5x scipy ``Rotation``'s default calls
(``from_matrix`` validates and orthogonalizes its input by default; ``as_matrix`` writes a
fresh 72 MB array, most of its time); Procrustes <= 1x roma.

Where the time goes. Each conversion row reports ``fresh_out_ms``: allocating and
filling a fresh tensor of the output's size with torch (72 MB for a matrix result, 32 MB
for quaternions, 24 MB for rotation vectors), and ``numpy_fresh_out_ms``: the same with
numpy, which asks for huge pages (PyTorch's allocator does not, unless
``THP_MEM_ALLOC_ENABLE=1``; see BENCHMARKS.md). Our conversions evaluate large CPU
batches in blocks of 16384 rows that stay in cache, so beyond that first touch of the
output they cost a few dozen cache-resident passes per block. For quaternion->matrix
and rotvec->matrix the first touch alone (~60 ms quiet) is above 1.5x scipy's whole
call (42 and 57 ms, which write their output into huge pages): those two scipy targets
cannot be met with PyTorch's default allocator, whatever the arithmetic.

Procrustes: the float64 ``eigh`` of 4096 Horn 4x4 matrices (LAPACK, one call per
matrix, ~2-4 us each) is about 40% of our time; the weighted moments (centroids as
matrix-vector products, one centered copy of ``src``, ``S`` from the uncentered
``dst``) most of the rest. roma replaces the eigen-solver by a closed form of the
eigenvalues (from the singular values of ``S``).
"""

from __future__ import annotations

import time

import numpy as np
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


def _fresh_ms(shape: tuple[int, ...]) -> dict:
    """Best of 5: a fresh float64 output of ``shape`` filled once, in torch and in numpy."""
    def best(fill) -> float:
        times = []
        for _ in range(5):
            start = time.perf_counter()
            fill()
            times.append(time.perf_counter() - start)
        return round(1e3 * min(times), 1)
    return {"fresh_out_ms": best(lambda: torch.empty(shape, dtype=torch.float64).fill_(0)),
            "numpy_fresh_out_ms": best(lambda: np.empty(shape).fill(0))}


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
    to_q, to_m, to_v = _fresh_ms((n, 4)), _fresh_ms((n, 3, 3)), _fresh_ms((n, 3))
    out = [
        Case(f"matrix->quaternion {size}", lambda: matrix_to_quaternion(mat),
             lambda: roma.rotmat_to_unitquat(mat), roma_peer, target=1.0, extra=to_q),
        Case(f"matrix->quaternion {size} [scipy]", lambda: matrix_to_quaternion(mat),
             lambda: Rotation.from_matrix(mat_np).as_quat(), scipy_peer, target=1.5,
             extra=to_q),
        Case(f"quaternion->matrix {size}", lambda: quaternion_to_matrix(quat),
             lambda: roma.unitquat_to_rotmat(quat_xyzw), roma_peer, target=1.0, extra=to_m),
        Case(f"quaternion->matrix {size} [scipy]", lambda: quaternion_to_matrix(quat),
             lambda: Rotation.from_quat(quat_np).as_matrix(), scipy_peer, target=1.5,
             extra=to_m),
        Case(f"rotvec->matrix {size}", lambda: axis_angle_to_matrix(rotvec),
             lambda: roma.rotvec_to_rotmat(rotvec), roma_peer, target=1.0, extra=to_m),
        Case(f"rotvec->matrix {size} [scipy]", lambda: axis_angle_to_matrix(rotvec),
             lambda: Rotation.from_rotvec(rotvec_np).as_matrix(), scipy_peer, target=1.5,
             extra=to_m),
        Case(f"matrix->rotvec {size}", lambda: matrix_to_axis_angle(mat),
             lambda: roma.rotmat_to_rotvec(mat), roma_peer, target=1.0, extra=to_v),
        Case(f"matrix->rotvec {size} [scipy]", lambda: matrix_to_axis_angle(mat),
             lambda: Rotation.from_matrix(mat_np).as_rotvec(), scipy_peer, target=1.5,
             extra=to_v),
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
