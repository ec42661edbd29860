"""Nearest neighbours, radius search, Chamfer, voxels, outliers and sampling against scipy's
cKDTree and Open3D. The targets hold at 1 thread; the 2-thread rows are reported (the
peers get the same count: cKDTree ``workers``, Open3D's TBB pool through the harness; our
Warp kernels run on one thread on the CPU, the torch steps around them on two).

Targets (ratio ours / peer):
- ``knn`` k=1 and k=8, float32, on the rabbit scans (8,000 -> 10,000 points) and on
  200,000 -> 200,000 torus-surface points: <= 1.0 x cKDTree (build + query).
- ``radius_search`` on 200,000 torus-surface points, about 32 neighbours each, float32:
  <= 1.0 x cKDTree ``query_ball_point(return_sorted=True)`` + the sort by distance.
- ``voxel_downsample`` of 1M points (float64): <= 1.0 x Open3D ``voxel_down_sample``.
- Outlier removal on 200,000 points (float64): <= 1.0 x Open3D's.
- ``farthest_point_sampling`` 100,000 -> 4,096 (float64): <= 1.0 x Open3D's
  ``farthest_point_down_sample``.
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
from torchgeo_cg.mesh.data import rabbit_scan_pairs
from torchgeo_cg.points import (
    chamfer_distance,
    farthest_point_sampling,
    knn,
    radius_search,
    remove_radius_outliers,
    remove_statistical_outliers,
    voxel_downsample,
)


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
        tree_b.query(an, workers=torch.get_num_threads())
        tree_a.query(bn, workers=torch.get_num_threads())

    err = float((chamfer_distance(a.double(), b.double()).loss
                 - (cKDTree(bn).query(an)[0] ** 2).mean() - (cKDTree(an).query(bn)[0] ** 2).mean())
                .abs())
    out = [Case(f"chamfer_distance {n:,} vs {n:,} pts {label} f32 fwd",
                lambda: chamfer_distance(a, b), peer, f"scipy {scipy_version} cKDTree x2",
                target=target, threads=(1, 2), target_threads=(1,),
                extra={"abs_err_f64_vs_ckdtree": err})]
    return out


def _knn_cases(quick: bool) -> list[Case]:
    from scipy import __version__ as scipy_version
    from scipy.spatial import cKDTree

    gen = torch.Generator().manual_seed(1)
    pairs = rabbit_scan_pairs(1, 10000, generator=torch.Generator().manual_seed(0))
    big = 20000 if quick else 200000
    clouds = [("rabbit scans", pairs.source[0].float(), pairs.target[0].float()),
              ("torus surface", torus_points(big, gen), torus_points(big, gen))]
    out = []
    for label, q, r in clouds:
        qn, rn = q.numpy(), r.numpy()
        for k in (1, 8):
            def peer(k=k, qn=qn, rn=rn):
                cKDTree(rn).query(qn, k=k, workers=torch.get_num_threads())

            out.append(Case(f"knn k={k} {len(q):,} -> {len(r):,} pts {label} f32",
                            lambda k=k, q=q, r=r: knn(q, r, k), peer,
                            f"scipy {scipy_version} cKDTree build + query", target=1.0,
                            threads=(1, 2), target_threads=(1,)))
    return out


def _radius_case(quick: bool) -> Case:
    from scipy import __version__ as scipy_version
    from scipy.spatial import cKDTree

    gen = torch.Generator().manual_seed(2)
    n = 20000 if quick else 200000
    q, r = torus_points(n, gen), torus_points(n, gen)
    area = 4 * math.pi**2 * 1.0 * 0.35
    radius = math.sqrt(32 / (math.pi * n / area))  # about 32 neighbours per query
    qn, rn = q.numpy(), r.numpy()

    def peer():
        tree = cKDTree(rn)
        rows = tree.query_ball_point(qn, radius, return_sorted=True,
                                     workers=torch.get_num_threads())
        for i, row in enumerate(rows):  # the peer's sort by distance, as ours returns
            d = ((rn[row] - qn[i]) ** 2).sum(-1)
            sorted(zip(d.tolist(), row))

    mean = float(radius_search(q, r, radius).counts.double().mean())
    return Case(f"radius_search {n:,} pts torus surface f32, {mean:.0f} neighbours",
                lambda: radius_search(q, r, radius), peer,
                f"scipy {scipy_version} cKDTree query_ball_point + sort", target=1.0,
                threads=(1, 2), target_threads=(1,))


def _open3d_cases(quick: bool) -> list[Case]:
    import open3d as o3d

    gen = torch.Generator().manual_seed(3)
    vec = o3d.utility.Vector3dVector
    n_vox, n_out, n_fps = (100000, 20000, 10000) if quick else (1000000, 200000, 100000)
    dense = torch.rand(n_vox, 3, generator=gen, dtype=torch.float64)
    cloud = torus_points(n_out, gen).double()
    cloud[: n_out // 50] = torch.rand(n_out // 50, 3, generator=gen, dtype=torch.float64) * 3
    spread = torus_points(n_fps, gen).double()
    pc_dense, pc_cloud, pc_spread = (o3d.geometry.PointCloud(vec(x.numpy()))
                                     for x in (dense, cloud, spread))
    name = f"open3d {o3d.__version__}"
    return [
        Case(f"voxel_downsample {n_vox:,} pts f64 voxel 0.01", lambda: voxel_downsample(
            dense, 0.01), lambda: pc_dense.voxel_down_sample(0.01),
            f"{name} voxel_down_sample", target=1.0, threads=(1, 2),
             target_threads=(1,)),
        Case(f"remove_statistical_outliers {n_out:,} pts f64 k=20 std 2",
             lambda: remove_statistical_outliers(cloud, 20, 2.0),
             lambda: pc_cloud.remove_statistical_outlier(20, 2.0),
             f"{name} remove_statistical_outlier", target=1.0, threads=(1, 2),
             target_threads=(1,)),
        Case(f"remove_radius_outliers {n_out:,} pts f64 16 within 0.03",
             lambda: remove_radius_outliers(cloud, 0.03, 16),
             lambda: pc_cloud.remove_radius_outlier(16, 0.03),
             f"{name} remove_radius_outlier", target=1.0, threads=(1, 2),
             target_threads=(1,)),
        Case(f"farthest_point_sampling {n_fps:,} -> 4,096 pts f64",
             lambda: farthest_point_sampling(spread, 4096),
             lambda: pc_spread.farthest_point_down_sample(4096),
             f"{name} farthest_point_down_sample", target=1.0, threads=(1, 2),
             target_threads=(1,)),
    ]


def cases(quick: bool = False) -> list[Case]:
    gen = torch.Generator().manual_seed(0)
    out: list[Case] = _knn_cases(quick) + [_radius_case(quick)] + _open3d_cases(quick)
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
                    target=1.5, threads=(1, 2), target_threads=(1,)))
    cube_a, cube_b = torch.rand(n, 3, generator=gen), torch.rand(n, 3, generator=gen)
    out += _chamfer_cases(n, cube_a, cube_b, None, "uniform cube")
    return out
