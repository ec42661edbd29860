"""The DeepSDF sampler: distribution checked statistically, balance, clamp, seeds, .npz I/O."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import trimesh
from scipy import stats

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.mesh import data as sample_data
from torchgeo_cg.sdf.mesh_distance import mesh_sdf
from torchgeo_cg.sdf.primitives import Torus, sphere, torus
from torchgeo_cg.sdf.sampler import (
    SDFSampler,
    SDFSamples,
    load_samples,
    sample_mesh_surface,
    save_samples,
)


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)

def test_distribution_of_an_analytic_source():
    n = 20000
    s = SDFSampler(lambda p: sphere(p, 0.5), generator=_gen(0), dtype=torch.float64).sample(n)
    assert s.points.shape == (n, 3) and s.sdf.dtype == torch.float64
    n_uni = round(0.06 * n)
    per = (n - n_uni) // 2
    near1, near2, uni = s.sdf[:per], s.sdf[per:2 * per], s.points[2 * per:]
    # the SDF of a surface point of a sphere of radius R moved by N(0, var I) is
    # |R n + e| - R ~ e_n + |e_t|^2 / 2R: standard deviation sqrt(var), mean var / R
    for block, var in ((near1, 0.005), (near2, 0.0005)):
        assert abs(float(block.std()) - math.sqrt(var)) < 0.05 * math.sqrt(var)
        assert abs(float(block.mean()) - var / 0.5) < 4 * math.sqrt(var / per) + 0.1 * var / 0.5
    # uniform block: in the bounds and uniform per axis (Kolmogorov-Smirnov)
    assert uni.shape[0] == n_uni
    for axis in range(3):
        assert stats.kstest(uni[:, axis].numpy(), "uniform", args=(-1, 2)).pvalue > 1e-3
    assert_close(s.sdf, sphere(s.points, 0.5))


def test_mesh_source_surface_and_values():
    m = trimesh.creation.icosphere(subdivisions=2)
    sampler = SDFSampler(m, generator=_gen(1))
    surf = sampler.surface_points(500)
    V, F = torch.tensor(m.vertices), torch.tensor(m.faces)
    assert mesh_sdf(V, F, surf).sdf.abs().max() < 1e-12
    s = SDFSampler(m, generator=_gen(1)).sample(400)
    assert s.sdf.dtype == torch.float64
    assert_close(s.sdf, mesh_sdf(V, F, s.points).sdf)
    lo, hi = V.amin(0), V.amax(0)
    pad = 0.1 * (hi - lo)
    assert (s.points[-24:] >= lo - pad - 1e-12).all() and (s.points[-24:] <= hi + pad + 1e-12).all()
    # (vertices, faces) tuples work the same
    s2 = SDFSampler((V, F), generator=_gen(1)).sample(400)
    assert_close(s2.points, s.points)


def test_surface_sampling_is_area_weighted():
    # two triangles with areas 1/2 and 3 get points in that ratio (binomial test)
    V = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [3, 0, 1], [0, 2, 1]])
    F = torch.tensor([[0, 1, 2], [3, 4, 5]])
    p = sample_mesh_surface(V, F, 4000, torch.Generator().manual_seed(0))
    k = int((p[:, 2] == 0).sum())
    assert stats.binomtest(k, 4000, 0.5 / 3.5).pvalue > 1e-3


def test_analytic_surface_points_lie_on_the_surface():
    s = SDFSampler(Torus(1.0, 0.25), bounds=(-1.5, 1.5), generator=_gen(2))
    surf = s.surface_points(300)
    assert torus(surf, 1.0, 0.25).abs().max() < 1e-5


def test_balanced_clamped_and_reproducible():
    a = SDFSampler(torus, balanced=True, clamp=0.05, generator=_gen(7)).sample(301)
    assert int((a.sdf < 0).sum()) == 150 and int((a.sdf >= 0).sum()) == 151
    assert float(a.sdf.abs().max()) <= 0.05 + 1e-7
    b = SDFSampler(torus, balanced=True, clamp=0.05, generator=_gen(7)).sample(301)
    assert torch.equal(a.points, b.points)
    c = SDFSampler(torus, balanced=True, clamp=0.05, generator=_gen(8)).sample(301)
    assert not torch.equal(a.points, c.points)
    # configurable fractions
    only_uniform = SDFSampler(sphere, uniform_fraction=1.0, generator=_gen(0)).sample(50)
    assert (only_uniform.points.abs() <= 1).all()


def test_save_load_round_trip(tmp_path):
    s = SDFSampler(sphere, generator=_gen(3), dtype=torch.float64).sample(200)
    path = tmp_path / "samples.npz"
    SDFSampler(sphere).save(path, s)
    with np.load(path) as data:
        assert data["pos"].shape[1] == 4 and (data["neg"][:, 3] < 0).all()
    back = SDFSampler.load(path)
    assert isinstance(back, SDFSamples) and back.points.shape == (200, 3)
    order = torch.cat([torch.nonzero(s.sdf >= 0), torch.nonzero(s.sdf < 0)]).squeeze(1)
    assert_close(back.points, s.points[order])
    assert_close(back.sdf, s.sdf[order])
    np.savez(tmp_path / "bad.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match="pos"):
        load_samples(tmp_path / "bad.npz")


def test_bad_input():
    with pytest.raises(TypeError, match="source"):
        SDFSampler(42)
    with pytest.raises(ValueError, match="variances"):
        SDFSampler(sphere, variances=(0.01, -1.0))
    with pytest.raises(ValueError, match="uniform_fraction"):
        SDFSampler(sphere, uniform_fraction=1.5)
    with pytest.raises(ValueError, match="clamp"):
        SDFSampler(sphere, clamp=0.0)
    with pytest.raises(ValueError, match="n"):
        SDFSampler(sphere).sample(0)
    with pytest.raises(ValueError, match="finite"):
        SDFSampler((torch.full((3, 3), math.nan), torch.tensor([[0, 1, 2]])))
    with pytest.raises(RuntimeError, match="balance"):
        SDFSampler(lambda p: p[:, 0] * 0 + 1.0, balanced=True, uniform_fraction=1.0).sample(10)
    with pytest.raises(RuntimeError, match="surface points"):
        SDFSampler(lambda p: sphere(p, 5.0), generator=_gen(0)).sample(10)


# --- polygon meshes, batches, DataLoader workers, progress ------------------------------

def _control_mesh():

    return sample_data.rabbit(dtype=torch.float64)


def test_quad_control_mesh_is_triangulated():
    from torchgeo_cg.mesh import triangulate_faces

    mesh = _control_mesh()
    assert mesh.faces.shape[1] == 4
    sampler = SDFSampler(mesh, generator=_gen(0))
    tris = triangulate_faces(mesh.faces)
    assert torch.equal(sampler.faces, tris)
    s = sampler.sample(500)
    assert_close(s.sdf, mesh_sdf(mesh.verts, tris, s.points).sdf)
    surface = sampler.surface_points(200)
    assert mesh_sdf(mesh.verts, tris, surface).sdf.abs().max() < 1e-12


def test_batched_surface_sampling_equals_the_loop():
    m = trimesh.creation.icosphere(subdivisions=1)
    verts = torch.tensor(m.vertices)
    quads_and_tris = torch.tensor(m.faces)
    batch = torch.stack([verts, 2 * verts + 1, verts * torch.tensor([1.0, 3.0, 0.5])])
    batch = batch.reshape(3, 1, -1, 3).expand(3, 2, -1, 3)  # batch dims (3, 2)
    got = sample_mesh_surface(batch, quads_and_tris, 64, torch.Generator().manual_seed(5))
    gen = torch.Generator().manual_seed(5)
    loop = torch.stack([sample_mesh_surface(v, quads_and_tris, 64, gen)
                        for v in batch.reshape(6, -1, 3)])
    assert got.shape == (3, 2, 64, 3)
    assert torch.equal(got.reshape(6, 64, 3), loop)


def test_surface_sampling_of_polygons_is_area_weighted():
    # a unit square (quad) and a triangle of area 2: points in ratio 1 : 2
    V = torch.tensor([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [2, 0, 1],
                      [0, 2, 1]])
    F = torch.tensor([[0, 1, 2, 3], [4, 5, 6, -1]])
    p = sample_mesh_surface(V, F, 3000, torch.Generator().manual_seed(1))
    k = int((p[:, 2] == 0).sum())
    assert stats.binomtest(k, 3000, 1 / 3).pvalue > 1e-3


def test_batched_sampler_matches_per_mesh_values():
    mesh = _control_mesh()
    batch = torch.stack([mesh.verts, 0.5 * mesh.verts + 0.1])
    s = SDFSampler((batch, mesh.faces), generator=_gen(3), balanced=True).sample(300)
    assert s.points.shape == (2, 300, 3) and s.sdf.shape == (2, 300)
    from torchgeo_cg.mesh import triangulate_faces

    tris = triangulate_faces(mesh.faces)
    for b in range(2):
        assert_close(s.sdf[b], mesh_sdf(batch[b], tris, s.points[b]).sdf)
        assert int((s.sdf[b] < 0).sum()) == 150


class _SamplerDataset(torch.utils.data.Dataset):
    def __init__(self, seed):
        self.sampler = SDFSampler(sphere, generator=_gen(seed), dtype=torch.float64)

    def __len__(self):
        return 4

    def __getitem__(self, i):
        info = torch.utils.data.get_worker_info()
        return info.id, self.sampler.sample(16).points


def _worker_streams(seed):
    loader = torch.utils.data.DataLoader(_SamplerDataset(seed), batch_size=None, num_workers=2,
                                         multiprocessing_context="fork")
    return list(loader)


def test_generator_is_used_and_advanced_and_checked():
    g = _gen(5)
    first = SDFSampler(sphere, generator=g).sample(20).points
    second = SDFSampler(sphere, generator=g).sample(20).points  # g moved on
    assert not torch.equal(first, second)
    assert torch.equal(first, SDFSampler(sphere, generator=_gen(5)).sample(20).points)
    with pytest.raises(TypeError, match="generator: expected a torch.Generator, got int"):
        SDFSampler(sphere, generator=0)


def test_dataloader_workers_get_independent_reproducible_streams():
    first = _worker_streams(seed=11)
    ids = [w for w, _ in first]
    assert sorted(set(ids)) == [0, 1]
    by_worker = {w: [p for i, p in first if i == w] for w in (0, 1)}
    assert not torch.equal(by_worker[0][0], by_worker[1][0])  # independent streams
    assert not torch.equal(by_worker[0][0], by_worker[0][1])  # a stream moves on
    again = _worker_streams(seed=11)
    assert all(torch.equal(a, b) for (_, a), (_, b) in zip(first, again))  # reproducible
    other = _worker_streams(seed=12)
    assert not torch.equal(first[0][1], other[0][1])


def test_nan_variance_and_progress(capsys):
    with pytest.raises(ValueError, match="variances"):
        SDFSampler(sphere, variances=(math.nan,))
    with pytest.raises(ValueError, match="variances"):
        SDFSampler(sphere, variances=(0.01, math.inf))
    SDFSampler(sphere, generator=_gen(0)).sample(100, progress=True)
    assert "SDFSampler" in capsys.readouterr().err
    SDFSampler(sphere, generator=_gen(0)).sample(100)
    assert "SDFSampler" not in capsys.readouterr().err


@pytest.mark.parametrize("backend", ["torch", "warp"])
def test_backend_is_passed_to_mesh_sdf(backend):
    from torchgeo_cg.sdf import available_engines

    if backend != "torch" and backend not in available_engines():
        pytest.skip(f"engine {backend!r} is not installed (extra 'fast')")
    m = trimesh.creation.icosphere(subdivisions=2)
    V, F = torch.tensor(m.vertices), torch.tensor(m.faces)
    s = SDFSampler(m, generator=_gen(3), backend=backend).sample(300)
    assert_close(s.sdf, mesh_sdf(V, F, s.points, backend="torch").sdf)
    with pytest.raises(ValueError, match="backend"):
        SDFSampler(m, generator=_gen(3), backend="no-such-engine")


# --- dtype policy and file validation -------------------------------------------------------


def test_save_samples_dtypes(tmp_path):
    points = torch.tensor([[0.0, 0, 0], [2, 0, 0]], dtype=torch.float64)
    sdf = torch.tensor([-1.0, 1.0], dtype=torch.float64)
    path = tmp_path / "s.npz"
    with pytest.raises(TypeError, match="sdf is torch.float32 on cpu but points"):
        save_samples(path, SDFSamples(points, sdf.float()))  # never silently promoted
    with pytest.raises(TypeError, match="sdf: expected a floating-point"):
        save_samples(path, SDFSamples(points, sdf.long()))
    # numpy has no bfloat16: stored as float32, restored on request (was a raw torch error)
    save_samples(path, SDFSamples(points.bfloat16(), sdf.bfloat16()))
    with np.load(path) as data:
        assert data["pos"].dtype == np.float32
        assert data["pos"].tolist() == [[2.0, 0, 0, 1.0]]
        assert data["neg"].tolist() == [[0.0, 0, 0, -1.0]]
    back = load_samples(path, dtype=torch.bfloat16)
    assert back.sdf.dtype == torch.bfloat16 and back.sdf.tolist() == [1.0, -1.0]


def test_load_samples_validates_each_array(tmp_path):
    good = np.zeros((2, 4))
    for pos, neg, error, match in ((np.zeros((2, 5)), good, ShapeError, r"pos: .*\(2, 5\)"),
                                   (good, np.zeros(4), ShapeError, r"neg: .*\(4,\)"),
                                   (good, np.zeros((2, 4), dtype=np.int64), TypeError,
                                    "neg: expected floating-point rows")):
        np.savez(tmp_path / "bad.npz", pos=pos, neg=neg)
        with pytest.raises(error, match=match):  # were a raw numpy error / int tensors
            load_samples(tmp_path / "bad.npz")
    np.savez(tmp_path / "mixed.npz", pos=good, neg=good.astype(np.float32))
    assert load_samples(tmp_path / "mixed.npz").points.dtype == torch.float64  # promoted


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16])
def test_sample_mesh_surface_low_precision_is_computed_in_float32(low):
    m = trimesh.creation.icosphere(subdivisions=1)
    v = torch.tensor(m.vertices).to(low)
    f = torch.tensor(m.faces)
    got = sample_mesh_surface(v, f, 50, torch.Generator().manual_seed(0))
    want = sample_mesh_surface(v.float(), f, 50, torch.Generator().manual_seed(0))
    assert got.dtype == low and torch.equal(got, want.to(low))


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16])
def test_function_source_low_precision_is_computed_in_float32(low):
    # the Newton projection ran in bfloat16 and never met its tolerance (RuntimeError)
    got = SDFSampler(lambda p: sphere(p, 0.5), generator=_gen(0), dtype=low).sample(40)
    want = SDFSampler(lambda p: sphere(p, 0.5), generator=_gen(0), dtype=torch.float32).sample(40)
    assert got.points.dtype == low and got.sdf.dtype == low
    assert torch.equal(got.points, want.points.to(low))
    assert torch.equal(got.sdf, sphere(got.points.float(), 0.5).to(low))
