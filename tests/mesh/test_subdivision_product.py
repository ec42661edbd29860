"""The stencil product's kernels: MKL's sparse matmul, embedding_bag, batch chunks, row blocks.

The reference is a brute-force float64 sum over the ``(row, col, weight)`` triplets,
written here with ``index_add_`` (independent of both kernels): duplicates summed, empty
rows zero. The shapes are picked to reach every path: embedding_bag (CPU float32, 8 or
more columns) in multi-item chunks with a short last chunk or a last chunk of one item,
one item per chunk for wide data, a single item; MKL for narrow data and float64; and
more rows than one embedding_bag block.
"""

from __future__ import annotations

import os
import re

import pytest
import torch

from torchgeo_cg.mesh.subdivision import apply_stencils, catmull_clark_operator
from torchgeo_cg.mesh.subdivision._stencil_build import StencilMatrix, index_dtype, stencil_matrix

R, C, NNZ = 40_000, 3_000, 200_000  # 40k rows: three blocks of embedding_bag rows


@pytest.fixture(scope="module")
def random_matrix():
    """Random entries on the even rows only (odd rows empty), with duplicates."""
    g = torch.Generator().manual_seed(0)
    rows = 2 * torch.randint(0, R // 2, (NNZ,), generator=g)
    cols = torch.randint(0, C, (NNZ,), generator=g)
    weights = torch.randn(NNZ, generator=g, dtype=torch.float64)
    return stencil_matrix(rows, cols, weights, (R, C)), (rows, cols, weights)


def _brute(triplets, x):
    rows, cols, weights = triplets
    x = x.double()
    out = torch.zeros(x.shape[0], R, x.shape[2], dtype=torch.float64)
    return out.index_add_(1, rows, weights[:, None] * x[:, cols])


def _bound(triplets, x, rel):
    """Elementwise float-rounding bound: ``rel`` times the sum of ``|w| |x|``."""
    rows, cols, weights = triplets
    return rel * _brute((rows, cols, weights.abs()), x.abs())


@pytest.mark.parametrize(("batch", "width", "dtype"), [
    (64, 3, torch.float32),   # embedding_bag, eight chunks of eight items
    (65, 3, torch.float32),   # ... and a last chunk of one item
    (50, 2, torch.float32),   # chunks of twelve, a last one of two
    (5, 3, torch.float32),    # one chunk of five
    (3, 30, torch.float32),   # wide: one item per chunk
    (1, 8, torch.float32),    # one item, embedding_bag
    (2, 3, torch.float32),    # six columns: MKL, one chunk of two
    (1, 3, torch.float32),    # MKL, in place
    (9, 3, torch.float64),    # MKL, chunks of four and a last one of one item
])
def test_product_matches_brute_force(random_matrix, batch, width, dtype):
    stencils, triplets = random_matrix
    g = torch.Generator().manual_seed(batch * 100 + width)
    x = torch.randn(batch, C, width, generator=g, dtype=dtype)
    got = apply_stencils(stencils, x)
    assert got.shape == (batch, R, width) and got.dtype == dtype and got.is_contiguous()
    rel = 1e-6 if dtype == torch.float32 else 1e-14
    assert bool(((got.double() - _brute(triplets, x)).abs() <= _bound(triplets, x, rel)).all())
    assert bool((got[:, 1::2] == 0).all())  # empty rows
    out = torch.full_like(got, float("nan"))
    apply_stencils(stencils, x, out=out)
    assert torch.equal(out, got)  # the same kernels run with out=


@pytest.mark.parametrize(("batch", "dtype"), [(64, torch.float32), (9, torch.float64),
                                              (1, torch.float32)])
def test_non_finite_values_stay_in_their_rows(random_matrix, batch, dtype):
    """A NaN (an inf) in one value reaches exactly the rows whose stencils use it, in that
    item and component only; nothing else becomes non-finite."""
    stencils, _ = random_matrix
    g = torch.Generator().manual_seed(5)
    x = torch.randn(batch, C, 3, generator=g, dtype=dtype)
    b_nan, b_inf = batch // 2, batch - 1
    x[b_nan, 17, 1] = float("nan")
    x[b_inf, 42, 2] = float("inf")
    got = apply_stencils(stencils, x)
    row_of = torch.repeat_interleave(torch.arange(R), stencils.crow.diff().long())
    nan_rows = torch.zeros(R, dtype=torch.bool)
    nan_rows[row_of[stencils.col == 17]] = True
    inf_rows = torch.zeros(R, dtype=torch.bool)
    inf_rows[row_of[stencils.col == 42]] = True
    expect_nan = torch.zeros_like(got, dtype=torch.bool)
    expect_nan[b_nan, :, 1] = nan_rows
    expect_inf = torch.zeros_like(got, dtype=torch.bool)
    expect_inf[b_inf, :, 2] = inf_rows & ~expect_nan[b_inf, :, 2]
    assert nan_rows.any() and inf_rows.any()
    assert torch.equal(torch.isnan(got), expect_nan)
    assert torch.equal(torch.isinf(got), expect_inf)


def test_indices_are_int32_where_they_fit_and_int64_indices_still_work(random_matrix):
    stencils, triplets = random_matrix
    assert all(p.dtype == torch.int32 for p in (stencils.crow, stencils.col, stencils.crow_t,
                                                  stencils.col_t))
    assert index_dtype(R, C, NNZ) == torch.int32
    assert index_dtype(3, 2**31, 6) == torch.int64 and index_dtype(2**31, 3, 6) == torch.int64
    assert index_dtype(3, 3, 2**31) == torch.int64
    wide = StencilMatrix(*(p if p.is_floating_point() else p.long() for p in stencils))
    for x in (torch.randn(64, C, 3), torch.randn(9, C, 3, dtype=torch.float64)):
        rel = 1e-6 if x.dtype == torch.float32 else 1e-14
        got = apply_stencils(wide, x)
        assert bool(((got.double() - _brute(triplets, x)).abs()
                     <= _bound(triplets, x, rel)).all())
    op = catmull_clark_operator([[0, 1, 2, 3]], 4)
    assert op.stencils.col.dtype == torch.int32


def test_large_fresh_output_is_ordinary_and_differentiable(random_matrix):
    """A large fresh output (here 15 MB) is an ordinary tensor: right values, a backward
    through the transpose, a resizable storage from torch's allocator."""
    stencils, triplets = random_matrix
    g = torch.Generator().manual_seed(2)
    x = torch.randn(32, C, 3, generator=g).requires_grad_(True)
    y = apply_stencils(stencils, x)
    assert y.nbytes >= 4 << 20
    assert bool(((y.detach().double() - _brute(triplets, x.detach())).abs()
                 <= _bound(triplets, x.detach(), 1e-6)).all())
    grad = torch.randn(y.shape, generator=g)
    y.backward(grad)
    rows, cols, weights = triplets
    expect = torch.zeros(32, C, 3, dtype=torch.float64).index_add_(
        1, cols, weights[:, None] * grad.double()[:, rows])
    bound = 1e-6 * torch.zeros(32, C, 3, dtype=torch.float64).index_add_(
        1, cols, weights.abs()[:, None] * grad.double().abs()[:, rows])
    assert bool(((x.grad.double() - expect).abs() <= bound).all())
    storage = y.detach().untyped_storage()
    storage.resize_(storage.nbytes() + 64)  # torch-owned, resizable


@pytest.mark.skipif(not os.path.exists("/sys/kernel/mm/transparent_hugepage/enabled"),
                    reason="no transparent huge pages on this system")
def test_large_fresh_output_is_marked_for_huge_pages(random_matrix):
    """The mapping holding a large fresh CPU output carries the huge-page hint (``hg``
    in ``/proc/self/smaps``)."""
    stencils, _ = random_matrix
    y = apply_stencils(stencils, torch.randn(32, C, 3))
    inside = y.data_ptr() + y.nbytes // 2
    flags = None
    with open("/proc/self/smaps") as smaps:
        current = False
        for line in smaps:
            span = re.match(r"^([0-9a-f]+)-([0-9a-f]+) ", line)
            if span:
                current = int(span[1], 16) <= inside < int(span[2], 16)
            elif current and line.startswith("VmFlags:"):
                flags = line.split()[1:]
                break
    assert flags is not None and "hg" in flags
