"""knn against a brute force written here and scipy's cKDTree: ties, ragged, k > M, D = 2, 3."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import cKDTree

import torchgeo_cg.points._search as search_module
import torchgeo_cg.points.nearest_neighbors as knn_module
from torchgeo_cg.core import ShapeError
from torchgeo_cg.engine import warp_status
from torchgeo_cg.points import knn


def reference_knn(q, r, k, ql=None, rl=None):
    """Brute force: every distance, stable sort (ties -> smaller index), padding -1/0."""
    B, N, _ = q.shape
    M = r.shape[1]
    ql = torch.full((B,), N) if ql is None else ql
    rl = torch.full((B,), M) if rl is None else rl
    dists = torch.zeros(B, N, k, dtype=q.dtype)
    idx = torch.full((B, N, k), -1)
    for b in range(B):
        for i in range(int(ql[b])):
            d2 = ((q[b, i] - r[b, : int(rl[b])]) ** 2).sum(-1)
            order = torch.sort(d2, stable=True).indices[:k]
            idx[b, i, : order.numel()] = order
            dists[b, i, : order.numel()] = d2[order]
    return dists, idx


HAS_WARP = warp_status()[0] == "ok"


def use_backend(monkeypatch, backend: str) -> None:
    """Make every ``knn(backend="auto")`` of a test run ``backend``."""
    monkeypatch.setattr(knn_module, "resolve_backend", lambda name, device=None: backend)


@pytest.fixture(params=["grid", "brute", "warp"])
def path(request, monkeypatch):
    """Run each test through the torch grid search, the torch brute-force search and the
    Warp kernel."""
    if request.param == "warp" and not HAS_WARP:
        pytest.skip("Warp is not available here")
    use_backend(monkeypatch, "warp" if request.param == "warp" else "torch")
    monkeypatch.setattr(search_module, "BRUTE_FORCE_PAIRS",
                        0 if request.param == "grid" else 1 << 62)
    return request.param


@pytest.mark.parametrize("D", [2, 3])
@pytest.mark.parametrize("k", [1, 3])
def test_matches_brute_force_ragged(path, D, k):
    gen = torch.Generator().manual_seed(D * 10 + k)
    q = torch.randn(3, 40, D, generator=gen, dtype=torch.float64)
    r = torch.randn(3, 50, D, generator=gen, dtype=torch.float64) * 0.7
    ql, rl = torch.tensor([40, 17, 0]), torch.tensor([50, 2, 30])
    res = knn(q, r, k, ql, rl)
    d_ref, i_ref = reference_knn(q, r, k, ql, rl)
    assert torch.equal(res.idx, i_ref)
    torch.testing.assert_close(res.dists, d_ref, rtol=0, atol=0)


@pytest.mark.parametrize("D", [2, 3])
def test_equals_ckdtree(path, D):
    rng = np.random.default_rng(D)
    ref = rng.random((700, D)) ** 3  # clustered towards the origin
    qry = rng.normal(size=(300, D)) * 2  # many queries outside the reference box
    d_sc, i_sc = cKDTree(ref).query(qry, k=4)
    res = knn(torch.from_numpy(qry), torch.from_numpy(ref), k=4)
    np.testing.assert_allclose(res.dists.numpy(), d_sc**2, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(res.idx.numpy(), i_sc)  # no ties in random data


def test_ties_go_to_the_smaller_index(path):
    # integer lattice: many equidistant neighbours; duplicated reference points too
    axis = torch.arange(6, dtype=torch.float64)
    r = torch.cartesian_prod(axis, axis)
    r = torch.cat([r, r[:10]])  # rows 36..45 duplicate rows 0..9
    q = torch.cartesian_prod(axis, axis)[:, [1, 0]] + 0.5
    res = knn(q, r, k=5)
    d_ref, i_ref = reference_knn(q[None], r[None], 5)
    assert torch.equal(res.idx, i_ref[0])
    torch.testing.assert_close(res.dists, d_ref[0], rtol=0, atol=0)


def test_k_larger_than_m_is_padded(path):
    q = torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    r = torch.tensor([[0.0, 0.0, 1.0], [2.0, 0.0, 0.0]])
    res = knn(q, r, k=4)
    assert res.idx.tolist() == [[0, 1, -1, -1], [0, 1, -1, -1]]
    assert res.dists.tolist() == [[1.0, 4.0, 0.0, 0.0], [2.0, 3.0, 0.0, 0.0]]


@pytest.mark.parametrize("backend", ["torch", "warp"])
def test_grid_handles_surfaces_lines_and_far_queries(monkeypatch, backend):
    if backend == "warp" and not HAS_WARP:
        pytest.skip("Warp is not available here")
    use_backend(monkeypatch, backend)
    monkeypatch.setattr(search_module, "BRUTE_FORCE_PAIRS", 0)
    gen = torch.Generator().manual_seed(3)
    sphere = torch.nn.functional.normalize(torch.randn(2000, 3, generator=gen, dtype=torch.float64),
                                           dim=-1)
    line = torch.zeros(2000, 3, dtype=torch.float64)
    line[:, 0] = torch.rand(2000, generator=gen, dtype=torch.float64)
    same = torch.ones(2000, 3, dtype=torch.float64)  # all reference points coincide
    q = torch.cat([torch.randn(300, 3, generator=gen, dtype=torch.float64),
                   torch.randn(20, 3, generator=gen, dtype=torch.float64) * 1e4])
    for r in (sphere, line, same):
        res = knn(q, r, k=2)
        d_ref, i_ref = reference_knn(q[None], r[None], 2)
        assert torch.equal(res.idx, i_ref[0])


@given(st.integers(0, 10_000), st.sampled_from([1e-6, 1.0, 1e6]))
def test_scale_invariance(seed, scale):
    gen = torch.Generator().manual_seed(seed)
    q = torch.randn(30, 3, generator=gen, dtype=torch.float64)
    r = torch.randn(25, 3, generator=gen, dtype=torch.float64)
    base = knn(q, r, k=2, backend="torch")
    for pairs, backend in ((0, "torch"), (1 << 62, "torch"), (0, "auto")):
        search_module.BRUTE_FORCE_PAIRS = pairs
        try:
            scaled = knn(q * scale, r * scale, k=2, backend=backend)
        finally:
            search_module.BRUTE_FORCE_PAIRS = 1 << 18
        assert torch.equal(scaled.idx, base.idx)
        torch.testing.assert_close(scaled.dists, base.dists * scale**2, rtol=1e-12, atol=0)


def test_float32_and_batch_broadcast(path):
    gen = torch.Generator().manual_seed(5)
    q = torch.randn(2, 3, 30, 3, generator=gen)
    r = torch.randn(3, 40, 3, generator=gen)  # broadcast over the leading 2
    res = knn(q, r, k=2)
    assert res.dists.shape == (2, 3, 30, 2) and res.dists.dtype == torch.float32
    d_ref, i_ref = reference_knn(q.reshape(6, 30, 3).double(), r.expand(2, 3, 40, 3)
                                 .reshape(6, 40, 3).double(), 2)
    assert torch.equal(res.idx.reshape(6, 30, 2), i_ref)


@pytest.mark.grad
def test_gradcheck_both_point_sets(path):
    gen = torch.Generator().manual_seed(7)
    q = torch.randn(2, 12, 3, generator=gen, dtype=torch.float64, requires_grad=True)
    r = torch.randn(2, 15, 3, generator=gen, dtype=torch.float64, requires_grad=True)
    ql, rl = torch.tensor([12, 7]), torch.tensor([15, 2])
    assert torch.autograd.gradcheck(lambda a, b: knn(a, b, 3, ql, rl).dists, (q, r))


def test_nan_in_nan_out_and_empty():
    q = torch.tensor([[0.0, 0.0], [float("nan"), 0.0]])
    r = torch.tensor([[1.0, 0.0], [2.0, 0.0]])
    res = knn(q, r)
    assert res.idx.tolist() == [[0], [-1]] and torch.isnan(res.dists[1]).all()
    assert not torch.isnan(res.dists[0]).any()
    bad_ref = knn(q[:1], torch.tensor([[float("nan"), 0.0], [2.0, 0.0]]))
    assert torch.isnan(bad_ref.dists).all()
    # a NaN in a padded reference row is ignored
    ok = knn(q[None, :1], torch.tensor([[[2.0, 0.0], [float("nan"), 0.0]]]),
             reference_lengths=torch.tensor([1]))
    assert ok.dists.tolist() == [[[4.0]]]
    assert knn(torch.zeros(0, 3), torch.zeros(5, 3), k=2).dists.shape == (0, 2)
    empty_ref = knn(torch.zeros(4, 3), torch.zeros(0, 3), k=2)
    assert (empty_ref.idx == -1).all() and (empty_ref.dists == 0).all()


def test_errors_name_the_argument():
    with pytest.raises(ShapeError, match="reference"):
        knn(torch.zeros(4, 3), torch.zeros(5, 2))
    with pytest.raises(TypeError, match="query"):
        knn(torch.zeros(4, 3, dtype=torch.long), torch.zeros(5, 3))
    with pytest.raises(ValueError, match="k: expected a positive int"):
        knn(torch.zeros(4, 3), torch.zeros(5, 3), k=0)
    with pytest.raises(ValueError, match="reference_lengths"):
        knn(torch.zeros(2, 4, 3), torch.zeros(2, 5, 3), reference_lengths=torch.tensor([6, 1]))
    with pytest.raises(ShapeError, match="query_lengths"):
        knn(torch.zeros(2, 4, 3), torch.zeros(2, 5, 3), query_lengths=torch.tensor([1]))


@pytest.mark.parametrize("dtype, scale", [(torch.float64, 1e-170), (torch.float64, 1e160),
                                          (torch.float32, 1e-25), (torch.float32, 1e20)])
def test_neighbours_at_extreme_scales(path, dtype, scale):
    # before the search ran on power-of-two scaled coordinates, every squared distance
    # underflowed to 0 (all ties: index 0) or overflowed to inf (idx -1, dists 0)
    gen = torch.Generator().manual_seed(11)
    q = torch.randn(2, 20, 3, generator=gen, dtype=torch.float64)
    r = torch.randn(2, 25, 3, generator=gen, dtype=torch.float64)
    _, i_ref = reference_knn(q.to(dtype).double(), r.to(dtype).double(), 3)
    res = knn((q * scale).to(dtype), (r * scale).to(dtype), k=3)
    assert torch.equal(res.idx, i_ref)


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16])
def test_low_precision_is_searched_in_float32_and_saturates(low):
    q = torch.tensor([[0.0, 0.0], [1.0, 0.5]]).to(low)
    r = torch.tensor([[300.0, 0.0], [1.0, 0.25]]).to(low)
    res = knn(q, r, k=2)
    ref = knn(q.float(), r.float(), k=2)
    assert res.dists.dtype == low and torch.equal(res.idx, ref.idx)
    # 300^2 is beyond float16: the largest finite value, not inf (computed in float32)
    assert torch.equal(res.dists, ref.dists.clamp_max(torch.finfo(low).max).to(low))
    assert torch.isfinite(res.dists).all()
