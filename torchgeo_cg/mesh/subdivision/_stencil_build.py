"""Building CSR stencil matrices, and the checks shared by everything that applies them
(the weights' and indices' dtypes, caller-given output buffers); the internals of
:mod:`torchgeo_cg.mesh.subdivision.stencils`, which re-exports :class:`StencilMatrix`."""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import ShapeError, check_tensor
from torchgeo_cg.mesh.subdivision._spmm import csr_tensor

__all__ = [
    "StencilMatrix", "check_out", "index_dtype", "plain_eager", "stencil_matrix", "weights_dtype",
]


class StencilMatrix(NamedTuple):
    """A sparse ``(R, C)`` matrix and its transpose as plain CSR tensors.

    Attributes:
        crow: ``(R + 1,)`` int32 row offsets (int64 where the sizes do not fit in
            int32, see :func:`index_dtype`; ``crow`` and ``col`` share a dtype, as do
            ``crow_t`` and ``col_t``).
        col: ``(nnz,)`` int32 (or int64) column of each entry.
        weights: ``(nnz,)`` float value of each entry.
        crow_t: ``(C + 1,)`` int32 (or int64) row offsets of the transpose.
        col_t: ``(nnz,)`` int32 (or int64) columns of the transpose (rows of the matrix).
        weights_t: ``(nnz,)`` float values of the transpose.

    Example:
        >>> s = stencil_matrix(torch.tensor([0, 0, 1]), torch.tensor([0, 1, 1]),
        ...                    torch.tensor([0.5, 0.5, 1.0]), (2, 2))
        >>> s.dense()
        tensor([[0.5000, 0.5000],
                [0.0000, 1.0000]])
    """

    crow: Tensor
    col: Tensor
    weights: Tensor
    crow_t: Tensor
    col_t: Tensor
    weights_t: Tensor

    @property
    def shape(self) -> tuple[int, int]:
        """``(R, C)``."""
        return self.crow.numel() - 1, self.crow_t.numel() - 1

    def sparse(self) -> Tensor:
        """The matrix as a ``torch.sparse_csr`` tensor (shares memory)."""
        return csr_tensor(self.crow, self.col, self.weights, self.shape[1])

    def sparse_t(self) -> Tensor:
        """The transpose as a ``torch.sparse_csr`` tensor (shares memory)."""
        return csr_tensor(self.crow_t, self.col_t, self.weights_t, self.shape[0])

    def dense(self) -> Tensor:
        """The ``(R, C)`` dense matrix."""
        return self.sparse().to_dense()


def weights_dtype(dtype: torch.dtype | None) -> torch.dtype:
    """The dtype of an operator's weights: ``dtype``, or the default dtype for ``None``.

    Raises:
        TypeError: ``dtype`` is not a floating-point dtype (an integer dtype would be
            promoted away silently).

    Example:
        >>> weights_dtype(None) == torch.get_default_dtype(), weights_dtype(torch.float64)
        (True, torch.float64)
    """
    if dtype is None:
        return torch.get_default_dtype()
    if not isinstance(dtype, torch.dtype) or not dtype.is_floating_point:
        raise TypeError(f"dtype: expected a floating-point torch.dtype, got {dtype!r}")
    return dtype


def index_dtype(*sizes: int) -> torch.dtype:
    """The index dtype of a CSR matrix with these sizes (rows, columns, entries): int32
    where every index and offset fits (MKL's faster sparse path, half the memory
    traffic), else int64.

    Example:
        >>> index_dtype(10, 10, 100), index_dtype(3, 2**31, 6)
        (torch.int32, torch.int64)
    """
    return torch.int32 if max(sizes) < 2**31 - 1 else torch.long


