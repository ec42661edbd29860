"""Signed distance fields (issue 4).

Targets, 1 thread, ratios measured side by side in one process:

- ``mesh_sdf`` on a 16k-face closed mesh (a torus scaled into the unit sphere, as
  DeepSDF normalizes), 250k DeepSDF-distributed points (94% surface points perturbed
  with variances 0.005 / 0.0005, 6% uniform in [-1, 1]^3): at least 10x the throughput
  of ``trimesh.proximity.signed_distance`` (ratio ours / trimesh <= 0.1; trimesh runs on
  2,000 of the points, extrapolated with ``peer_scale``), >= 100k points/s, 0 sign errors
  against a brute-force exact reference (all faces, winding-number sign), distance
  error <= 1e-6 in float64 (both on a random subset, size in the notes).
- ``sample_grid`` of the exact torus at 256^3: <= 1.5x the time of the same expression
  in plain torch on a fully materialized (prebuilt) grid; peak memory at 512^3 reported.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time

import torch

from benchmarks.harness import Case
from torchgeo_cg.sdf import grid_points, mesh_sdf, sample_grid, torus, winding_number
from torchgeo_cg.sdf.mesh_search import face_table as _face_table
from torchgeo_cg.sdf.mesh_search import pair_d2 as _pair_d2
from torchgeo_cg.sdf.sampler import sample_mesh_surface

# VmHWM (peak resident set) of a fresh process; unlike ru_maxrss it is not inherited
# from the parent across exec.
_PEAK_SCRIPT = """
import sys, torch
from torchgeo_cg.sdf import sample_grid, torus
def hwm():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
torch.set_num_threads(1)
n = int(sys.argv[1])
sample_grid(lambda p: torus(p, 1.0, 0.3), 8, (-1.5, 1.5))
base = hwm()
vol = sample_grid(lambda p: torus(p, 1.0, 0.3), n, (-1.5, 1.5))
peak = hwm()
print(base, peak, vol.values.numel() * vol.values.element_size() / 2**20)
"""


def _peak_memory_mb(n: int) -> tuple[float, float, float]:
    """(baseline RSS, peak RSS, output size) in MiB of ``sample_grid`` at ``n^3`` (subprocess)."""
    out = subprocess.run([sys.executable, "-c", _PEAK_SCRIPT, str(n)], capture_output=True,
                         text=True, check=True).stdout.split()
    return float(out[0]), float(out[1]), float(out[2])


def _deepsdf_points(vertices, faces, n, gen):
    n_uniform = round(0.06 * n)
    half = math.ceil((n - n_uniform) / 2)
    surf = sample_mesh_surface(vertices, faces, half, gen)
    near = torch.cat([surf + math.sqrt(0.005) * torch.randn(surf.shape, generator=gen,
                                                            dtype=surf.dtype),
                      surf + math.sqrt(0.0005) * torch.randn(surf.shape, generator=gen,
                                                             dtype=surf.dtype)])
    uni = torch.rand(n_uniform, 3, generator=gen, dtype=surf.dtype) * 2 - 1
    pts = torch.cat([near[: n - n_uniform], uni])
    return pts[torch.randperm(n, generator=gen)]


def _brute_force(vertices, faces, points, block=1 << 22):
    """Exact unsigned distance over every face, and the winding-number inside mask."""
    table = _face_table(vertices[faces].double())
    F = faces.shape[0]
    step = max(1, block // F)
    best = []
    for s in range(0, points.shape[0], step):
        p = points[s:s + step].double()
        pairs = p.repeat_interleave(F, 0).t().contiguous()
        d2 = _pair_d2(table, pairs, torch.arange(F).repeat(p.shape[0]))
        best.append(d2.reshape(p.shape[0], F).min(1).values.sqrt())
    inside = winding_number(vertices, faces, points) > 0.5
    return torch.cat(best), inside


def _mesh_case(quick: bool) -> Case:
    import trimesh

    sections = (64, 32) if quick else (128, 64)
    mesh = trimesh.creation.torus(1.0, 0.3, major_sections=sections[0],
                                  minor_sections=sections[1])
    mesh.apply_scale(1.0 / 1.3)  # into the unit sphere, as DeepSDF normalizes
    V = torch.tensor(mesh.vertices, dtype=torch.float64)
    F = torch.tensor(mesh.faces)
    n = 50_000 if quick else 250_000
    gen = torch.Generator().manual_seed(0)
    points = _deepsdf_points(V, F, n, gen)
    n_peer = 500 if quick else 2000
    peer_points = points[:n_peer].numpy()

    # correctness on a random subset against brute force (all faces)
    n_check = 1000 if quick else 5000
    prev = torch.get_num_threads()
    torch.set_num_threads(1)
    runs = []
    for _ in range(3):  # median of 3 (the first call also pays the allocator's warm-up)
        t0 = time.perf_counter()
        ours = mesh_sdf(V, F, points).sdf
        runs.append(time.perf_counter() - t0)
    single = sorted(runs)[1]
    torch.set_num_threads(prev)
    ref_d, ref_inside = _brute_force(V, F, points[:n_check])
    sign_errors = int(((ours[:n_check] < 0) != ref_inside).sum())
    dist_err = float((ours[:n_check].abs() - ref_d).abs().max())
    trimesh_sd = trimesh.proximity.signed_distance(mesh, peer_points[:200])
    trimesh_err = float((torch.from_numpy(-trimesh_sd) - ours[:200]).abs().max())
    return Case(
        f"mesh_sdf {F.shape[0]} faces, {n} DeepSDF points, f64",
        lambda: mesh_sdf(V, F, points),
        lambda: trimesh.proximity.signed_distance(mesh, peer_points),
        f"trimesh {trimesh.__version__} signed_distance",
        target=0.1,
        peer_scale=n / n_peer,
        extra={
            "points_per_s_1thread": n / single,
            "target_points_per_s": 100_000,
            "sign_errors": sign_errors,
            "max_dist_err_f64": dist_err,
            "checked_points": n_check,
            "max_diff_vs_trimesh": trimesh_err,
        },
    )


def _grid_case(quick: bool) -> Case:
    n = 96 if quick else 256
    big, small = 1.0, 0.3
    bounds = (-1.5, 1.5)
    grid = grid_points(n, bounds)  # the peer's fully materialized grid, built outside

    def plain():
        x, y, z = grid[..., 0], grid[..., 1], grid[..., 2]
        return torch.sqrt((torch.sqrt(x * x + y * y) - big) ** 2 + z * z) - small

    def ours():
        return sample_grid(lambda p: torus(p, big, small), n, bounds).values

    err = float((ours() - plain()).abs().max())
    peak_n = 256 if quick else 512
    base, peak, output = _peak_memory_mb(peak_n)
    return Case(
        f"sample_grid exact torus {n}^3 f32",
        ours,
        plain,
        "plain torch, materialized grid",
        target=1.5,
        extra={
            "max_abs_diff": err,
            f"peak_rss_mb_at_{peak_n}^3": peak,
            "baseline_rss_mb": base,
            "output_mb": output,
            "overhead_mb": peak - base - output,
            "materialized_grid_mb": peak_n**3 * 3 * 4 / 2**20,
        },
    )


def cases(quick: bool = False) -> list[Case]:
    return [_mesh_case(quick), _grid_case(quick)]
