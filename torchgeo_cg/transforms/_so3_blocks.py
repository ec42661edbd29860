"""Large CPU batches of rotation conversions, evaluated in blocks of rows.

A conversion is a few dozen elementwise steps. On a whole batch of a million
rotations every step streams a fresh 8 MB temporary through memory (strided, for
the columns of a matrix); on blocks of 16384 rows per thread the temporaries stay
in cache and the allocator reuses them, and each block is stacked straight into
its rows of the one output. The entries are the functions of :mod:`._so3` that the
whole-batch path stacks, with their rare branches (series near 0, the sign rule at
π) evaluated only on the rows that need them: the matrix and quaternion results
are the same bits as the whole-batch path, the rotation vectors of matrices agree
to rounding (they skip the quaternion's normalization, which cancels).

Blocks are used only where nothing records the computation: on CPU, with no
autograd through the input, outside ``torch.func`` transforms and compilation.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from torchgeo_cg.core.autograd import records_graph

BLOCK = 1 << 14


def blocks_apply(x: torch.Tensor) -> bool:
    """Whether ``x`` may take the block path (nothing needs a graph of the steps)."""
    return (x.device.type == "cpu" and not torch.compiler.is_compiling()
            and not records_graph(x))


def blockwise(entries: Callable, x: torch.Tensor, width: int) -> torch.Tensor:
    """``stack(entries(columns of x), -1)`` for ``x`` (*, k), block by block -> (*, width).

    ``entries`` maps the ``k`` columns of a block (1D views) to ``width`` 1D tensors.
    """
    rows = x.reshape(-1, x.shape[-1])
    out = torch.empty(rows.shape[0], width, dtype=x.dtype, device=x.device)
    size = BLOCK * max(1, torch.get_num_threads())  # each thread gets one block's worth
    for start in range(0, rows.shape[0], size):
        block = rows[start:start + size]
        torch.stack(entries(block.unbind(-1)), -1, out=out[start:start + size])
    return out.reshape(*x.shape[:-1], width)