def stencil_matrix(
    rows: Tensor, cols: Tensor, weights: Tensor, shape: tuple[int, int]
) -> StencilMatrix:
    """Build a :class:`StencilMatrix` from ``(row, col, weight)`` triplets.

    Duplicate ``(row, col)`` entries are summed and zero weights dropped: one sort of
    the flattened keys ``row * C + col``, a scatter-add of the weights, and one stable
    sort of the columns for the transpose (no Python loop over entries).

    Args:
        rows: ``(N,)`` long in ``[0, R)``.
        cols: ``(N,)`` long in ``[0, C)``.
        weights: ``(N,)`` float.
        shape: ``(R, C)``.

    Returns:
        :class:`StencilMatrix` on the device of ``rows``, dtype of ``weights``, indices
        of :func:`index_dtype`.

    Example:
        >>> s = stencil_matrix(torch.tensor([1, 1]), torch.tensor([0, 0]),
        ...                    torch.tensor([0.25, 0.5]), (2, 1))
        >>> s.crow.tolist(), s.col.tolist(), s.weights.tolist()
        ([0, 0, 1], [0], [0.75])
    """
    n_rows, n_cols = shape
    rows, cols = rows.long(), cols.long()  # the keys row * C + col need 64 bits
    keep = weights != 0
    if not bool(keep.all()):
        rows, cols, weights = rows[keep], cols[keep], weights[keep]
    key_s, perm = torch.sort(rows * n_cols + cols)
    first = torch.ones_like(key_s, dtype=torch.bool)
    first[1:] = key_s[1:] != key_s[:-1]
    segment = torch.cumsum(first, 0) - 1  # index of the unique key of each sorted entry
    key_u = key_s[first]
    values_u = weights.new_zeros(key_u.numel()).index_add_(0, segment, weights[perm])
    rows_u, cols_u = key_u // max(n_cols, 1), key_u % max(n_cols, 1)
    crow = rows_u.new_zeros(n_rows + 1)
    crow[1:] = torch.cumsum(torch.bincount(rows_u, minlength=n_rows), 0)
    order_t = torch.sort(cols_u, stable=True).indices  # rows stay sorted within a column
    crow_t = cols_u.new_zeros(n_cols + 1)
    crow_t[1:] = torch.cumsum(torch.bincount(cols_u, minlength=n_cols), 0)
    index = index_dtype(n_rows, n_cols, key_u.numel())
    return StencilMatrix(crow.to(index), cols_u.to(index), values_u, crow_t.to(index),
                         rows_u[order_t].to(index), values_u[order_t])


def plain_eager() -> bool:
    return not (torch.compiler.is_compiling() or records_graph())  # no tensor: a transform


def check_out(out: Tensor, shape: tuple[int, ...], like: Tensor) -> None:
    """Validate a caller's output buffer ``out``: a tensor of ``shape`` with ``like``'s dtype
    and device, written outside autograd (like torch's ``out=``: an error where grad mode
    is on and ``like`` or ``out`` requires grad), in plain eager mode.

    Raises:
        ShapeError: ``out`` has another shape.
        TypeError: ``out`` is not a tensor, or of another dtype.
        ValueError: ``out`` on another device, autograd would be needed, or a
            ``torch.compile`` / ``torch.func`` transform is active.

    Example:
        >>> check_out(torch.empty(2, 3), (2, 3), torch.zeros(1))
    """
    check_tensor(out, "out")
    if tuple(out.shape) != tuple(shape):
        raise ShapeError(f"out: expected shape {tuple(shape)}, got {tuple(out.shape)}")
    if out.dtype != like.dtype:
        raise TypeError(f"out: expected dtype {like.dtype} (the input's), got {out.dtype}")
    if out.device != like.device:
        raise ValueError(f"out: expected device {like.device} (the input's), got {out.device}")
    if not plain_eager():
        raise ValueError("out: not supported under torch.compile or torch.func transforms; "
                         "call without out=")
    if records_graph(like, out):
        raise ValueError("out: writing into a buffer does not support autograd (an input or "
                         "out requires grad or carries a forward-mode tangent); call without "
                         "out=, or under torch.no_grad()")
