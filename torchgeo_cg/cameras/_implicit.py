"""Gradients of a solved equation by implicit differentiation.

A solver finds ``x`` with ``F(x, theta) = 0`` without autograd (bisection, Newton,
trust regions: none of it differentiable). At the solution, ``dx/dtheta =
-J^-1 dF/dtheta`` with ``J = dF/dx``. The backward pass therefore solves
``J^T lam = grad_x`` once and returns ``-lam^T dF/dtheta``: one residual evaluation,
no unrolled iterations. ``F`` acts point by point (row ``i`` of ``x`` only meets row
``i`` of the residual), so ``J`` is a batch of ``D x D`` blocks, ``D`` in ``{1, 2}``.
"""

from __future__ import annotations

from collections.abc import Callable

import torch


def _solve_transposed(jac: torch.Tensor, grad: torch.Tensor) -> torch.Tensor:
    """``J^-T grad`` per point for ``jac (*, D, D)``, ``grad (*, D)``; 0 where ``J`` is singular."""
    if jac.shape[-1] == 1:
        den = jac[..., 0, 0]
        ok = den != 0
        return torch.where(ok, grad[..., 0] / torch.where(ok, den, 1.0), 0.0)[..., None]
    a, b, c, d = jac[..., 0, 0], jac[..., 0, 1], jac[..., 1, 0], jac[..., 1, 1]
    det = a * d - b * c
    ok = det != 0
    inv_det = torch.where(ok, 1.0 / torch.where(ok, det, 1.0), 0.0)
    g0, g1 = grad[..., 0], grad[..., 1]
    # (J^T)^-1 = [[d, -c], [-b, a]] / det
    return torch.stack([(d * g0 - c * g1) * inv_det, (a * g1 - b * g0) * inv_det], -1)


class _Implicit(torch.autograd.Function):
    """``solution`` as a function of ``inputs`` through ``residual(x, *inputs) = 0``."""

    @staticmethod
    def forward(ctx, residual, usable, solution, *inputs):
        ctx.residual = residual
        ctx.save_for_backward(usable, solution, *inputs)
        return solution.clone()

    @staticmethod
    def backward(ctx, grad):
        usable, solution, *inputs = ctx.saved_tensors
        wants = ctx.needs_input_grad[3:]
        with torch.enable_grad():
            x = solution.detach().requires_grad_(True)
            leaves = [t.detach().requires_grad_(w) for t, w in zip(inputs, wants)]
            res = ctx.residual(x, *leaves)  # (*, D)
            rows = [torch.autograd.grad(res[..., i].sum(), x, retain_graph=True)[0]
                    for i in range(res.shape[-1])]
            jac = torch.stack(rows, -2)  # (*, D, D): jac[..., i, j] = dF_i / dx_j
            lam = _solve_transposed(jac, grad.to(jac.dtype))
            lam = torch.where(usable[..., None], lam, 0.0)
            chosen = [t for t in leaves if t.requires_grad]
            grads = torch.autograd.grad(res, chosen, grad_outputs=-lam, allow_unused=True) \
                if chosen else ()
        it = iter(grads)
        out = [next(it) if w else None for w in wants]
        out = [None if g is None else g for g in out]
        return (None, None, None, *out)


def implicit_solution(residual: Callable, usable: torch.Tensor, solution: torch.Tensor,
                      *inputs: torch.Tensor) -> torch.Tensor:
    """``solution`` (detached, ``(*, D)``) with the implicit gradient in ``inputs``.

    ``usable (*)`` marks the points whose gradient is taken (elsewhere it is 0: no
    preimage, or a singular Jacobian).
    """
    if not any(t.requires_grad for t in inputs if isinstance(t, torch.Tensor)):
        return solution
    return _Implicit.apply(residual, usable, solution.detach(), *inputs)
