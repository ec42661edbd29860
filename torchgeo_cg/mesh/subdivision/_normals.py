"""Scale-free unit normals from two tangents, and the power-of-two scaling they rely on."""

from __future__ import annotations

import torch

from torchgeo_cg.core.numerics import power_of_two_scale, safe_norm


def power_of_two_scaled(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(x / scale, scale)`` with ``scale`` the power of two of each item's largest
    magnitude (exact division, :func:`~torchgeo_cg.core.numerics.power_of_two_scale`).
    Tangent masks are differences (rows sum to 0), so ``4 a - 4 b`` of points near the
    largest float would overflow although the tangent is finite; on the scaled data it
    cannot. Empty, zero and non-finite items keep ``scale = 1``."""
    if x.shape[-2] * x.shape[-1] == 0:
        return x, x.new_ones(())
    scale = power_of_two_scale(x.detach().abs().amax(dim=(-2, -1), keepdim=True))
    return x / scale, scale


def unit_normals(tu: torch.Tensor, tv: torch.Tensor) -> torch.Tensor:
    """``normalize(tu x tv)`` at every scale: each tangent is divided by its largest
    component first (the normal does not change), so the cross product neither
    overflows (|t| ~ 1e20 in float32) nor underflows to a zero normal (|t| ~ 1e-25).
    Zero tangents give a zero normal; NaN passes through."""
    def unit_max(t):
        big = t.detach().abs().amax(dim=-1, keepdim=True)
        return t / torch.where(big > 0, big, torch.ones_like(big))

    n = torch.linalg.cross(unit_max(tu), unit_max(tv), dim=-1)
    length = safe_norm(n, keepdim=True)
    return n / torch.where(length > 0, length, torch.ones_like(length))
