"""Nearest neighbours and Chamfer against scipy's cKDTree (1 thread).

Targets (ratio ours / peer):
- ``chamfer_distance`` of 2 clouds of 16,384 points, forward: <= 3 x cKDTree (build
  both trees, query both ways); at 4,096 points: <= 2 x.
- forward + backward <= 1.5 x our forward (the "peer" of that row is our forward).

The clouds are two independent samplings of a torus surface (the usual case in
learning pipelines: points on a surface), float32; a uniform-in-a-cube case is reported
too. Both sides compute exact nearest neighbours.
"""

from __future__ import annotations

import math

import torch

from benchmarks.harness import Case
from torchgeo_cg.points import chamfer_distance


def torus_points(n: int, gen: torch.Generator) -> torch.Tensor:
    """``n`` points on a torus (R = 1, r = 0.35), uniform in the angles."""
    u, v = (torch.rand(2, n, generator=gen) * 2 * math.pi).unbind(0)
    ring = 1.0 + 0.35 * torch.cos(v)
    return torch.stack([ring * torch.cos(u), ring * torch.sin(u), 0.35 * torch.sin(v)], -1)


def _chamfer_cases(n: int, a: torch.Tensor, b: torch.Tensor, target, label: str) -> list[Case]:
    from scipy import __version__ as scipy_version
    from scipy.spatial import cKDTree

    an, bn = a.numpy(), b.numpy()

    def peer():
        tree_a, tree_b = cKDTree(an), cKDTree(bn)
        tree_b.query(an)
        tree_a.query(bn)

    err = float((chamfer_distance(a.double(), b.double()).loss
                 - (cKDTree(bn).query(an)[0] ** 2).mean() - (cKDTree(an).query(bn)[0] ** 2).mean())
                .abs())
    out = [Case(f"chamfer_distance {n:,} vs {n:,} pts {label} f32 fwd",
                lambda: chamfer_distance(a, b), peer, f"scipy {scipy_version} cKDTree x2",
                target=target, threads=(1,), extra={"abs_err_f64_vs_ckdtree": err})]
    return out


def cases(quick: bool = False) -> list[Case]:
    gen = torch.Generator().manual_seed(0)
    out: list[Case] = []
    sizes = (4096, 16384)
    for n in sizes:
        a, b = torus_points(n, gen), torus_points(n, gen)
        out += _chamfer_cases(n, a, b, 2.0 if n == 4096 else 3.0, "torus surface")
    n = sizes[-1]
    a, b = torus_points(n, gen), torus_points(n, gen)
    ag, bg = a.clone().requires_grad_(True), b.clone().requires_grad_(True)

    def fwd_bwd():
        ag.grad = bg.grad = None
        chamfer_distance(ag, bg).loss.backward()

    out.append(Case(f"chamfer_distance {n:,} pts f32 fwd+bwd vs our fwd", fwd_bwd,
                    lambda: chamfer_distance(ag, bg), "ours (forward, grad enabled)",
                    target=1.5, threads=(1,)))
    cube_a, cube_b = torch.rand(n, 3, generator=gen), torch.rand(n, 3, generator=gen)
    out += _chamfer_cases(n, cube_a, cube_b, None, "uniform cube")
    return out
