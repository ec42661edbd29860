"""Signed distance fields.

Targets, 1 thread, ratios measured side by side in one process:

- ``mesh_sdf(backend="torch")`` on a 16k-face closed mesh (a torus scaled into the unit
  sphere, as DeepSDF normalizes), 250k DeepSDF-distributed points (94% surface points
  perturbed with variances 0.005 / 0.0005, 6% uniform in [-1, 1]^3): >= 150k points/s,
  ratio to ``trimesh.proximity.signed_distance`` <= 0.1 (trimesh runs on 2,000 of the
  points, extrapolated with ``peer_scale``), 0 sign errors against a brute-force exact
  reference (all faces, winding-number sign), distance error <= 1e-6 in float64.
- ``mesh_sdf(backend="auto")`` with the extra ``fast`` (Warp) on the same input:
  >= 800k points/s, float64 output, exact against the brute force; reported side by side
  with the engines a user would pick instead (Open3D, Warp's bare float32 query,
  point-cloud-utils, libigl), as installed. libigl and point-cloud-utils run their own
  threads (``IGL_NUM_THREADS=1`` is set before they load).
- ``SDFSampler`` 500k samples from the shipped control mesh (``rabbit.obj``, Catmull-Clark
  level 2), with the extra (``"auto"``) against without it (torch backend).
- ``sample_grid`` of the exact torus at 256^3: <= 1.5x the time of the same expression
  in plain torch on a fully materialized (prebuilt) grid; peak memory at 512^3 reported.
"""

from __future__ import annotations

import contextlib
import importlib.util
import math
import os
import subprocess
import sys
import time

import torch

from benchmarks.harness import Case
from torchgeo_cg.sdf import (
    closest_point_on_triangle,
    grid_points,
    mesh_sdf,
    sample_grid,
    torus,
    winding_number,
)
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


