"""Shared numerics that never give birth to NaN or inf, forward or backward.

All helpers use the double-``where`` idiom: the unsafe input is replaced by a
safe value *before* the dangerous operation, so the branch that is thrown away
cannot poison the gradient. NaN inputs still give NaN outputs.
"""

from __future__ import annotations

import torch

__all__ = ["clamp_away_from_zero", "safe_div", "safe_sqrt", "safe_norm"]


def clamp_away_from_zero(x: torch.Tensor, eps: float = 1e-8) -> torch.Tensor:
    """Replace entries with ``|x| < eps`` by ``eps`` carrying the sign of ``x``.

    ``+0.0`` becomes ``+eps`` and ``-0.0`` becomes ``-eps``. Where an entry was
    replaced, its gradient is zero. NaN stays NaN.

    Example:
        >>> clamp_away_from_zero(torch.tensor([2.0, 0.0, -1e-12, float("nan")]))
        tensor([ 2.0000e+00,  1.0000e-08, -1.0000e-08,         nan])
    """
    return torch.where(x.abs() < eps, torch.full_like(x, eps).copysign(x), x)


def safe_div(num: torch.Tensor, den: torch.Tensor, eps: float = 1e-8) -> torch.Tensor:
    """``num / den`` with ``|den| < eps`` replaced by ``±eps`` (sign kept, ``+eps`` at 0).

    Args:
        num: numerator, any shape broadcastable with ``den``.
        den: denominator.
        eps: the smallest magnitude the denominator is allowed to have.

    Returns:
        The broadcast quotient. Finite whenever the inputs are finite; its gradient
        with respect to ``den`` is zero where ``den`` was clamped.

    Example:
        >>> safe_div(torch.tensor([1.0, 1.0, 1.0]), torch.tensor([2.0, 0.0, -1e-12]))
        tensor([ 5.0000e-01,  1.0000e+08, -1.0000e+08])
    """
    return num / clamp_away_from_zero(den, eps)


def safe_sqrt(x: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """``sqrt(max(x, 0))`` with a finite gradient (zero) where ``x <= eps``; NaN stays NaN.

    Example:
        >>> x = torch.tensor([4.0, 0.0, -1.0], requires_grad=True)
        >>> y = safe_sqrt(x)
        >>> y.sum().backward()
        >>> y.detach(), x.grad
        (tensor([2., 0., 0.]), tensor([0.2500, 0.0000, 0.0000]))
    """
    positive = x > eps
    x_safe = torch.where(positive, x, torch.ones_like(x))
    # (x * 0).abs() is 0 for finite x and NaN for NaN, so NaN in gives NaN out
    return torch.where(positive, x_safe.sqrt(), (x * 0).abs())


def safe_norm(
    x: torch.Tensor, dim: int = -1, keepdim: bool = False, eps: float = 1e-12
) -> torch.Tensor:
    """Euclidean norm along ``dim`` whose gradient at the zero vector is zero, not NaN.

    Example:
        >>> x = torch.tensor([[3.0, 4.0], [0.0, 0.0]], requires_grad=True)
        >>> n = safe_norm(x)
        >>> n.sum().backward()
        >>> n.detach(), x.grad
        (tensor([5., 0.]), tensor([[0.6000, 0.8000],
                [0.0000, 0.0000]]))
    """
    return safe_sqrt((x * x).sum(dim=dim, keepdim=keepdim), eps=eps * eps)
