"""farthest_point_sampling against a brute-force greedy loop written here."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchgeo_cg.core import ShapeError
from torchgeo_cg.points import farthest_point_sampling


def reference_fps(p, k, n=None, start=0):
    """Greedy over Python lists: the farthest unpicked point, ties to the smaller index."""
    n = p.shape[0] if n is None else n
    pts = p[:n].tolist()
    picks = []
    best = [float("inf")] * n
    cur = start
    for _ in range(min(k, n)):
        picks.append(cur)
        for j in range(n):
            d = sum((a - b) ** 2 for a, b in zip(pts[j], pts[cur]))
            best[j] = min(best[j], d)
        cand = [(best[j], -j) for j in range(n) if j not in picks]
        if not cand:
            break
        cur = -max(cand)[1]
    return picks + [-1] * (k - len(picks))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 40), k=st.integers(0, 45),
       d=st.integers(1, 4), grid=st.booleans())
def test_matches_brute_force(seed, n, k, d, grid):
    g = torch.Generator().manual_seed(seed)
    p = torch.randn(n, d, generator=g, dtype=torch.float64)
    if grid:  # many exact ties and coincident points
        p = torch.randint(0, 3, (n, d), generator=g).double()
    start = int(torch.randint(0, n, (1,), generator=g))
    res = farthest_point_sampling(p, k, start=start)
    want = reference_fps(p, k, start=start)
    assert res.indices.tolist() == want
    got_valid = res.indices[res.indices >= 0]
    assert got_valid.unique().numel() == got_valid.numel()  # no duplicates
    torch.testing.assert_close(res.points[: got_valid.numel()], p[got_valid])
    assert (res.points[got_valid.numel():] == 0).all()


def test_ragged_batch_equals_each_cloud():
    g = torch.Generator().manual_seed(3)
    p = torch.randn(3, 2, 30, 3, generator=g)
    lengths = torch.tensor([[30, 5], [0, 17], [1, 29]])
    res = farthest_point_sampling(p, 8, lengths=lengths, start=0)
    assert res.points.shape == (3, 2, 8, 3) and res.indices.shape == (3, 2, 8)
    for i in range(3):
        for j in range(2):
            want = reference_fps(p[i, j], 8, int(lengths[i, j]))
            assert res.indices[i, j].tolist() == want


def test_duplicates_are_taken_in_index_order():
    p = torch.tensor([[0.0, 0.0], [0.0, 0.0], [5.0, 0.0], [5.0, 0.0]])
    assert farthest_point_sampling(p, 4).indices.tolist() == [0, 2, 1, 3]


def test_gradient_flows_to_the_picked_points():
    p = torch.randn(2, 10, 3, dtype=torch.float64, requires_grad=True)
    res = farthest_point_sampling(p, 4)
    res.points.sum().backward()
    picked = torch.zeros(2, 10, dtype=torch.bool)
    picked.scatter_(1, res.indices, True)
    assert torch.equal(p.grad[..., 0] == 1, picked)


def test_scale_free():
    p = torch.randn(50, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    ref = farthest_point_sampling(p, 20).indices
    for s in (2.0**-70, 1e-6, 1e6, 3.0**40):
        assert torch.equal(farthest_point_sampling(p * s, 20).indices, ref)


def test_empty_and_bad_arguments():
    assert farthest_point_sampling(torch.zeros(2, 0, 3), 3).indices.tolist() == [[-1] * 3] * 2
    assert farthest_point_sampling(torch.zeros(4, 3), 0).points.shape == (0, 3)
    with pytest.raises(ShapeError, match="points"):
        farthest_point_sampling(torch.zeros(3), 2)
    with pytest.raises(TypeError, match="points"):
        farthest_point_sampling(torch.zeros(4, 3, dtype=torch.long), 2)
    with pytest.raises(ValueError, match="k"):
        farthest_point_sampling(torch.zeros(4, 3), -1)
    with pytest.raises(ValueError, match="start"):
        farthest_point_sampling(torch.zeros(2, 4, 3), 2, lengths=torch.tensor([4, 2]), start=2)
    with pytest.raises(ShapeError, match="lengths"):
        farthest_point_sampling(torch.zeros(2, 4, 3), 2, lengths=torch.tensor([4]))
