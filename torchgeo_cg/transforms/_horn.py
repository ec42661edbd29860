"""Horn's quaternion form of orthogonal Procrustes, with a gradient that survives symmetry.

The rotation ``R`` maximizing ``tr(R S)`` for a 3x3 correlation ``S = Σ w p qᵀ``
(``q ≈ R p``) is the quaternion of the largest eigenvalue of Horn's symmetric
4x4 matrix ``K(S)`` (Horn 1987), and ``max tr(R S) = λ_max``. The best improper
orthogonal matrix is ``-R'`` with ``R'`` the quaternion of ``K``'s smallest
eigenvalue (``K(-S) = -K(S)``), worth ``-λ_min``.

Unlike an SVD of ``S``, whose gradient divides by ``σ_i² - σ_j²`` and is NaN for
a tetrahedron, a square or a cube (repeated singular values), the eigenvector
of ``K`` has the derivative ``(λI - K)⁺ dK v``, finite whenever the optimum is
unique. ``torch.linalg.eigh``'s own backward divides by every eigenvalue gap,
the unused ones included, so the derivative is attached here by hand.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.autograd import records_graph


class HornSolution(NamedTuple):
    """quaternion (*, 4) of the optimum, value (*) ``tr(O S)``, improper (*) bool,
    gap (*) to the next eigenvalue and spread (*) ``λ_max - λ_min`` (both detached)."""

    quaternion: torch.Tensor
    value: torch.Tensor
    improper: torch.Tensor
    gap: torch.Tensor
    spread: torch.Tensor


def horn_matrix(s: torch.Tensor) -> torch.Tensor:
    """Horn's symmetric ``K`` (*, 4, 4) of a correlation ``s`` (*, 3, 3) ``Σ w p qᵀ``."""
    sxx, sxy, sxz, syx, syy, syz, szx, szy, szz = s.flatten(-2).unbind(-1)
    rows = [
        sxx + syy + szz, syz - szy, szx - sxz, sxy - syx,
        syz - szy, sxx - syy - szz, sxy + syx, szx + sxz,
        szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy,
        sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz,
    ]
    return torch.stack(rows, -1).unflatten(-1, (4, 4))


def _attached(k, vals, vecs, index: int):
    """Eigenpair ``index`` of ``k`` with first-order derivatives through ``k``.

    ``dv = (λI - K)⁺ dK v`` and ``dλ = vᵀ dK v``; gaps that are exactly 0 (a
    non-unique optimum, flagged by the caller) contribute no derivative.
    """
    v, lam = vecs[..., index], vals[..., index]
    if not records_graph(k):
        return v, lam
    others = [j for j in range(4) if j != index % 4]
    gaps = lam[..., None] - vals[..., others]  # (*, 3)
    nonzero = gaps != 0
    inv = torch.where(nonzero, 1 / torch.where(nonzero, gaps, torch.ones_like(gaps)),
                      torch.zeros_like(gaps))
    basis = vecs[..., others]  # (*, 4, 3)
    pinv = (basis * inv[..., None, :]) @ basis.mT  # (*, 4, 4)
    dk = k - k.detach()  # zero, carries the gradient
    dkv = (dk @ v[..., None])[..., 0]
    return v + (pinv @ dkv[..., None])[..., 0], lam + (v * dkv).sum(-1)


def horn_solve(s: torch.Tensor, allow_reflection: bool) -> HornSolution:
    """Optimal rotation (or orthogonal matrix) for the correlations ``s`` (*, 3, 3).

    The eigen-decomposition runs in float64 without grad (non-finite problems
    get zeros there, and NaN back at the end); the derivative is attached by
    :func:`_attached`.
    """
    k = horn_matrix(s).to(torch.float64)
    finite = torch.isfinite(k).all(-1).all(-1)
    k_safe = torch.where(finite[..., None, None], k, torch.zeros_like(k))
    with torch.no_grad():
        vals, vecs = torch.linalg.eigh(k_safe.detach())  # ascending
    top_v, top = _attached(k_safe, vals, vecs, 3)
    spread = vals[..., 3] - vals[..., 0]
    improper = torch.zeros_like(finite)
    if allow_reflection:
        bot_v, bot = _attached(k_safe, vals, vecs, 0)
        improper = -vals[..., 0] > vals[..., 3]
        quat = torch.where(improper[..., None], bot_v, top_v)
        value = torch.where(improper, -bot, top)
        gap = torch.where(improper, vals[..., 1] - vals[..., 0], vals[..., 3] - vals[..., 2])
    else:
        quat, value, gap = top_v, top, vals[..., 3] - vals[..., 2]
    nan = torch.where(finite, 0.0, float("nan")).to(quat.dtype)
    return HornSolution((quat + nan[..., None]).to(s.dtype), (value + nan).to(s.dtype),
                        improper, gap, spread)
