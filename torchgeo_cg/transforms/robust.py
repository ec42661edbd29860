"""Robust losses of squared residuals (M-estimators) and their IRLS weights.

:func:`robust_loss` is ``ρ(s)`` of a squared residual ``s = r²``, and
:func:`robust_weights` is ``ρ'(s)``, the weight of each residual in one
iteratively reweighted least-squares step. :func:`fit_transform` and the
point-cloud registration use them.

Convention:
    With scale ``c`` (Triggs et al. 2000, table of M-estimators): ``"l2"`` ``s``;
    ``"huber"`` ``s`` for ``s <= c²`` else ``2 c √s - c²``; ``"cauchy"``
    ``c² log(1 + s / c²)``; ``"tukey"`` ``c²/3 (1 - (1 - s/c²)³)``, constant
    ``c²/3`` beyond ``c``. Each is ``s`` near 0 and homogeneous,
    ``ρ(k² s; k c) = k² ρ(s; c)``, so the weights are scale-free:
    ``ρ'(k² s; k c) = ρ'(s; c)``.
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.core.check import check_broadcastable, check_choice, check_float, check_tensor

__all__ = ["LOSSES", "robust_loss", "robust_weights"]

#: Robust losses, as functions of the squared residual.
LOSSES: tuple[str, ...] = ("l2", "huber", "cauchy", "tukey")


def _check(squared_residuals: torch.Tensor, loss: str, scale) -> None:
    check_float(check_tensor(squared_residuals, "squared_residuals"), "squared_residuals")
    check_choice(loss, LOSSES, "loss")
    if isinstance(scale, torch.Tensor):
        check_float(scale, "scale")
        check_broadcastable({"squared_residuals": squared_residuals.shape, "scale": scale.shape})
    else:
        value = float(scale)
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"scale: expected a finite positive number, got {scale!r}")


def robust_loss(
    squared_residuals: torch.Tensor, loss: str, scale: float | torch.Tensor
) -> torch.Tensor:
    """``ρ(s)`` of squared residuals for the robust ``loss`` at ``scale``.

    Convention:
        See the module: ``s`` is a squared residual, ``scale`` the residual
        ``c`` (same units as ``√s``) where the loss starts to discount. A tensor
        ``scale`` must be positive (it is not checked, to avoid a sync).

    Args:
        squared_residuals: ``(*)`` non-negative squared residuals.
        loss: one of :data:`LOSSES`.
        scale: ``c > 0``, a float or a tensor broadcastable with ``squared_residuals``.

    Returns:
        ``(*)`` the loss, broadcast with ``scale``.

    Example:
        >>> s = torch.tensor([0.25, 4.0])
        >>> robust_loss(s, "huber", 1.0), robust_loss(s, "cauchy", 1.0)
        (tensor([0.2500, 3.0000]), tensor([0.2231, 1.6094]))
    """
    _check(squared_residuals, loss, scale)
    if loss == "l2":
        return squared_residuals
    c2 = scale * scale
    t = squared_residuals / c2
    if loss == "huber":
        inside = t <= 1
        t_safe = torch.where(inside, torch.ones_like(t), t)  # sqrt only where t > 1
        return torch.where(inside, squared_residuals, c2 * (2 * t_safe.sqrt() - 1))
    if loss == "cauchy":
        return c2 * torch.log1p(t)
    return c2 / 3 * (1 - (1 - t.clamp(max=1)).pow(3))


def robust_weights(
    squared_residuals: torch.Tensor, loss: str, scale: float | torch.Tensor
) -> torch.Tensor:
    """IRLS weights ``ρ'(s)`` of squared residuals for the robust ``loss`` at ``scale``.

    Minimizing ``Σ ρ(r_i²)`` by iteratively reweighted least squares solves, at
    each step, ``Σ w_i r_i²`` with ``w_i = ρ'(r_i²)`` from the current residuals.

    Convention:
        ``"l2"`` gives ones; ``"huber"`` ``min(1, c / |r|)``; ``"cauchy"``
        ``1 / (1 + r²/c²)``; ``"tukey"`` ``(1 - r²/c²)²`` inside ``c``, 0
        beyond. Scale-free: residuals and ``scale`` multiplied by ``k`` give
        the same weights. A tensor ``scale`` must be positive (unchecked).

    Args:
        squared_residuals: ``(*)`` non-negative squared residuals ``r²``.
        loss: one of :data:`LOSSES`.
        scale: ``c > 0``, a float or a tensor broadcastable with ``squared_residuals``.

    Returns:
        ``(*)`` weights in ``[0, 1]``, broadcast with ``scale``.

    Example:
        >>> s = torch.tensor([0.25, 4.0, 9.0])
        >>> robust_weights(s, "huber", 1.0)
        tensor([1.0000, 0.5000, 0.3333])
        >>> robust_weights(s, "tukey", 2.0)
        tensor([0.8789, 0.0000, 0.0000])
    """
    _check(squared_residuals, loss, scale)
    if loss == "l2":
        return torch.ones_like(squared_residuals)
    t = squared_residuals / (scale * scale)
    if loss == "huber":
        inside = t <= 1
        t_safe = torch.where(inside, torch.ones_like(t), t)
        return torch.where(inside, torch.ones_like(t), t_safe.rsqrt())
    if loss == "cauchy":
        return 1 / (1 + t)
    return (1 - t.clamp(max=1)).square()
