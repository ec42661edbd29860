"""launch_rows: a launch cut into row chunks, one per torch CPU thread, gives the result of
one launch; the kernels that use it agree with their torch paths at two threads."""

from __future__ import annotations

import math
import threading

import pytest
import torch

from torchgeo_cg.engine import kernels as engine_kernels
from torchgeo_cg.engine import launch_rows, register_kernels, to_warp, warp_status
from torchgeo_cg.points import knn, radius_search, remove_radius_outliers
from torchgeo_cg.rays import ray_mesh_intersect

needs_warp = pytest.mark.skipif(warp_status()[0] != "ok", reason="Warp is not available here")


def _build(wp):
    @wp.kernel
    def square_rows(rows: wp.array(dtype=wp.int64), x: wp.array(dtype=wp.float64),
                    y: wp.array(dtype=wp.float64)):
        i = int(rows[wp.tid()])
        y[i] = x[i] * x[i] + wp.float64(i)

    return square_rows


_kernels = register_kernels(_build)


class _Threads:
    """torch's thread count set for a block."""

    def __init__(self, n: int):
        self.n, self.previous = n, torch.get_num_threads()

    def __enter__(self):
        torch.set_num_threads(self.n)

    def __exit__(self, *exc):
        torch.set_num_threads(self.previous)


@needs_warp
@pytest.mark.parametrize("threads", [1, 2, 3])
def test_the_chunks_give_the_result_of_one_launch(threads, monkeypatch):
    n = 20000
    x = torch.randn(n, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    rows = torch.randperm(n, generator=torch.Generator().manual_seed(1))
    sizes = []
    real = engine_kernels.launch
    monkeypatch.setattr(engine_kernels, "launch",
                        lambda k, dim, args, dev: sizes.append(dim) or real(k, dim, args, dev))
    y = torch.full_like(x, math.nan)
    with _Threads(threads):
        launch_rows(_kernels(), rows, [None, to_warp(x), to_warp(y)], 0, x.device)
    assert torch.equal(y, x * x + torch.arange(n, dtype=torch.float64))
    assert len(sizes) == min(threads, n // 4096) and sum(sizes) == n


@needs_warp
def test_an_error_in_a_worker_thread_reaches_the_caller(monkeypatch):
    def failing(kernel, dim, args, device):
        if threading.current_thread() is not threading.main_thread():
            raise RuntimeError("chunk failed")

    monkeypatch.setattr(engine_kernels, "launch", failing)
    x = torch.zeros(10000, dtype=torch.float64)
    with _Threads(2), pytest.raises(RuntimeError, match="chunk failed"):
        launch_rows(_kernels(), torch.arange(10000), [None, to_warp(x), to_warp(x)], 0,
                    x.device)


@needs_warp
def test_the_split_kernels_agree_with_torch_at_two_threads():
    g = torch.Generator().manual_seed(2)
    q = torch.rand(12000, 3, generator=g)
    r = torch.rand(15000, 3, generator=g)
    with _Threads(2):
        for k in (1, 6):
            a, b = knn(q, r, k, backend="torch"), knn(q, r, k, backend="warp")
            assert torch.equal(a.idx, b.idx) and torch.equal(a.dists, b.dists)
        a, b = (radius_search(q, r, 0.03, backend=x) for x in ("torch", "warp"))
        assert torch.equal(a.idx, b.idx) and torch.equal(a.counts, b.counts)
        a, b = (remove_radius_outliers(r, 0.03, 3, backend=x) for x in ("torch", "warp"))
        assert torch.equal(a, b) and 0 < int(a.sum()) < r.shape[0]


@needs_warp
def test_ray_walk_agrees_with_torch_at_two_threads():
    verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=torch.float64)
    tet = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    g = torch.Generator().manual_seed(3)
    origins = torch.rand(40000, 3, generator=g, dtype=torch.float64) * 1.2 - 0.1
    origins[:, 2] = 2.0  # most rays enter the grid: more than two chunks of rows
    directions = torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64).expand(40000, 3)
    with _Threads(2):
        a, b = (ray_mesh_intersect(verts, tet, origins, directions, backend=x)
                for x in ("torch", "warp"))
    assert torch.equal(a.face, b.face) and torch.equal(a.t, b.t)
    assert 0 < int(a.hit.sum()) < 40000
