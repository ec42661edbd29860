"""transform_points against kornia on (64, 16384, 2) float32, forward and forward+backward.

Target: our time ≤ 0.8x kornia's in both, at 1 thread.
"""

from __future__ import annotations

import torch

from benchmarks.harness import Case
from torchgeo_cg.transforms import transform_points


def cases(quick: bool = False) -> list[Case]:
    import kornia

    batch, n = (16, 4096) if quick else (64, 16384)
    gen = torch.Generator().manual_seed(0)
    matrix = torch.eye(3) + 0.05 * torch.randn(batch, 3, 3, generator=gen)
    points = torch.randn(batch, n, 2, generator=gen)
    kornia_tp = kornia.geometry.linalg.transform_points
    size = f"({batch},{n},2) f32"

    matrix_g = matrix.clone().requires_grad_(True)
    points_g = points.clone().requires_grad_(True)

    def ours_fb():
        transform_points(matrix_g, points_g).sum().backward()

    def kornia_fb():
        kornia_tp(matrix_g, points_g).sum().backward()

    ref = kornia_tp(matrix.double(), points.double())
    err = ((transform_points(matrix, points) - ref).abs().max() / ref.abs().max()).item()
    peer = f"kornia {kornia.__version__}"
    return [
        Case(
            f"transform_points {size} fwd",
            lambda: transform_points(matrix, points),
            lambda: kornia_tp(matrix, points),
            peer,
            target=0.8,
            extra={"max_rel_err_vs_f64": err},
        ),
        Case(f"transform_points {size} fwd+bwd", ours_fb, kornia_fb, peer, target=0.8),
    ]
