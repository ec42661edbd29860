"""The product behind ``apply_stencils``: an ``(R, C)`` CSR matrix times a batch ``(B, C, D)``.

Two kernels compute ``y = S @ x`` for one dense ``(C, N)`` ``x``:

- ``torch.mm`` on a ``torch.sparse_csr`` tensor (MKL on CPU, cuSPARSE on CUDA): the
  fastest for narrow ``x`` (``N < 8``), in float64 and off the CPU. MKL runs its LP64
  path on int32 indices (int64 ones are 1.5-2x slower at these sizes).
- ``torch.nn.functional.embedding_bag`` in ``"sum"`` mode with the weights as
  per-sample weights (the row offsets are its bag offsets, the columns its indices, one
  bag per output row): on CPU float32 this is FBGEMM's generated kernel, whose cost
  barely grows with ``N`` up to a few dozen columns (the icosphere(5) Catmull-Clark
  operator at 1 thread: 0.34 ms for 12 or 24 columns, MKL 0.53 and 0.98 ms).

A batch is cut into chunks of ``n`` items laid out d-major, ``x2[c, d * n + i] =
x[b0 + i, c, d]``: then ``y2.view(R * D, n)[:, i]`` is item ``i``'s whole output,
flattened, so the items go in and come out with one strided copy each whose inner loop
runs over all ``C * D`` (``R * D``) entries. The item-major layout ``x2[c, i * D + d]``
copies rows of ``D`` values at a time, which for ``D = 3`` costs 2-3x more than the
product itself.

Convention:
    ``crow`` ``(R + 1,)``, ``col`` ``(nnz,)`` (one integer dtype), ``weights`` ``(nnz,)``
    in ``x``'s dtype and on its device; ``x`` is ``(B, C, D)``, the result ``(B, R, D)``
    contiguous. Rows are output items: ``y[b, r] = sum_k weights[k] x[b, col[k]]`` over
    ``crow[r] <= k < crow[r + 1]``.
"""

from __future__ import annotations

import ctypes
import functools
import mmap
import sys
import warnings

import torch
import torch.nn.functional as F
from torch import Tensor

_MKL_COLUMNS = 12  # dense columns per MKL product: the gathered rows stay in cache
_GATHER_COLUMNS = 24  # per embedding_bag product: near its flat cost, chunks stay in L2
_GATHER_MIN_COLUMNS = 8  # below this MKL is as fast or faster
_GATHER_ROWS = 16384  # output rows per embedding_bag product
_HUGE_PAGE_MIN_BYTES = 4 << 20  # outputs marked for huge pages (numpy's threshold)

_CSR_WARNING_SEEN = False


