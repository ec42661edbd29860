"""Stencil tables: a sparse ``(R, C)`` matrix kept as plain CSR tensors, applied by one op.

OpenSubdiv's ``Far::StencilTable`` keeps sizes, indices and weights, a CSR matrix in
all but name. :class:`StencilMatrix` does the same with three dense tensors (row
offsets, column indices, weights) plus those of its transpose, so that the tensors can
be module buffers (``.to()``, ``copy.deepcopy``, ``state_dict``, DDP's broadcast all
handle dense tensors), and :func:`apply_stencils` multiplies them through one custom
operator ``torchgeo_cg::stencil_matmul``. That operator is opaque to ``torch.compile``
(``fullgraph=True`` works), has a ``vmap`` rule (a leading batch of data, the matrix
shared), and its backward is the same operator on the cached transpose, so
``jacrev``, double backward and ``vmap`` of gradients compose.

Convention:
    Rows are output items, columns input items: ``out[..., r, :] = sum_c S[r, c] x[..., c, :]``.
    ``crow`` is ``(R + 1,)`` int32 (int64 for sizes past int32), ``col`` and ``weights``
    are ``(nnz,)``, rows sorted, duplicate entries summed at build time. The weights are
    cast to the data's dtype and device on use; float16/bfloat16 data is multiplied in
    float32 (sparse matmuls have no half-precision kernels, and the sums would lose
    digits) and cast back.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import check_float, check_shape, check_tensor
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.mesh.subdivision._spmm import spmm_batched
from torchgeo_cg.mesh.subdivision._stencil_build import (
    StencilMatrix,
    check_out,
    plain_eager,
)

__all__ = ["StencilMatrix", "apply_stencils"]


def _stencil_matmul_eager(crow, col, weights, crow_t, x_bvd: Tensor,
                          out_brd: Tensor | None = None) -> Tensor:
    """``(R, C)`` stencils times ``(B, C, D)`` data -> ``(B, R, D)`` (weights in x's dtype),
    into ``out_brd`` when given."""
    if x_bvd.shape[1] == 0 or crow.numel() == 1 or x_bvd.shape[0] * x_bvd.shape[2] == 0:
        if out_brd is not None:
            return out_brd.zero_()
        return x_bvd.new_zeros(x_bvd.shape[0], crow.numel() - 1, x_bvd.shape[2])
    return spmm_batched(crow, col, weights, crow_t.numel() - 1, x_bvd.contiguous(), out_brd)


@torch.library.custom_op("torchgeo_cg::stencil_matmul", mutates_args=())
def _stencil_matmul(
    crow: Tensor,
    col: Tensor,
    weights: Tensor,
    crow_t: Tensor,
    col_t: Tensor,
    weights_t: Tensor,
    x_bvd: Tensor,
) -> Tensor:
    """The opaque op that ``torch.compile`` sees (sparse tensors never enter a graph)."""
    return _stencil_matmul_eager(crow, col, weights, crow_t, x_bvd)


@_stencil_matmul.register_fake
def _(crow, col, weights, crow_t, col_t, weights_t, x_bvd):
    return x_bvd.new_empty(x_bvd.shape[0], crow.shape[0] - 1, x_bvd.shape[2])


class _StencilApply(torch.autograd.Function):
    """``S @ X`` through the opaque op; backward applies ``S^T`` through this same
    Function, so gradients are differentiable and vmap-able. (No forward-mode ``jvp``:
    Dynamo cannot trace a Function that defines one.)"""

    @staticmethod
    def forward(crow, col, weights, crow_t, col_t, weights_t, x_bvd):
        if torch.compiler.is_compiling():  # opaque to Dynamo
            return _stencil_matmul(crow, col, weights, crow_t, col_t, weights_t, x_bvd)
        return _stencil_matmul_eager(crow, col, weights, crow_t, x_bvd)  # no dispatch cost

    @staticmethod
    def setup_context(ctx, inputs, output):
        ctx.save_for_backward(*inputs[:6])

    @staticmethod
    def backward(ctx, grad_brd):
        crow, col, weights, crow_t, col_t, weights_t = ctx.saved_tensors
        if not records_graph(grad_brd) and plain_eager():  # no double backward, no transform
            grad_x = _stencil_matmul_eager(crow_t, col_t, weights_t, crow, grad_brd)
        else:
            grad_x = _StencilApply.apply(crow_t, col_t, weights_t, crow, col, weights, grad_brd)
        return None, None, None, None, None, None, grad_x

    @staticmethod
    def vmap(info, in_dims, crow, col, weights, crow_t, col_t, weights_t, x_bvd):
        if any(d is not None for d in in_dims[:6]):
            raise ValueError("apply_stencils: vmap over the stencil matrix is not supported; "
                             "batch the data instead")
        x_nbvd = x_bvd.movedim(in_dims[6], 0)
        N, B, V, D = x_nbvd.shape
        out = _StencilApply.apply(crow, col, weights, crow_t, col_t, weights_t,
                                  x_nbvd.reshape(N * B, V, D))
        return out.reshape(N, B, -1, D), 0


class _StencilApplyEager(torch.autograd.Function):
    """The plain-eager twin of :class:`_StencilApply` (no ``setup_context``, so no
    per-call signature binding); used when no transform is active and nothing compiles.
    Its backward goes through :class:`_StencilApply`, so double backward still works."""

    @staticmethod
    def forward(ctx, crow, col, weights, crow_t, col_t, weights_t, x_bvd):
        ctx.save_for_backward(crow, col, weights, crow_t, col_t, weights_t)
        return _stencil_matmul_eager(crow, col, weights, crow_t, x_bvd)

    @staticmethod
    def backward(ctx, grad_brd):
        return _StencilApply.backward(ctx, grad_brd)


def apply_stencils(stencils: StencilMatrix, x: Tensor, *, out: Tensor | None = None) -> Tensor:
    """Multiply ``(*, C, D)`` data by the ``(R, C)`` stencils -> ``(*, R, D)``.

    Convention:
        Rows are items (vertices): ``x[..., c, :]`` is item ``c``. Differentiable in
        ``x`` (backward applies the transpose through the same op); works under
        ``torch.compile(fullgraph=True)``, ``torch.func.vmap`` and ``jacrev``. The
        weights are cast to ``x``'s dtype and device when they differ; float16 and
        bfloat16 ``x`` are computed in float32 and the result cast back. With ``out``,
        the result is written into that buffer and returned (no allocation when it is
        contiguous and not half precision); like torch's ``out=`` it is outside
        autograd: an error where grad mode is on and ``x`` or ``out`` requires grad,
        and in plain eager mode only. ``out`` must not overlap ``x``.

    Args:
        stencils: :class:`StencilMatrix` of shape ``(R, C)``.
        x: ``(*, C, D)`` float.
        out: optional ``(*, R, D)`` buffer of ``x``'s dtype and device.

    Returns:
        ``(*, R, D)``, same dtype and device as ``x`` (``out`` itself when given).

    Raises:
        ShapeError: ``x`` is not ``(*, C, D)`` with the stencils' ``C`` columns, or
            ``out`` is not ``(*, R, D)``.
        TypeError: ``x`` is not a floating tensor, or ``out`` has another dtype.
        ValueError: ``out`` on another device, needing autograd, or under a transform.

    Example:
        >>> from torchgeo_cg.mesh.subdivision._stencil_build import stencil_matrix
        >>> s = stencil_matrix(torch.tensor([0, 0]), torch.tensor([0, 1]),
        ...                    torch.tensor([0.5, 0.5]), (1, 2))
        >>> apply_stencils(s, torch.tensor([[0., 2.], [4., 6.]]))
        tensor([[2., 4.]])
        >>> buffer = torch.empty(1, 2)
        >>> apply_stencils(s, torch.tensor([[0., 2.], [4., 6.]]), out=buffer) is buffer
        True
    """
    check_tensor(x, "x")
    check_shape(x, ["*", "C", "D"], "x", {"C": stencils.shape[1]})
    check_float(x, "x")
    batch, (C, D) = x.shape[:-2], x.shape[-2:]
    if out is not None:
        check_out(out, (*batch, stencils.shape[0], D), x)
    dtype = working_dtype(x.dtype)
    parts = list(stencils)
    if parts[2].dtype != dtype or parts[2].device != x.device:
        parts = [p.to(x.device) for p in parts]
        parts[2], parts[5] = parts[2].to(dtype), parts[5].to(dtype)
    x_bcd = x.to(dtype).reshape(math.prod(batch), C, D)
    if out is not None:
        return _apply_into(parts, x_bcd, out)
    function = _StencilApplyEager if plain_eager() else _StencilApply
    y_brd = function.apply(*parts, x_bcd)
    return cast_back(y_brd.reshape(*batch, y_brd.shape[1], D), x.dtype)


def _apply_into(parts, x_bcd: Tensor, out: Tensor) -> Tensor:
    """The product written into ``out``: directly when it is contiguous in the working
    dtype, else through a temporary and one copy."""
    B, R, D = x_bcd.shape[0], parts[0].numel() - 1, x_bcd.shape[2]
    direct = out.dtype == x_bcd.dtype and out.is_contiguous()
    target = out.view(B, R, D) if direct else x_bcd.new_empty(B, R, D)
    _stencil_matmul_eager(parts[0], parts[1], parts[2], parts[3], x_bcd, target)
    if not direct:
        out.copy_(target.reshape(out.shape))
    return out
