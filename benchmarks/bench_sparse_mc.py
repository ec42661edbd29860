"""Sparse marching cubes on a field against sampling the grid and dense marching cubes.

Targets (ratio ours / peer, 1 thread):
- torus SDF at 1024^3 float32: <= 0.5x dense (``sample_grid`` + ``marching_cubes``) and
  peak RSS above the baseline <= 1 GiB;
- 2048^3 (dense would need 32 GiB for the grid alone): time and peak reported;
- an MLP field (4 x 128, float32) with ``lipschitz=None``: <= 0.2x dense evaluation plus
  dense marching cubes at 512^3;
- anchors, time and peak: scikit-image ``marching_cubes`` on the sampled grid at 512^3
  (sampling not timed) and PyMCubes ``marching_cubes_func``, which calls a Python function
  per sample, at 256^3 and 512^3;
- at 128^3 / 256^3 the in-process ratios are reported (the shell is a larger share of a
  small grid).
The runs of minutes are made once each, in fresh processes with a fixed
``MALLOC_MMAP_THRESHOLD_`` (``python -m benchmarks.bench_sparse_mc TOOL N`` runs one), and
report the face counts, which must agree between ours and dense. The quick run makes them
at small sizes.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import torch
from torch import nn

from benchmarks.harness import Case
from torchgeo_cg.mesh import marching_cubes, sparse_marching_cubes
from torchgeo_cg.sdf import sample_grid

BOUNDS = torch.tensor([-1.2, 1.2])
ROOT = Path(__file__).resolve().parent.parent


def torus(p: torch.Tensor) -> torch.Tensor:
    """Torus SDF (R = 0.7, r = 0.3) around z."""
    return torch.stack([p[:, :2].norm(dim=1) - 0.7, p[:, 2]], 1).norm(dim=1) - 0.3


def mlp() -> nn.Module:
    """4 x 128 softplus MLP around a sphere (float32)."""
    torch.manual_seed(0)
    net = nn.Sequential(nn.Linear(3, 128), nn.Softplus(beta=10), nn.Linear(128, 128),
                        nn.Softplus(beta=10), nn.Linear(128, 128), nn.Softplus(beta=10),
                        nn.Linear(128, 1))
    return lambda p: p.norm(dim=1) - 0.6 + 0.02 * net(p).squeeze(1)


def _torus_py(x: float, y: float, z: float) -> float:
    return math.hypot(math.hypot(x, y) - 0.7, z) - 0.3


def _tools(n: int) -> dict:
    """What a fresh process can run at ``n^3``: name -> (prepare, run); prepare's result
    (a dense grid for scikit-image) is made before the baseline and passed to run."""
    field = mlp()
    return {
        "sparse": (None, lambda _: sparse_marching_cubes(torus, BOUNDS, n).faces.shape[0]),
        "dense": (None, lambda _: marching_cubes(sample_grid(torus, n, BOUNDS)).faces.shape[0]),
        "sparse_mlp": (None, lambda _: sparse_marching_cubes(
            field, BOUNDS, n, lipschitz=None).faces.shape[0]),
        "dense_mlp": (None, lambda _: marching_cubes(
            sample_grid(field, n, BOUNDS)).faces.shape[0]),
        "skimage": (lambda: sample_grid(torus, n, BOUNDS).values.numpy(),
                    lambda grid: _skimage_mc(grid).shape[0]),
        "pymcubes": (None, lambda _: _pymcubes(n).shape[0]),
    }


def _skimage_mc(grid):
    from skimage.measure import marching_cubes as sk_marching_cubes

    return sk_marching_cubes(grid, 0.0)[1]


def _pymcubes(n: int):
    import mcubes

    return mcubes.marching_cubes_func((-1.2,) * 3, (1.2,) * 3, n, n, n, _torus_py, 0.0)[1]


def _peak_kib() -> int:
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM"))


def _fresh_main(tool: str, n: int) -> None:
    """Run ``tool`` at ``n^3`` once (after a 32^3 warm-up) and print its time, peak RSS above
    the baseline and face count as JSON."""
    torch.set_num_threads(1)
    with torch.no_grad():
        prepare, run = _tools(32)[tool]
        run(prepare() if prepare else None)
        prepare, run = _tools(n)[tool]
        data = prepare() if prepare else None
        before, start = _peak_kib(), time.perf_counter()
        faces = run(data)
        seconds = time.perf_counter() - start
    print(json.dumps({"s": seconds, "peak_extra_MiB": (_peak_kib() - before) / 1024,
                      "faces": faces}))


def fresh_process(tool: str, n: int) -> dict:
    """Time, peak RSS above the baseline and face count of ``tool`` at ``n^3``, in a fresh
    process with a fixed ``MALLOC_MMAP_THRESHOLD_`` (glibc's default makes peaks vary by a
    third between identical runs)."""
    env = dict(os.environ, MALLOC_MMAP_THRESHOLD_="65536",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-m", "benchmarks.bench_sparse_mc", tool, str(n)],
                         env=env, cwd=ROOT, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _fresh_case(name: str, n: int, ours: str, peer: str | None = None, peer_name: str = "",
                target: float | None = None, extra: dict | None = None) -> Case:
    return Case(name=f"{name} (fresh processes)", once=True, threads=(1,), target=target,
                ours=lambda: fresh_process(ours, n),
                peer=None if peer is None else (lambda: fresh_process(peer, n)),
                peer_name=peer_name, extra=extra or {})


def cases(quick: bool) -> list[Case]:
    out: list[Case] = []
    for n in ((64,) if quick else (128, 256)):
        out.append(Case(
            name=f"sparse_marching_cubes torus {n}^3 f32 (vs sample_grid + marching_cubes)",
            ours=lambda n=n: sparse_marching_cubes(torus, BOUNDS, n),
            peer=lambda n=n: marching_cubes(sample_grid(torus, n, BOUNDS)),
            peer_name="dense (ours)", threads=(1,),
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
    return out + _fresh_cases(quick)


def _fresh_cases(quick: bool) -> list[Case]:
    """The runs of minutes, each in its own process, with time, peak and face counts."""
    big, mlp_n, anchor, huge = (48, 32, 48, 64) if quick else (1024, 512, 512, 2048)
    return [
        _fresh_case(f"sparse_marching_cubes torus {big}^3 f32 (vs sample_grid + "
                    "marching_cubes)", big, "sparse", "dense", "dense (ours)", 0.5,
                    {"peak_target_MiB": 1024}),
        _fresh_case(f"sparse_marching_cubes torus {huge}^3 f32", huge, "sparse"),
        _fresh_case(f"sparse_marching_cubes MLP 4x128 {mlp_n}^3 f32 lipschitz=None (vs dense "
                    "evaluation + marching_cubes)", mlp_n, "sparse_mlp", "dense_mlp",
                    "dense (ours)", 0.2),
        _fresh_case(f"sparse_marching_cubes torus {anchor}^3 f32 (vs scikit-image on the "
                    "sampled grid, sampling not timed)", anchor, "sparse", "skimage",
                    "skimage marching_cubes"),
        *(_fresh_case(f"sparse_marching_cubes torus {n}^3 f32 (vs PyMCubes "
                      "marching_cubes_func, a Python callable)", n, "sparse", "pymcubes",
                      "PyMCubes") for n in ((32,) if quick else (256, 512))),
    ]


def _no_grad(fn):
    with torch.no_grad():
        return fn()


if __name__ == "__main__":
    _fresh_main(sys.argv[1], int(sys.argv[2]))
