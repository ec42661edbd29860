"""Levenberg-Marquardt for 3D rigid and similarity fits, on se(3) (and a log scale).

The unknown is the normalized transform ``Ĥ = T_dst M T_src⁻¹``, where ``T`` centres a
point set at its weighted centroid and scales both sets by one shared factor ``k``
(their inverse RMS radius), so ``Ĥ`` stays rigid (or a similarity). Each step is a left
perturbation ``Ĥ ← E(δ) Ĥ`` with ``δ = (v, ω[, σ])`` and
``E(δ) = [[e^σ R, t], [0, 1]]``, ``[R, t] = se3_exp(v, ω)``. At the current points
``x_i = Ĥ p_i`` a perturbation moves ``x_i`` by ``v + ω × x_i + σ x_i`` to first order,
so the residual ``r_i = x_i - q_i`` has the Jacobian ``J_i = [I, -hat(x_i), x_i]``, and
``JᵀWJ`` is assembled from three weighted moments (``Σ w``, ``Σ w x``, ``Σ w x xᵀ``):

    [[S0 I,      -hat(S1),        S1   ],
     [hat(S1),   tr(S2) I - S2,   0    ],
     [S1ᵀ,       0,               tr S2]]

and ``Jᵀr = (Σ w r, Σ w x × r, Σ w xᵀ r)``. Robust losses enter as IRLS weights
``w ρ'(r²)``, recomputed at each step; a step is kept only if the robust cost drops.
The iterations are unrolled, so the result is differentiable in the inputs.
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.transforms._so3 import hat
from torchgeo_cg.transforms._solvers import damped_step, lm_update
from torchgeo_cg.transforms.robust import robust_loss, robust_weights
from torchgeo_cg.transforms.rotations import se3_exp, se3_log


def _normalize(src, dst, w):
    """Centroids (B, 3), the shared scale k (B,), and the normalized points (B, N, 3)."""
    wn = w / w.sum(-1, keepdim=True)  # (B, N)
    cs = (src * wn[..., None]).sum(-2)
    cd = (dst * wn[..., None]).sum(-2)
    ps, qs = src - cs[..., None, :], dst - cd[..., None, :]
    msd = (wn * (ps.square().sum(-1) + qs.square().sum(-1))).sum(-1) / 2  # (B,)
    ok = msd > 0  # coincident points: no scale to remove
    k = torch.where(ok, torch.where(ok, msd, torch.ones_like(msd)).rsqrt(), torch.ones_like(msd))
    return cs, cd, k, ps * k[:, None, None], qs * k[:, None, None], wn


def _apply(h: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
    return p @ h[:, :3, :3].mT + h[:, None, :3, 3]


def _terms(h, p, q, wn, kind, c):
    """(objective (B,) in the normalized frame, squared residuals (B, N))."""
    r2 = (_apply(h, p) - q).square().sum(-1)
    rho = r2 if kind == "l2" else robust_loss(r2, kind, c[:, None])
    return (wn * rho).sum(-1), r2


def _normal_system(h, p, q, wn, kind, c, with_scale: bool):
    """``JᵀWJ`` (B, P, P) and ``Jᵀ W r`` (B, P) at ``h`` (IRLS weights for robust losses)."""
    x = _apply(h, p)  # (B, N, 3)
    r = x - q
    w = wn if kind == "l2" else wn * robust_weights(r.square().sum(-1), kind, c[:, None])
    s0 = w.sum(-1)  # (B,)
    s1 = (w[..., None] * x).sum(-2)  # (B, 3)
    s2 = (w[..., None] * x).mT @ x  # (B, 3, 3)
    eye = torch.eye(3, dtype=x.dtype, device=x.device)
    tr = s2.diagonal(dim1=-2, dim2=-1).sum(-1)  # (B,)
    top = torch.cat([s0[:, None, None] * eye, -hat(s1)], -1)  # (B, 3, 6)
    mid = torch.cat([hat(s1), tr[:, None, None] * eye - s2], -1)
    jtj = torch.cat([top, mid], -2)  # (B, 6, 6)
    jtr = torch.cat([(w[..., None] * r).sum(-2),
                     (w[..., None] * torch.linalg.cross(x, r, dim=-1)).sum(-2)], -1)
    if with_scale:
        col = torch.cat([s1, torch.zeros_like(s1)], -1)  # (B, 6): the σ column
        jtj = torch.cat([torch.cat([jtj, col[..., None]], -1),
                         torch.cat([col, tr[:, None]], -1)[:, None]], -2)  # (B, 7, 7)
        jtr = torch.cat([jtr, (w * (x * r).sum(-1)).sum(-1, keepdim=True)], -1)
    return jtj, jtr


def _perturbation(step: torch.Tensor, with_scale: bool) -> torch.Tensor:
    e = se3_exp(step[:, :6])
    if not with_scale:
        return e
    scale = torch.exp(step[:, 6])[:, None, None]
    return torch.cat([torch.cat([e[:, :3, :3] * scale, e[:, :3, 3:]], -1), e[:, 3:]], -2)


def lm_fit_3d(src, dst, w, init, with_scale: bool, kind: str, scale: float, steps: int,
              mu0: float, tol: float, bar):
    """LM fit of ``(B, N, 3)`` correspondences with weights ``w (B, N)`` (positive sum).

    Returns ``(matrix (B, 4, 4), params (B, 6 | 7), loss (B,), history [(B,)])``;
    ``init`` is ``(B, 4, 4)`` ``dst_from_src`` (a rigid or similarity transform).
    """
    cs, cd, k, p, q, wn = _normalize(src, dst, w)
    c = scale * k  # the robust scale in the normalized frame, (B,)
    # Ĥ = T_dst M T_src⁻¹ with T = [[k I, -k c], [0, 1]]: the linear part is unchanged
    lin = init[:, :3, :3]
    t_hat = k[:, None] * (init[:, :3, 3] + (lin @ cs[..., None])[..., 0] - cd)
    h = torch.cat([torch.cat([lin, t_hat[..., None]], -1), init[:, 3:]], -2)
    obj, _ = _terms(h, p, q, wn, kind, c)
    history = [obj.detach() / k.square()]
    mu = torch.full_like(obj, mu0)
    for _ in bar:
        jtj, jtr = _normal_system(h, p, q, wn, kind, c, with_scale)
        step = damped_step(jtj, jtr, mu)  # (B, P)
        trial = _perturbation(step, with_scale) @ h
        obj_new, _ = _terms(trial, p, q, wn, kind, c)
        small = step.norm(dim=-1) <= math.sqrt(tol)
        accept, obj, mu, converged = lm_update(obj, obj_new, mu, small, tol)
        h = torch.where(accept[:, None, None], trial, h)
        history.append(obj.detach() / k.square())
        bar.set_postfix(loss=float((obj / k.square()).detach().mean()))
        if bool(converged.all()):
            break
    # M = T_dst⁻¹ Ĥ T_src: the linear part again unchanged, t = t̂ / k + cd - A cs
    lin = h[:, :3, :3]
    t = h[:, :3, 3] / k[:, None] + cd - (lin @ cs[..., None])[..., 0]
    matrix = torch.cat([torch.cat([lin, t[..., None]], -1), h[:, 3:]], -2)
    params = _parameters(h, with_scale)
    return matrix, params, obj / k.square(), history


def _parameters(h: torch.Tensor, with_scale: bool) -> torch.Tensor:
    """``se3_log`` of the normalized rigid motion (and ``log s``): (B, 6) or (B, 7)."""
    if not with_scale:
        return se3_log(h)
    det = torch.linalg.det(h[:, :3, :3])
    s = det.abs().pow(1.0 / 3.0)
    s_safe = torch.where(s > 0, s, torch.ones_like(s))
    rigid = torch.cat([torch.cat([h[:, :3, :3] / s_safe[:, None, None], h[:, :3, 3:]], -1),
                       h[:, 3:]], -2)
    return torch.cat([se3_log(rigid), s_safe.log()[:, None]], -1)
