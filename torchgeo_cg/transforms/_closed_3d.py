"""The 3D closed forms of :mod:`torchgeo_cg.transforms.estimation`, on centered points.

Each takes the weighted centroids ``cs, cd`` (*, 3), the centered points
``ps, qs`` (*, N, 3) and the weights ``w`` (*, N), and returns
``(matrix (*, 4, 4), rank_ok (*), condition (*))``.

Degeneracy is decided relative to the input's precision: a quantity that is
exactly zero for degenerate points is compared with ``64 eps`` of the input
dtype times its natural scale (and, for second moments computed in float64,
with the float64 rounding floor), so the flags are the same at every scale.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.numerics import working_dtype
from torchgeo_cg.transforms._horn import horn_solve
from torchgeo_cg.transforms.rotations import quaternion_to_matrix


def _affine_from(lin: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """(*, 3, 3) linear part and (*, 3) translation -> (*, 4, 4)."""
    top = torch.cat([lin, t[..., None]], dim=-1)
    bottom = torch.zeros_like(top[..., :1, :])
    bottom = torch.cat([bottom[..., :-1], torch.ones_like(bottom[..., -1:])], dim=-1)
    return torch.cat([top, bottom], dim=-2)


def _big(like: torch.Tensor) -> torch.Tensor:
    return torch.full_like(like, torch.finfo(like.dtype).max)


def _tolerance(low: torch.dtype) -> float:
    """64 eps of the dtype the fit is computed in (float16/bfloat16 inputs: float32)."""
    return 64 * float(torch.finfo(working_dtype(low)).eps)


def rigid_moments(src, dst, w, uniform: bool = False):
    """Centroids ``cs, cd`` (*, 3), centered ``src`` (*, N, 3), the correlation
    ``S = Σ wn p̃ q̃ᵀ`` (*, 3, 3) and the normalized weights ``wn`` (*, N).

    The centroids are weighted matrix-vector products, and ``S`` is formed as
    ``Σ wn p̃ qᵀ - (Σ wn p̃) cdᵀ`` from the *uncentered* ``dst`` (equal in exact
    arithmetic, since ``Σ wn p̃ = 0``; the second term removes what rounding
    left of it), so ``dst`` is never copied centered. Its rounding error is that of
    centering ``dst``: ``eps |cd|`` per point, as with a centered copy. ``uniform``
    (no weights given) scales ``p̃ᵀ q`` by ``1/N`` instead of weighting each point.
    """
    wn = w / w.sum(-1, keepdim=True)
    wrow = wn[..., None, :]  # (*, 1, N)
    cs, cd = (wrow @ src)[..., 0, :], (wrow @ dst)[..., 0, :]
    ps = src - cs[..., None, :]
    residual = (wrow @ ps)[..., 0, :]  # Σ wn p̃, zero up to rounding
    if uniform:
        s = (ps.mT @ dst) / src.shape[-2]
    else:
        s = (ps * wn[..., None]).mT @ dst
    s = s - residual[..., :, None] * cd[..., None, :]
    return cs, cd, ps, s, wn


def rigid_3d(cs, cd, ps, s, wn, with_scale: bool, allow_reflection: bool, low):
    """Kabsch (``with_scale=False``) or Umeyama through Horn's quaternion matrix, from
    :func:`rigid_moments`."""
    sol = horn_solve(s, allow_reflection)
    rot = quaternion_to_matrix(sol.quaternion)
    rot = torch.where(sol.improper[..., None, None], -rot, rot)
    tol = _tolerance(low)
    gap, spread = sol.gap, sol.spread
    rank_ok = (gap > tol * spread) & (spread > 0)
    condition = torch.where(rank_ok, spread / torch.where(gap > 0, gap, torch.ones_like(gap)),
                            _big(gap))
    if allow_reflection:  # an orthogonal matrix needs S of rank 3 (no plane's mirror)
        with torch.no_grad():
            sv = torch.linalg.svdvals(torch.nan_to_num(s.detach().to(torch.float64)))
        rank_ok = rank_ok & (sv[..., 2] > tol * sv[..., 0])
    lin = rot
    if with_scale:
        var = (ps.square().sum(-1) * wn).sum(-1)  # (*)
        ok = var > 0
        scale = torch.where(ok, sol.value / torch.where(ok, var, torch.ones_like(var)),
                            torch.zeros_like(var))
        lin = rot * scale[..., None, None]
        rank_ok = rank_ok & ok
    t = cd - (lin @ cs[..., None])[..., 0]
    return _affine_from(lin, t), rank_ok, condition.to(ps.dtype)


def _inverse_sym3(c: torch.Tensor):
    """Adjugate inverse of (*, 3, 3) via row cross products (differentiable, no LAPACK)."""
    r0, r1, r2 = c.unbind(-2)
    cols = torch.stack([torch.linalg.cross(r1, r2, dim=-1), torch.linalg.cross(r2, r0, dim=-1),
                        torch.linalg.cross(r0, r1, dim=-1)], -1)
    det = (r0 * cols[..., :, 0]).sum(-1)
    return cols, det


def affine_3d(cs, cd, ps, qs, w, low):
    """``A = C_qp C_pp⁻¹``; singular ``C_pp`` (coplanar ``src``) damped and flagged."""
    cov_pp = ps.mT @ (ps * w[..., None])  # (*, 3, 3) Σ w p̃ p̃ᵀ
    cov_qp = qs.mT @ (ps * w[..., None])  # (*, 3, 3) Σ w q̃ p̃ᵀ
    with torch.no_grad():
        lam = torch.linalg.eigvalsh(torch.nan_to_num(cov_pp.detach().to(torch.float64)))
        floor = max(_tolerance(low) ** 2, 64 * float(torch.finfo(torch.float64).eps))
        full = lam[..., 0] > floor * lam[..., 2]
        condition = torch.where(full, lam[..., 2] / torch.where(full, lam[..., 0], 1.0),
                                torch.finfo(torch.float64).max)
    tr = cov_pp.diagonal(dim1=-2, dim2=-1).sum(-1)
    damp = torch.where(full.to(tr.device), torch.zeros_like(tr),
                       float(torch.finfo(tr.dtype).eps) ** 0.5 * tr)
    eye = torch.eye(3, dtype=tr.dtype, device=tr.device)
    adj, det = _inverse_sym3(cov_pp + damp[..., None, None] * eye)
    ok = det != 0  # only coincident points (C = 0) remain singular: A = 0 there
    inv = torch.where(ok[..., None, None], adj / torch.where(ok, det, torch.ones_like(det))
                      [..., None, None], torch.zeros_like(adj))
    inv = inv + (tr * 0)[..., None, None]  # NaN kept
    lin = cov_qp @ inv
    t = cd - (lin @ cs[..., None])[..., 0]
    rank_ok = full.to(tr.device) & ~torch.isnan(tr)
    return _affine_from(lin, t), rank_ok, condition.to(ps.dtype)


def translation_fit(matrix: torch.Tensor, t: torch.Tensor):
    """A translation is always determined: ``rank_ok`` True (False for NaN), condition 1."""
    nan = torch.isnan(t).any(-1)
    return matrix, ~nan, torch.ones_like(t[..., 0]) + t[..., 0] * 0