def csr_tensor(crow: Tensor, col: Tensor, weights: Tensor, num_cols: int) -> Tensor:
    """The ``(R, num_cols)`` ``torch.sparse_csr`` tensor of the three CSR tensors (shares
    their memory; torch's one "sparse CSR is in beta" warning is silenced).

    Example:
        >>> csr_tensor(torch.tensor([0, 1]), torch.tensor([1]), torch.tensor([2.]), 2).to_dense()
        tensor([[0., 2.]])
    """
    global _CSR_WARNING_SEEN
    shape = (crow.numel() - 1, num_cols)
    if _CSR_WARNING_SEEN:  # torch warns once per process: no filter needed afterwards
        return torch.sparse_csr_tensor(crow, col, weights, shape, check_invariants=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        matrix = torch.sparse_csr_tensor(crow, col, weights, shape, check_invariants=False)
    _CSR_WARNING_SEEN = True
    return matrix


def new_output(shape: tuple[int, ...], like: Tensor) -> Tensor:
    """An uninitialised tensor of ``shape`` with ``like``'s dtype and device, for an output
    that is written once, in full.

    A large CPU output (4 MiB and more) is marked for transparent huge pages
    (``madvise(MADV_HUGEPAGE)`` on the whole pages inside it, before anything touches
    it; numpy does the same for its large arrays). Such an output's first touch is
    mostly page faults: a fresh 45 MB output of 4 KiB pages takes ~11,500 of them, at
    2-3 us each more than the product itself, against ~300 with 2 MiB pages. Only this
    buffer is concerned (no process-wide allocator option); the system's
    ``transparent_hugepage`` setting decides whether the hint is taken, and the tensor
    is an ordinary one from torch's allocator, freed with its last reference.

    Example:
        >>> new_output((2, 3), torch.zeros(1, dtype=torch.float64)).dtype
        torch.float64
    """
    out = like.new_empty(shape)
    if like.device.type == "cpu" and out.nbytes >= _HUGE_PAGE_MIN_BYTES:
        madvise = _madvise()
        if madvise is not None:
            page = mmap.PAGESIZE
            start = -(-out.data_ptr() // page) * page  # whole pages of this buffer only
            stop = (out.data_ptr() + out.nbytes) // page * page
            madvise(start, stop - start, mmap.MADV_HUGEPAGE)  # a hint: a refusal is harmless
    return out


@functools.cache
def _madvise():
    """libc's ``madvise``, or ``None`` where there is none to call (not Linux)."""
    if not sys.platform.startswith("linux") or not hasattr(mmap, "MADV_HUGEPAGE"):
        return None
    try:
        function = ctypes.CDLL(None, use_errno=True).madvise
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    function.restype = ctypes.c_int
    return function


def spmm_batched(crow: Tensor, col: Tensor, weights: Tensor, num_cols: int, x_bcd: Tensor,
                 out_brd: Tensor | None = None) -> Tensor:
    """``(R, C)`` CSR times each ``(C, D)`` item of ``(B, C, D)`` -> contiguous ``(B, R, D)``,
    written into ``out_brd`` when given (contiguous, ``x``'s dtype and device).

    Items are grouped so that each product sees about ``_MKL_COLUMNS`` (MKL) or
    ``_GATHER_COLUMNS`` (embedding_bag) dense columns: a loop over batch chunks, not
    elements. One very wide product thrashes the cache, many narrow ones waste the
    stencil reads.

    Example:
        >>> crow, col, w = torch.tensor([0, 2]), torch.tensor([0, 1]), torch.tensor([.5, .5])
        >>> spmm_batched(crow, col, w, 2, torch.tensor([[[0.], [2.]], [[4.], [6.]]]))
        tensor([[[1.]],
        <BLANKLINE>
                [[5.]]])
    """
    B, C, D = x_bcd.shape
    R = crow.numel() - 1
    if out_brd is None:
        out_brd = new_output((B, R, D), x_bcd)
    gather = (x_bcd.device.type == "cpu" and x_bcd.dtype == torch.float32
              and min(B * D, _GATHER_COLUMNS) >= _GATHER_MIN_COLUMNS)
    if gather:
        blocks = _row_blocks(crow, col, weights)
        per = max(1, _GATHER_COLUMNS // D)

        def product(block, x2d: Tensor, into: Tensor | None) -> Tensor:
            offsets, block_col, block_weights = block
            return F.embedding_bag(block_col, x2d, offsets, mode="sum",
                                   per_sample_weights=block_weights, include_last_offset=True)
    else:
        blocks = [(0, R, csr_tensor(crow, col, weights, num_cols))]
        per = max(1, _MKL_COLUMNS // max(D, 1))

        def product(matrix, x2d: Tensor, into: Tensor | None) -> Tensor:
            return torch.mm(matrix, x2d, out=into)
    return _chunked(blocks, product, x_bcd, out_brd, min(per, B), writes_into=not gather)


def _row_blocks(crow: Tensor, col: Tensor, weights: Tensor) -> list:
    """``(r0, r1, (offsets, col, weights))`` of each block of ``_GATHER_ROWS`` rows, the
    offsets from 0 (embedding_bag's bag offsets). Blocks keep each product's fresh output
    small: it is reused from the heap instead of mapped (and faulted in) again, and it is
    still in cache when copied out."""
    R = crow.numel() - 1
    starts = [*range(0, R, _GATHER_ROWS), R]
    at = crow[starts].tolist()
    return [(r0, r1, (crow[r0:r1 + 1] - a0, col[a0:a1], weights[a0:a1]))
            for r0, r1, a0, a1 in zip(starts[:-1], starts[1:], at[:-1], at[1:])]  # blocks


def _chunked(blocks, product, x_bcd: Tensor, out_brd: Tensor, per: int,
             writes_into: bool) -> Tensor:
    """The batch in chunks of ``per`` items, d-major (see the module docstring), each
    chunk's product in blocks of rows. A product that ``writes_into`` (MKL) writes into
    one reused scratch, or a one-item chunk (the item itself) straight into ``out_brd``;
    embedding_bag makes its own output. The copies go through a trailing unit
    dimension: a 2-D transposed copy takes torch's blocked-transpose path, several
    times slower for so few columns."""
    B, C, D = x_bcd.shape
    R = out_brd.shape[1]
    x_scratch = x_bcd.new_empty(C * D * per) if per > 1 else None
    y_scratch = x_bcd.new_empty(R * D * per) if per > 1 and writes_into else None
    for b0 in range(0, B, per):  # a loop over batch chunks
        n = min(per, B - b0)
        if n == 1:
            x2 = x_bcd[b0]
        else:
            x2 = x_scratch[:C * D * n].view(C * D, n)
            x2.unsqueeze(-1).copy_(x_bcd[b0:b0 + n].reshape(n, C * D).T.unsqueeze(-1))
        for r0, r1, block in blocks:  # a loop over blocks of rows
            rows = r1 - r0
            into = (out_brd[b0, r0:r1] if n == 1 else
                    None if y_scratch is None else y_scratch[:rows * D * n].view(rows, D * n))
            y = product(block, x2.view(C, D * n), into)
            if not (n == 1 and y is into):  # not written in place
                target = out_brd[b0:b0 + n, r0:r1].view(n, rows * D)
                target.unsqueeze(-1).copy_(y.view(rows * D, n).T.unsqueeze(-1))
            del y  # freed before the next block's is allocated: the heap reuses it
    return out_brd
