"""Bezier fitting with parameter correction against Adam (1 thread).

Target: ``fit_bezier(..., correct_parameters=True)`` on 512 noisy strokes of 64 points
(cubics): rms residual within 10% of an Adam run of 500 steps that optimises the control
points and every sample's parameter jointly (the "peer"), in <= 0.2 x its time.

Strokes: random cubic control points in the unit square, 64 sorted uniform-random
parameters per stroke (uneven sampling, so chord-length parameters are off), Gaussian
noise of standard deviation 0.02 on every coordinate.
"""

from __future__ import annotations

import torch

from benchmarks.harness import Case
from torchgeo_cg.curves import bernstein_basis, fit_bezier

NOISE = 0.02


def noisy_strokes(count: int, samples: int, gen: torch.Generator) -> torch.Tensor:
    """``(count, samples, 2)`` points along random cubics, unevenly sampled, with noise."""
    cp = torch.rand(count, 4, 2, generator=gen)
    t = torch.rand(count, samples, generator=gen).sort(-1).values
    t = (t - t[:, :1]) / (t[:, -1:] - t[:, :1])
    clean = bernstein_basis(t, 3) @ cp
    return clean + NOISE * torch.randn(clean.shape, generator=gen)


def adam_fit(points: torch.Tensor, steps: int = 500, lr: float = 0.01) -> torch.Tensor:
    """Adam on control points and per-sample parameters; returns the rms per stroke."""
    start = fit_bezier(points, 3)
    cp = start.control_points.clone().requires_grad_(True)
    t = start.t.clone().requires_grad_(True)
    opt = torch.optim.Adam([cp, t], lr=lr)
    for _ in range(steps):
        opt.zero_grad()
        residual = bernstein_basis(t.clamp(0, 1), 3) @ cp - points
        residual.square().sum(-1).mean().backward()
        opt.step()
    with torch.no_grad():
        residual = bernstein_basis(t.clamp(0, 1), 3) @ cp - points
        return residual.square().sum(-1).mean(-1).sqrt()


def cases(quick: bool = False) -> list[Case]:
    gen = torch.Generator().manual_seed(0)
    points = noisy_strokes(512, 64, gen)
    ours_rms = float(fit_bezier(points, 3, correct_parameters=True).rms.square().mean().sqrt())
    plain_rms = float(fit_bezier(points, 3).rms.square().mean().sqrt())
    adam_rms = float(adam_fit(points).square().mean().sqrt())
    extra = {"rms_ours": ours_rms, "rms_adam500": adam_rms, "rms_no_correction": plain_rms,
             "rms_ratio_ours_over_adam": ours_rms / adam_rms, "noise": NOISE}
    return [Case("fit_bezier 512 strokes x 64 pts cubic, correct_parameters=True f32",
                 lambda: fit_bezier(points, 3, correct_parameters=True),
                 lambda: adam_fit(points), "Adam 500 steps (cp + t)", target=0.2,
                 threads=(1,), extra=extra)]
