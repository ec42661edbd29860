"""radius_search, voxel_downsample, outlier removal, farthest point sampling and icp: the
Warp and torch paths agree exactly, against a brute force written here and Open3D run
live; ties, duplicates, points at exactly the radius, batches, lengths, empty, NaN, errors."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from torchgeo_cg.core import ShapeError
from torchgeo_cg.engine import warp_status
from torchgeo_cg.mesh.data import rabbit_scan_pairs
from torchgeo_cg.points import (
    ICPConvergence,
    estimate_normals,
    farthest_point_sampling,
    icp,
    knn,
    radius_search,
    remove_radius_outliers,
    remove_statistical_outliers,
    voxel_downsample,
)

ROOT = Path(__file__).resolve().parents[2]
HAS_WARP = warp_status()[0] == "ok"
BACKENDS = ["torch", pytest.param("warp", marks=pytest.mark.skipif(
    not HAS_WARP, reason="Warp is not available here"))]


def _o3d():
    return pytest.importorskip("open3d")


def _clouds(kind: str, n: int, D: int, seed: int, dtype=torch.float64) -> torch.Tensor:
    """Random, clustered, duplicated or on-a-lattice (ties) points."""
    g = torch.Generator().manual_seed(seed)
    if kind == "random":
        return torch.rand(n, D, generator=g, dtype=dtype)
    if kind == "clustered":
        return torch.rand(n, D, generator=g, dtype=dtype) ** 4
    if kind == "duplicates":
        p = torch.rand(n // 2 + 1, D, generator=g, dtype=dtype)
        return torch.cat([p, p])[:n]
    return torch.randint(0, 5, (n, D), generator=g).to(dtype) / 4  # lattice: many ties


def brute_radius(q, r, radius, K=None):
    """Every pair, stable sort by squared distance (ties -> smaller index)."""
    d2 = (q[:, None, :] - r[None, :, :]).square().sum(-1)
    rows = []
    for i in range(q.shape[0]):  # the reference loops over points on purpose
        inside = (d2[i] <= radius * radius).nonzero().flatten()
        order = inside[torch.sort(d2[i, inside], stable=True).indices]
        rows.append(order)
    counts = torch.tensor([len(o) for o in rows])
    K = int(counts.max()) if K is None else K
    idx = torch.full((q.shape[0], K), -1)
    for i, o in enumerate(rows):
        idx[i, :min(K, len(o))] = o[:K]
    return idx, counts


# ----------------------------------------------------------------------------- radius


@pytest.mark.parametrize("kind", ["random", "clustered", "duplicates", "lattice"])
@pytest.mark.parametrize("D", [2, 3])
@pytest.mark.parametrize("K", [None, 3])
def test_radius_equals_brute_force_on_both_backends(kind, D, K):
    r = _clouds(kind, 300, D, seed=D)
    q = torch.cat([_clouds("random", 100, D, seed=7), r[:20]])
    radius = 0.25  # the lattice has points at exactly this distance
    want_idx, want_counts = brute_radius(q, r, radius, K)
    results = {}
    for backend in ("torch", "warp") if HAS_WARP else ("torch",):
        res = radius_search(q, r, radius, max_neighbors=K, backend=backend)
        assert torch.equal(res.idx, want_idx), backend
        assert torch.equal(res.counts, want_counts)
        assert torch.equal(res.overflow, want_counts > res.idx.shape[-1])
        found = res.idx >= 0
        d2 = (q[:, None] - r[res.idx.clamp_min(0)]).square().sum(-1)
        torch.testing.assert_close(res.dists, torch.where(found, d2, 0.0), rtol=0, atol=0)
        results[backend] = res
    if len(results) == 2:
        for a, b in zip(results["torch"], results["warp"]):
            assert torch.equal(a, b)


@pytest.mark.parametrize("backend", BACKENDS)
def test_radius_batches_lengths_nan_and_empty(backend):
    g = torch.Generator().manual_seed(1)
    q = torch.rand(2, 3, 40, 3, generator=g)
    r = torch.rand(3, 50, 3, generator=g)  # broadcast over the first batch dim
    ql = torch.tensor([[40, 10, 0], [5, 40, 40]])
    rl = torch.tensor([[50, 0, 20], [50, 1, 50]])
    res = radius_search(q, r, 0.3, query_lengths=ql, ref_lengths=rl, backend=backend)
    K = res.idx.shape[-1]
    for i in range(2):
        for j in range(3):
            idx, counts = brute_radius(q[i, j, :ql[i, j]], r[j, :rl[i, j]], 0.3, K)
            assert torch.equal(res.idx[i, j, :ql[i, j]], idx)
            assert torch.equal(res.counts[i, j, :ql[i, j]], counts)
            assert (res.idx[i, j, ql[i, j]:] == -1).all() and (res.counts[i, j, ql[i, j]:]
                                                                == 0).all()
    bad_q, bad_r = q[0, 0].clone(), r[0].clone()
    bad_q[3, 1] = math.nan
    bad_r[5, 0] = math.nan
    out = radius_search(bad_q, bad_r, 0.3, backend=backend)
    assert out.counts[3] == 0 and (out.idx[3] == -1).all() and out.dists[3].isnan().all()
    assert not (out.idx == 5).any()  # a NaN reference is nobody's neighbour
    assert not out.dists[torch.arange(40) != 3].isnan().any()
    empty = radius_search(torch.zeros(0, 3), r[0], 0.3, backend=backend)
    assert empty.idx.shape == (0, 0) and empty.counts.shape == (0,)
    none = radius_search(q[0, 0], torch.zeros(0, 3), 0.3, backend=backend)
    assert none.idx.shape == (40, 0) and (none.counts == 0).all()


def test_radius_scale_invariance_gradient_and_errors():
    q, r = _clouds("random", 30, 3, 2), _clouds("lattice", 60, 3, 3)
    base = radius_search(q, r, 0.5)
    for s in (2.0**-20, 3.0, 1e6):
        scaled = radius_search(q * s, r * s, 0.5 * s)
        assert torch.equal(scaled.idx, base.idx) and torch.equal(scaled.counts, base.counts)
    # gradients on a random cloud (on the lattice a nudge changes the neighbour sets)
    qq = q.clone().requires_grad_()
    rr = _clouds("random", 60, 3, 4).requires_grad_()
    assert torch.autograd.gradcheck(
        lambda a, b: radius_search(a, b, 0.5, max_neighbors=4).dists, (qq, rr))
    with pytest.raises(ShapeError, match="ref"):
        radius_search(q, torch.zeros(5, 2, dtype=q.dtype), 0.5)
    with pytest.raises(ShapeError, match="query"):
        radius_search(torch.zeros(3), r, 0.5)
    for radius in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError, match="radius"):
            radius_search(q, r, radius)
    with pytest.raises(ValueError, match="max_neighbors"):
        radius_search(q, r, 0.5, max_neighbors=0)
    with pytest.raises(ValueError, match="backend"):
        radius_search(q, r, 0.5, backend="cuda")


def test_radius_equals_open3d():
    o3d = _o3d()
    r = _clouds("clustered", 2000, 3, 5)
    q = _clouds("random", 200, 3, 6)
    tree = o3d.geometry.KDTreeFlann(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(
        r.numpy())))
    res = radius_search(q, r, 0.2)
    for i in range(q.shape[0]):  # the peer answers one query at a time
        count, idx, _ = tree.search_radius_vector_3d(q[i].numpy(), 0.2)
        assert int(res.counts[i]) == count
        assert set(res.idx[i, :count].tolist()) == set(np.asarray(idx).tolist())


# ----------------------------------------------------------------------------- voxels


def test_voxel_downsample_equals_open3d():
    o3d = _o3d()
    p = torch.cat([_clouds("clustered", 3000, 3, 8), _clouds("duplicates", 500, 3, 9)])
    colours = torch.rand(p.shape, generator=torch.Generator().manual_seed(0),
                         dtype=torch.float64)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p.numpy()))
    pc.colors = o3d.utility.Vector3dVector(colours.numpy())
    down = pc.voxel_down_sample(0.05)
    ours = voxel_downsample(p, 0.05, features=colours)
    theirs = np.asarray(down.points)
    order = np.lexsort(theirs.T[::-1])
    mine = ours.points.numpy()
    assert mine.shape == theirs.shape
    # ours is sorted by voxel index; the peer's order is its hash map's: compare sorted
    np.testing.assert_allclose(mine[np.lexsort(mine.T[::-1])], theirs[order], rtol=0,
                               atol=1e-12)
    cols = ours.features.numpy()[np.lexsort(mine.T[::-1])]
    np.testing.assert_allclose(cols, np.asarray(down.colors)[order], rtol=0, atol=1e-12)


def test_voxel_order_batches_gradient_nan_and_errors():
    p = torch.tensor([[0.9, 0.0, 0.0], [0.0, 0.9, 0.0], [0.0, 0.0, 0.9], [0.1, 0.1, 0.1],
                      [0.0, 0.0, 0.0]], dtype=torch.float64)
    out = voxel_downsample(p, 0.5)  # origin -0.25: voxels (0,0,0) (0,0,2) (0,2,0) (2,0,0)
    assert out.points.tolist() == [[0.05, 0.05, 0.05], [0.0, 0.0, 0.9], [0.0, 0.9, 0.0],
                                   [0.9, 0.0, 0.0]]
    batch = torch.stack([p, p.flip(0) * 2])
    res = voxel_downsample(batch, 0.5, lengths=torch.tensor([5, 2]))
    assert res.lengths.tolist() == [4, 1]  # (0, 0, 0) and (0.2, 0.2, 0.2) share a voxel
    assert torch.equal(res.points[0], out.points)
    assert torch.equal(res.points[1, :1], voxel_downsample(batch[1, :2], 0.5).points)
    assert (res.points[1, 1:] == 0).all()
    x = p.clone().requires_grad_()
    assert torch.autograd.gradcheck(lambda a: voxel_downsample(a, 0.5).points, (x,))
    nan = p.clone()
    nan[1, 0] = math.nan
    assert voxel_downsample(nan, 0.5).lengths == 3  # the NaN point is ignored
    empty = voxel_downsample(torch.zeros(2, 0, 3), 0.5)
    assert empty.points.shape == (2, 0, 3) and empty.lengths.tolist() == [0, 0]
    for size in (0.0, -1.0, math.inf):
        with pytest.raises(ValueError, match="voxel_size"):
            voxel_downsample(p, size)
    with pytest.raises(ShapeError, match="features"):
        voxel_downsample(p, 0.5, features=torch.zeros(4, 2, dtype=p.dtype))


# ----------------------------------------------------------------------------- outliers


def _noisy_scan(n=3000, seed=0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    p = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=torch.float64), dim=-1)
    p[: n // 20] = torch.rand(n // 20, 3, generator=g, dtype=torch.float64) * 4 - 2  # outliers
    p[100:130] = p[130:160]  # duplicates
    p[200:205] = p[205]  # a point repeated six times: its mean distance can be 0
    return p


@pytest.mark.parametrize("backend", BACKENDS)
def test_statistical_outliers_equal_open3d(backend):
    o3d = _o3d()
    p = _noisy_scan()
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p.numpy()))
    for k, ratio in ((6, 1.0), (20, 2.0), (3, 0.5), (1, 1.0)):
        _, keep = pc.remove_statistical_outlier(k, ratio)
        want = torch.zeros(len(p), dtype=torch.bool)
        want[torch.tensor(np.asarray(keep), dtype=torch.long)] = True
        assert torch.equal(remove_statistical_outliers(p, k, ratio, backend=backend), want)


@pytest.mark.parametrize("backend", BACKENDS)
def test_radius_outliers_equal_open3d(backend):
    o3d = _o3d()
    p = _noisy_scan(seed=1)
    lattice = _clouds("lattice", 300, 3, 4)  # points at exactly the radius: strict test
    for cloud, radius in ((p, 0.1), (p, 0.05), (lattice, 0.25)):
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.numpy()))
        for m in (1, 4, 16):
            _, keep = pc.remove_radius_outlier(m, radius)
            want = torch.zeros(len(cloud), dtype=torch.bool)
            want[torch.tensor(np.asarray(keep), dtype=torch.long)] = True
            got = remove_radius_outliers(cloud, radius, m, backend=backend)
            assert torch.equal(got, want), (radius, m)


@pytest.mark.skipif(not HAS_WARP, reason="Warp is not available here")
@pytest.mark.parametrize("kind", ["clustered", "duplicates", "lattice"])
@pytest.mark.parametrize("D", [2, 3])
def test_radius_outliers_backends_agree(kind, D):
    # the kernel counts to min_neighbors + 1 and stops; the torch path takes that k-th
    # neighbour's distance: equal on ties at exactly the radius, NaN rows and lengths
    p = torch.stack([_clouds(kind, 1500, D, s) for s in range(2)])
    p[0, :40] = math.nan
    p[1, 1000:] = p[1, 1000:] * 5
    L = torch.tensor([1500, 1200])
    for radius in (0.05, 0.25, 1e-9):
        for m in (0, 3, 12, 60):
            a = remove_radius_outliers(p, radius, m, lengths=L, backend="torch")
            b = remove_radius_outliers(p, radius, m, lengths=L, backend="warp")
            assert torch.equal(a, b), (radius, m)
            assert not b[1, 1200:].any() and not b[0, :40].any()


def test_outliers_batches_nan_empty_and_errors():
    p = _noisy_scan(400, seed=2)
    q = _noisy_scan(400, seed=3)
    batch = torch.stack([p, q])
    L = torch.tensor([400, 250])
    s = remove_statistical_outliers(batch, 8, 1.0, lengths=L)
    assert torch.equal(s[0], remove_statistical_outliers(p, 8, 1.0))
    assert torch.equal(s[1, :250], remove_statistical_outliers(q[:250], 8, 1.0))
    assert not s[1, 250:].any()
    r = remove_radius_outliers(batch, 0.2, 3, lengths=L)
    assert torch.equal(r[1, :250], remove_radius_outliers(q[:250], 0.2, 3))
    assert not r[1, 250:].any()
    nan = p.clone()
    nan[300] = math.nan
    clean = torch.cat([p[:300], p[301:]])
    for fn in (lambda x: remove_statistical_outliers(x, 8, 1.0),
               lambda x: remove_radius_outliers(x, 0.2, 3)):
        got = fn(nan)
        assert not got[300]  # never an inlier, and nobody's neighbour
        assert torch.equal(torch.cat([got[:300], got[301:]]), fn(clean))
        assert fn(torch.zeros(0, 3)).shape == (0,)
    for call, name in ((lambda: remove_statistical_outliers(p, 0, 1.0), "k"),
                       (lambda: remove_statistical_outliers(p, 4, -1.0), "std_ratio"),
                       (lambda: remove_radius_outliers(p, 0.0, 3), "radius"),
                       (lambda: remove_radius_outliers(p, 0.1, -1), "min_neighbors")):
        with pytest.raises(ValueError, match=name):
            call()
    with pytest.raises(ShapeError, match="points"):
        remove_radius_outliers(torch.zeros(3), 0.1, 2)


# ----------------------------------------------------------------------------- sampling


@pytest.mark.parametrize("kind", ["random", "clustered", "duplicates", "lattice"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.skipif(not HAS_WARP, reason="Warp is not available here")
def test_fps_backends_agree(kind, dtype):
    p = torch.stack([_clouds(kind, 300, 3, s, dtype) for s in range(3)])
    L = torch.tensor([300, 120, 7])
    for k in (1, 40, 300, 310):
        a = farthest_point_sampling(p, k, L, start=2, backend="torch")
        b = farthest_point_sampling(p, k, L, start=2, backend="warp")
        assert torch.equal(a.indices, b.indices) and torch.equal(a.points, b.points)
    p2 = p[..., :2].contiguous()
    assert torch.equal(farthest_point_sampling(p2, 50, backend="torch").indices,
                       farthest_point_sampling(p2, 50, backend="warp").indices)


@pytest.mark.parametrize("kind", ["clustered", "duplicates", "lattice"])
@pytest.mark.skipif(not HAS_WARP, reason="Warp is not available here")
def test_fps_backends_agree_on_many_buckets(kind):
    # thousands of points: the kernel skips the buckets a pick cannot change
    p = torch.stack([_clouds(kind, 3000, 3, s) for s in range(2)]) * torch.tensor([1e3, 1, 1e-3])
    L = torch.tensor([3000, 2000])
    a = farthest_point_sampling(p, 700, L, start=5, backend="torch")
    b = farthest_point_sampling(p, 700, L, start=5, backend="warp")
    assert torch.equal(a.indices, b.indices)
    p2 = p[0, :, 1:].float().contiguous()
    assert torch.equal(farthest_point_sampling(p2, 400, backend="torch").indices,
                       farthest_point_sampling(p2, 400, backend="warp").indices)


def test_fps_equals_open3d():
    o3d = _o3d()
    p = _clouds("random", 2000, 3, 11)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p.numpy()))
    theirs = np.asarray(pc.farthest_point_down_sample(64).points)
    ours = farthest_point_sampling(p, 64).points.numpy()  # both start at index 0
    # the peer returns the picks in index order (SelectByIndex): compare as sets of rows
    np.testing.assert_array_equal(ours[np.lexsort(ours.T[::-1])],
                                  theirs[np.lexsort(theirs.T[::-1])])


# ----------------------------------------------------------------------------- knn, icp


@pytest.mark.skipif(not HAS_WARP, reason="Warp is not available here")
@pytest.mark.parametrize("kind", ["random", "clustered", "duplicates", "lattice"])
def test_knn_backends_agree_on_every_layout(kind):
    r = torch.stack([_clouds(kind, 900, 3, s, torch.float32) for s in range(2)])
    q = torch.cat([r[:, :100], _clouds("random", 200, 3, 5, torch.float32).expand(2, -1, -1)
                   * 3 - 1], 1)  # queries on, near and far from the references
    for k in (1, 5, 16):
        for lengths in ((None, None), (torch.tensor([300, 0]), torch.tensor([900, 3]))):
            a = knn(q, r, k, *lengths, backend="torch")
            b = knn(q, r, k, *lengths, backend="warp")
            assert torch.equal(a.idx, b.idx) and torch.equal(a.dists, b.dists)


@pytest.mark.skipif(not HAS_WARP, reason="Warp is not available here")
@pytest.mark.parametrize("method", ["point_to_point", "point_to_plane"])
def test_icp_backends_agree_on_the_scans(method):
    pairs = rabbit_scan_pairs(2, points=1500, generator=torch.Generator().manual_seed(0))
    normals = estimate_normals(pairs.target, 10)
    runs = [icp(pairs.source, pairs.target, method=method, max_distance=0.2 * pairs.size,
                target_normals=normals, convergence=ICPConvergence(20), backend=backend)
            for backend in ("torch", "warp")]
    for a, b in zip(*runs):
        assert torch.equal(a, b)


# ----------------------------------------------------------------------------- guide


def test_the_guide_page_runs():
    text = (ROOT / "docs" / "guide" / "neighbourhoods.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "the guide page has no python block"
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "neighbourhoods.md", "exec"), namespace)  # noqa: S102