def _brute_force(vertices, faces, points, block=1 << 20):
    """Exact unsigned distance over every face, and the winding-number inside mask."""
    v0, v1, v2 = vertices[faces].double().unbind(1)  # (F, 3) each
    F = faces.shape[0]
    step = max(1, block // F)
    best = []
    for s in range(0, points.shape[0], step):  # chunks of points, bounded memory
        p = points[s:s + step].double()[:, None]  # (n, 1, 3) against every face
        d = (closest_point_on_triangle(p, v0, v1, v2).points - p).norm(dim=-1)  # (n, F)
        best.append(d.min(1).values)
    inside = winding_number(vertices, faces, points) > 0.5
    return torch.cat(best), inside


def _torus(quick: bool):
    import trimesh

    sections = (64, 32) if quick else (128, 64)
    mesh = trimesh.creation.torus(1.0, 0.3, major_sections=sections[0],
                                  minor_sections=sections[1])
    mesh.apply_scale(1.0 / 1.3)  # into the unit sphere, as DeepSDF normalizes
    V = torch.tensor(mesh.vertices, dtype=torch.float64)
    F = torch.tensor(mesh.faces)
    n = 50_000 if quick else 250_000
    points = _deepsdf_points(V, F, n, torch.Generator().manual_seed(0))
    return mesh, V, F, points


def _one_thread_rate(fn, n: int, reps: int = 5) -> float:
    """Points per second of ``fn`` at 1 thread, median of ``reps`` runs (after a warm-up)."""
    prev = torch.get_num_threads()
    torch.set_num_threads(1)
    runs = []
    fn()
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        runs.append(time.perf_counter() - t0)
    torch.set_num_threads(prev)
    return n / sorted(runs)[len(runs) // 2]


def _exactness(V, F, points, sdf, n_check: int) -> dict:
    ref_d, ref_inside = _brute_force(V, F, points[:n_check])
    return {"sign_errors": int(((sdf[:n_check] < 0) != ref_inside).sum()),
            "max_dist_err_f64": float((sdf[:n_check].abs() - ref_d).abs().max()),
            "checked_points": n_check}


def _mesh_case(quick: bool) -> Case:
    import trimesh

    mesh, V, F, points = _torus(quick)
    n = points.shape[0]
    n_peer = 500 if quick else 2000
    peer_points = points[:n_peer].numpy()
    ours = mesh_sdf(V, F, points, backend="torch").sdf
    trimesh_sd = trimesh.proximity.signed_distance(mesh, peer_points[:200])
    return Case(
        f"mesh_sdf torch backend {F.shape[0]} faces, {n} DeepSDF points, f64",
        lambda: mesh_sdf(V, F, points, backend="torch"),
        lambda: trimesh.proximity.signed_distance(mesh, peer_points),
        f"trimesh {trimesh.__version__} signed_distance",
        target=0.1,
        peer_scale=n / n_peer,
        threads=(1,),
        extra={
            "points_per_s_1thread": _one_thread_rate(
                lambda: mesh_sdf(V, F, points, backend="torch"), n),
            "target_points_per_s": 150_000,
            **_exactness(V, F, points, ours, 1000 if quick else 2000),
            "max_diff_vs_trimesh": float((torch.from_numpy(-trimesh_sd) - ours[:200]).abs().max()),
        },
    )


def _peer_engines(V, F, points):
    """name -> (zero-argument call, face ids of one call), for the engines installed."""
    import numpy as np

    Vn, Fn, Pn = V.numpy(), F.numpy(), points.numpy()
    Vf, Pf = Vn.astype(np.float32), Pn.astype(np.float32)
    peers = {}
    if importlib.util.find_spec("open3d") is not None:
        try:
            import open3d as o3d

            scene = o3d.t.geometry.RaycastingScene(nthreads=1)
            scene.add_triangles(o3d.core.Tensor(Vf), o3d.core.Tensor(Fn.astype(np.uint32)))
            query = o3d.core.Tensor(Pf)
            ids = scene.compute_closest_points(query, nthreads=1)["primitive_ids"].numpy()
            peers[f"Open3D {o3d.__version__} compute_signed_distance (Embree, f32)"] = (
                lambda: scene.compute_signed_distance(query, nthreads=1), ids)
        except ImportError:  # its wheel needs system libraries (libusb) on Linux
            pass
    if importlib.util.find_spec("warp") is not None:
        peers.update(_warp_peer(Vf, Fn, Pf))
    if importlib.util.find_spec("point_cloud_utils") is not None:
        import point_cloud_utils as pcu

        ids = pcu.closest_points_on_mesh(Pn, Vn, Fn)[1]
        peers["point-cloud-utils signed_distance_to_mesh (f64)"] = (
            lambda: pcu.signed_distance_to_mesh(Pn, Vn, Fn), ids)
    if importlib.util.find_spec("igl") is not None:
        import igl

        ids = igl.signed_distance(Pn, Vn, Fn)[1]
        peers["libigl signed_distance (pseudo-normal, f64, tree per call)"] = (
            lambda: igl.signed_distance(Pn, Vn, Fn), ids)
    return peers


def _warp_peer(Vf, Fn, Pf):
    import logging

    import numpy as np
    import warp as wp

    wp.config.log_level = max(wp.config.log_level, logging.WARNING)  # no banner
    wp.init()

    @wp.kernel
    def query(mesh: wp.uint64, pts: wp.array(dtype=wp.vec3), face: wp.array(dtype=wp.int32),
              sign: wp.array(dtype=wp.float32)):
        i = wp.tid()
        r = wp.mesh_query_point_sign_normal(mesh, pts[i], 1.0e30)
        face[i] = r.face
        sign[i] = r.sign

    mesh = wp.Mesh(points=wp.array(Vf, dtype=wp.vec3, device="cpu"),
                   indices=wp.array(Fn.astype(np.int32).reshape(-1), dtype=wp.int32,
                                    device="cpu"))
    pts = wp.array(Pf, dtype=wp.vec3, device="cpu")
    face = wp.zeros(len(Pf), dtype=wp.int32, device="cpu")
    sign = wp.zeros(len(Pf), dtype=wp.float32, device="cpu")

    def run():
        wp.launch(query, dim=len(Pf), inputs=[mesh.id, pts, face, sign], device="cpu")
        wp.synchronize()

    run()
    return {f"Warp {wp.__version__} mesh_query_point_sign_normal (f32, BVH prebuilt)":
            (run, face.numpy().copy())}


def _wrong_faces(V, F, points, ids, ours_d) -> float:
    """Fraction of points whose face is farther than ours by more than rounding."""
    v0, v1, v2 = V[F][torch.as_tensor(ids).long().reshape(-1)].unbind(1)
    d = (closest_point_on_triangle(points, v0, v1, v2).points - points).norm(dim=-1)
    return float(((d - ours_d) > 1e-12).double().mean())


def _engine_cases(quick: bool) -> list[Case]:
    from torchgeo_cg.sdf import available_engines

    os.environ.setdefault("IGL_NUM_THREADS", "1")
    if not available_engines():
        return [Case("mesh_sdf auto backend: no engine installed (pip install "
                     "torchgeo_cg[fast])", lambda: None)]
    _, V, F, points = _torus(quick)
    n = points.shape[0]
    ours = mesh_sdf(V, F, points, backend="auto", return_closest=True)
    base = {"engine": available_engines()[0],
            "points_per_s_1thread": _one_thread_rate(
                lambda: mesh_sdf(V, F, points, backend="auto"), n),
            "target_points_per_s": 800_000,
            **_exactness(V, F, points, ours.sdf, 1000 if quick else 2000)}
    cases = []
    for name, (call, ids) in _peer_engines(V, F, points).items():
        cases.append(Case(
            f"mesh_sdf auto backend {F.shape[0]} faces, {n} DeepSDF points, f64",
            lambda: mesh_sdf(V, F, points, backend="auto"), call, name, threads=(1,),
            extra={**base, "peer_points_per_s_1thread": _one_thread_rate(call, n),
                   "peer_wrong_face_fraction": _wrong_faces(V, F, points, ids,
                                                             ours.sdf.abs())}))
    return cases


@contextlib.contextmanager
def _without_engines():
    """Make ``backend="auto"`` fall back to torch, as on an install without the extra."""
    from torchgeo_cg.sdf import engines

    saved = dict(engines.ENGINES)
    engines.ENGINES.clear()
    try:
        yield
    finally:
        engines.ENGINES.update(saved)


def _sampler_case(quick: bool) -> Case:
    from torchgeo_cg.mesh import catmull_clark, triangulate_faces
    from torchgeo_cg.mesh.data import rabbit
    from torchgeo_cg.sdf import SDFSampler, available_engines

    mesh = rabbit()
    verts, faces = catmull_clark(mesh.verts.double(), mesh.faces, levels=2)
    tris = triangulate_faces(faces)
    n = 100_000 if quick else 500_000

    def sample():
        return SDFSampler((verts, tris), generator=torch.Generator().manual_seed(0)).sample(n)

    def without():
        with _without_engines():
            return sample()

    ours, peer = sample(), without()
    return Case(
        f"SDFSampler {n} samples, rabbit Catmull-Clark level 2 ({tris.shape[0]} triangles)",
        sample, without, "the same without the extra (torch backend)", threads=(1,),
        extra={"engine": (available_engines() or ["torch"])[0],
               "max_sdf_diff": float((ours.sdf - peer.sdf).abs().max())})


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
    return [_mesh_case(quick), *_engine_cases(quick), _sampler_case(quick),
            _grid_case(quick)]
