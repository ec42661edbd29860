"""Sparse marching cubes on a field against sampling the grid and dense marching cubes.

Targets (ratio ours / peer, 1 thread):
- torus SDF at 1024^3 float32: <= 0.5x dense (``sample_grid`` + ``marching_cubes``) and
  peak RSS above the baseline <= 1 GiB (measured in fresh processes, with a fixed
  ``MALLOC_MMAP_THRESHOLD_``; only in the full run, it takes minutes);
- at 128^3 / 256^3 the ratio is reported (the shell is a larger share of a small grid);
- an MLP field (4 x 128, float32) with ``lipschitz=None``: <= 0.2x dense evaluation plus
  dense marching cubes at 512^3 (the quick run reports 128^3);
- anchors: PyMCubes ``marching_cubes_func`` (a Python callable, slice by slice).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import torch
from torch import nn

from benchmarks.harness import Case
from torchgeo_cg.mesh import marching_cubes, sparse_marching_cubes
from torchgeo_cg.sdf import sample_grid

_PEAK_SCRIPT = r"""
import json, sys, time, torch
torch.set_num_threads(1)
n, tool = int(sys.argv[1]), sys.argv[2]
def hwm():
    with open("/proc/self/status") as s:
        return next(int(l.split()[1]) for l in s if l.startswith("VmHWM"))
from torchgeo_cg.mesh import marching_cubes, sparse_marching_cubes
from torchgeo_cg.sdf import sample_grid
def torus(p):
    return torch.stack([p[:, :2].norm(dim=1) - 0.7, p[:, 2]], 1).norm(dim=1) - 0.3
b = torch.tensor([-1.2, 1.2])
sparse_marching_cubes(torus, b, 32)
marching_cubes(sample_grid(torus, 32, b))
before, t = hwm(), time.perf_counter()
m = sparse_marching_cubes(torus, b, n) if tool == "sparse" else marching_cubes(
    sample_grid(torus, n, b))
print(json.dumps({"s": time.perf_counter() - t, "peak_extra_MiB": (hwm() - before) / 1024}))
"""

BOUNDS = torch.tensor([-1.2, 1.2])


def torus(p: torch.Tensor) -> torch.Tensor:
    """Torus SDF (R = 0.7, r = 0.3) around z."""
    return torch.stack([p[:, :2].norm(dim=1) - 0.7, p[:, 2]], 1).norm(dim=1) - 0.3


def fresh_process(n: int, tool: str) -> dict | None:
    """Time and peak RSS above the baseline of one call at ``n^3``, in a fresh process."""
    env = dict(os.environ, MALLOC_MMAP_THRESHOLD_="65536")
    try:
        out = subprocess.run([sys.executable, "-c", _PEAK_SCRIPT, str(n), tool], env=env,
                             capture_output=True, text=True, timeout=1800, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])
    except Exception:  # noqa: BLE001 - reported as missing, never fails the run
        return None


def mlp() -> nn.Module:
    """4 x 128 softplus MLP around a sphere (float32)."""
    torch.manual_seed(0)
    net = nn.Sequential(nn.Linear(3, 128), nn.Softplus(beta=10), nn.Linear(128, 128),
                        nn.Softplus(beta=10), nn.Linear(128, 128), nn.Softplus(beta=10),
                        nn.Linear(128, 1))
    return lambda p: p.norm(dim=1) - 0.6 + 0.02 * net(p).squeeze(1)


def cases(quick: bool) -> list[Case]:
    out: list[Case] = []
    for n in ((64,) if quick else (128, 256)):
        extra = {}
        if not quick and n == 256:
            extra = {"fresh_1024_sparse": fresh_process(1024, "sparse"),
                     "fresh_1024_dense": fresh_process(1024, "dense")}
        out.append(Case(
            name=f"sparse_marching_cubes torus {n}^3 f32 (vs sample_grid + marching_cubes)",
            ours=lambda n=n: sparse_marching_cubes(torus, BOUNDS, n),
            peer=lambda n=n: marching_cubes(sample_grid(torus, n, BOUNDS)),
            peer_name="dense (ours)", threads=(1,), extra=extra,
        ))
    field = mlp()
    n = 48 if quick else 128
    out.append(Case(
        name=f"sparse_marching_cubes MLP 4x128 {n}^3 f32 lipschitz=None "
             "(vs dense evaluation + marching_cubes)",
        ours=lambda: _no_grad(lambda: sparse_marching_cubes(field, BOUNDS, n, lipschitz=None)),
        peer=lambda: _no_grad(lambda: marching_cubes(sample_grid(field, n, BOUNDS))),
        peer_name="dense (ours)", threads=(1,),
    ))
    try:
        import mcubes
    except ImportError:  # pragma: no cover - optional peer
        return out
    n = 48 if quick else 128
    lo, hi = (-1.2,) * 3, (1.2,) * 3
    out.append(Case(
        name=f"sparse_marching_cubes torus {n}^3 (vs PyMCubes marching_cubes_func)",
        ours=lambda: sparse_marching_cubes(torus, BOUNDS.double(), n),
        peer=lambda: mcubes.marching_cubes_func(
            lo, hi, n, n, n, lambda x, y, z: math.hypot(math.hypot(x, y) - 0.7, z) - 0.3, 0.0),
        peer_name="PyMCubes", threads=(1,),
    ))
    return out


def _no_grad(fn):
    with torch.no_grad():
        return fn()
