"""The direct linear transform's algebra: moments, the 9x9 normal matrix and its smallest
eigenpair by inverse iteration through a 3x3 Schur complement, batch last.

Shared by :func:`find_homography_dlt` and the RANSAC hypotheses. A matrix here is
``(3, 3, B)`` and a vector ``(3, B)``: every entry is a contiguous B-vector.
"""

from __future__ import annotations

from typing import NamedTuple

import torch


# M = Σ w (r1 r1ᵀ + r2 r2ᵀ) for the DLT rows r2 = [P, 0, -u P], r1 = [0, -P, v P] with
# P = (x, y, 1) has 3x3 blocks [[S0, 0, -Su], [0, S0, -Sv], [-Su, -Sv, Suv]] where
# S_c = Σ w c P Pᵀ for c in (1, u, v, u² + v²). DLT_M_INDEX gathers M (81 entries) from the
# 24 moments (6 entries of P Pᵀ x 4 coefficients); index 24 is a zero.
def _m_index() -> tuple[list[int], list[float]]:
    pair = [[0, 1, 2], [1, 3, 4], [2, 4, 5]]  # P Pᵀ entry -> index of xx, xy, x, yy, y, 1
    coef = {(0, 0): (0, 1.0), (1, 1): (0, 1.0), (0, 2): (1, -1.0), (2, 0): (1, -1.0),
            (1, 2): (2, -1.0), (2, 1): (2, -1.0), (2, 2): (3, 1.0)}
    index, sign = [], []
    for row in range(9):
        for col in range(9):
            k, sgn = coef.get((row // 3, col // 3), (None, 0.0))
            index.append(24 if k is None else pair[row % 3][col % 3] * 4 + k)
            sign.append(sgn)
    return index, sign


DLT_M_INDEX, DLT_M_SIGN = _m_index()


def dlt_normal_matrix(moments: torch.Tensor) -> torch.Tensor:
    """``M = Aᵀ W A`` (B, 9, 9) from the (B, 6, 4) moments."""
    flat = moments.flatten(-2)
    flat = torch.cat([flat, torch.zeros_like(flat[..., :1])], dim=-1)  # (B, 25)
    index = torch.tensor(DLT_M_INDEX, device=flat.device)
    sign = torch.tensor(DLT_M_SIGN, dtype=flat.dtype, device=flat.device)
    return (torch.index_select(flat, -1, index) * sign).unflatten(-1, (9, 9))


def _dlt_blocks(moments: torch.Tensor) -> torch.Tensor:
    """The blocks S0, Su, Sv, Suv (4, 3, 3, B) from the batch-last (6, 4, B) moments."""
    index = torch.tensor([0, 1, 2, 1, 3, 4, 2, 4, 5], device=moments.device)
    return torch.index_select(moments, 0, index).transpose(0, 1).unflatten(1, (3, 3))


# Batch-last 3x3 algebra: a matrix is (3, 3, B), a vector (3, B). Each entry is then a
# contiguous B-vector, about 10x faster on CPU than (B, 3, 3) reductions or bmm.
def matmul3(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(3, 3, B) @ (3, 3, B) -> (3, 3, B)."""
    return (a[:, :, None] * b[None]).sum(1)


def _mv3(a: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """(3, 3, B) @ (3, B) -> (3, B)."""
    return (a * x[None]).sum(1)


def adjugate3(a: torch.Tensor) -> torch.Tensor:
    """(3, 3, B) adjugate (transposed cofactors): ``adj(a) a = det(a) I``."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    c10 = a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    c12 = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    c20 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    c21 = a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    return torch.stack([c00, c10, c20, c01, c11, c21, c02, c12, c22]).unflatten(0, (3, 3))


def _inv3(a: torch.Tensor) -> torch.Tensor:
    """(3, 3, B) inverse by the adjugate; a zero determinant is replaced by a tiny one."""
    adj = adjugate3(a)
    det = (a[0] * adj[:, 0]).sum(0)
    tiny = torch.finfo(a.dtype).tiny
    det = torch.where(det.abs() > tiny, det, torch.full_like(det, tiny))
    return adj / det


def _smallest_eigvec(blocks: torch.Tensor, iters: int, shift: float, start=None):
    """Smallest eigenvector of the PSD DLT matrix ``M`` (trace 1) by inverse iteration.

    ``M + shift I`` is solved blockwise through the 3x3 Schur complement
    ``R = Suv - Su S0⁻¹ Su - Sv S0⁻¹ Sv`` (all 3x3 inverses in closed form), so
    no LAPACK call is made: ``eigh`` on many 9x9 problems is ~10x slower.

    Args:
        blocks: (4, 3, 3, B) S0, Su, Sv, Suv, already divided by ``tr M``.

    Returns:
        The unit vector (B, 9) and ``tr(Q) - vᵀQv`` (B,) with ``Q = (M + shift I)⁻¹``:
        the sum of ``1 / (λ_i + shift)`` over the other eigenvalues, which lies
        between ``1 / (λ₂ + shift)`` and 8 times that. Runs without grad.
    """
    eye = torch.eye(3, dtype=blocks.dtype, device=blocks.device)[..., None]  # (3, 3, 1)
    s0, su, sv, suv = blocks[0] + shift * eye, blocks[1], blocks[2], blocks[3] + shift * eye
    a1 = _inv3(s0)
    gu, gv = matmul3(a1, su), matmul3(a1, sv)  # S0⁻¹ Su, S0⁻¹ Sv
    r_inv = _inv3(suv - matmul3(su, gu) - matmul3(sv, gv))  # Schur complement inverse
    gu_t, gv_t = gu.transpose(0, 1), gv.transpose(0, 1)

    def solve(b: torch.Tensor) -> torch.Tensor:  # (9, B) -> (M + shift I)⁻¹ b
        b1, b2, b3 = b[:3], b[3:6], b[6:]
        x3 = _mv3(r_inv, b3 + _mv3(gu_t, b1) + _mv3(gv_t, b2))
        return torch.cat([_mv3(a1, b1) + _mv3(gu, x3), _mv3(a1, b2) + _mv3(gv, x3), x3])

    vec = torch.ones_like(blocks[0, 0, 0]).expand(9, -1) if start is None else start  # (9, B)
    for _ in range(iters):
        vec = solve(vec)
        vec = vec / vec.norm(dim=0, keepdim=True).clamp_min(1e-300)
    top = (vec * solve(vec)).sum(0)  # vᵀ Q v
    trace_q = (2 * a1.diagonal().sum(-1) + r_inv.diagonal().sum(-1)
               + (matmul3(gu, r_inv) * gu).sum((0, 1)) + (matmul3(gv, r_inv) * gv).sum((0, 1)))
    return vec.T, trace_q - top


def _block_mv(blocks: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """``M v`` from the (4, 3, 3, B) blocks S0, Su, Sv, Suv and a (9, B) vector."""
    s0, su, sv, suv = blocks
    h1, h2, h3 = v[:3], v[3:6], v[6:]
    return torch.cat([_mv3(s0, h1) - _mv3(su, h3), _mv3(s0, h2) - _mv3(sv, h3),
                      _mv3(suv, h3) - _mv3(su, h1) - _mv3(sv, h2)])


class DLTEigen(NamedTuple):
    """Smallest eigenpair of the trace-normalized DLT matrix (internal result, batch last).

    Attributes:
        vector: ``(9, B)`` unit eigenvector of the smallest eigenvalue.
        value: ``(B,)`` its eigenvalue (Rayleigh quotient).
        condition: ``(B,)`` ``sqrt(λ_max / λ_2)`` (estimated within a factor 3), finite.
    """

    vector: torch.Tensor
    value: torch.Tensor
    condition: torch.Tensor


def dlt_smallest_eigenpair(moments: torch.Tensor, iters: int, shift: float) -> DLTEigen:
    """The exact smallest eigenpair of ``M`` (trace 1) from its (6, 4, B) moments, no grad.

    Inverse iteration through the 3x3 Schur complement runs ``iters`` steps on
    every problem; a problem is accepted when the Davis-Kahan bound
    ``sin∠(v, v₁) <= ‖M v - ρ v‖ / (λ₂ - ρ)`` is below ``64 eps`` (λ₂ bounded
    from below by ``1 / (tr Q - vᵀ Q v)``), or when ``λ₂ > ρ`` and the residual
    is at rounding level (``16 eps ‖M‖``: as accurate as a backward-stable
    solver can be). The rest (close eigenvalues, rank-deficient systems) is
    solved by LAPACK ``eigh`` on the 9x9 matrix.
    Non-finite problems are left to propagate NaN.
    """
    blocks = _dlt_blocks(moments)
    vec, rest = _smallest_eigvec(blocks, iters, shift)  # (B, 9), (B,)
    vec = vec.T  # (9, B)
    mv = _block_mv(blocks, vec)
    rho = (vec * mv).sum(0)
    resid = (mv - rho * vec).norm(dim=0)
    gap = 1.0 / rest - shift - rho  # <= λ₂ - ρ
    tol = 64 * torch.finfo(moments.dtype).eps
    finite = torch.isfinite(moments).all(0).all(0)
    # accepted: the bound is met, or v is an eigenvector of M + E with ‖E‖ <= 16 eps ‖M‖
    # (backward stable, as good as eigh) and λ₁ is separated
    done = (resid <= tol * torch.maximum(gap, 0.25 * (gap > 0))) | ~finite
    rest = rest.clamp_min(1.0)
    big = torch.full_like(rest, torch.finfo(rest.dtype).max)
    condition = torch.where(torch.isfinite(rest), rest, big).sqrt()
    todo = (~done).nonzero().squeeze(-1)
    if todo.numel():
        m_sub = dlt_normal_matrix(moments[..., todo].permute(2, 0, 1))  # (B', 9, 9)
        values, vectors = torch.linalg.eigh(m_sub)
        top, second = values[:, -1], values[:, 1]
        cap = 1.0 / torch.finfo(moments.dtype).eps
        ratio = torch.where(second * cap * cap > top, top / second.clamp_min(1e-300),
                            torch.full_like(top, cap * cap))
        # two inverse-iteration steps polish eigh's vector where λ₁ << λ₂
        polished, _ = _smallest_eigvec(blocks[..., todo], 2, shift, vectors[..., 0].T)
        vec[:, todo] = polished.T
        rho[todo] = values[:, 0]
        condition[todo] = ratio.sqrt()
    return DLTEigen(vec, rho, condition)


def svd_polish(eig: DLTEigen, p, q, w, trace) -> DLTEigen:
    """Re-solve ill-conditioned problems (``condition > 1e3``, where the normal equations
    lose ``eps · condition²``) by the SVD of the weighted 2N x 9 DLT system itself.

    p, q: (2, N, B) normalized points, w: (N, B) weights, trace: (B,) ``tr M``.
    """
    todo = ((eig.condition > 1e3) & torch.isfinite(trace) & torch.isfinite(eig.value))
    todo = todo.nonzero().squeeze(-1)
    if todo.numel() == 0:
        return eig
    x, y, u, v = (t[:, todo].T for t in (p[0], p[1], q[0], q[1]))  # (B', N)
    r = w[:, todo].T.clamp_min(0).sqrt()
    o, z = torch.ones_like(x), torch.zeros_like(x)
    rows1 = torch.stack([x, y, o, z, z, z, -u * x, -u * y, -u], -1)  # (B', N, 9)
    rows2 = torch.stack([z, z, z, x, y, o, -v * x, -v * y, -v], -1)
    a = torch.cat([rows1, rows2], -2) * torch.cat([r, r], -1)[..., None]  # (B', 2N, 9)
    _, sing, vh = torch.linalg.svd(a, full_matrices=True)
    sing = torch.cat([sing, sing.new_zeros(sing.shape[0], 9 - sing.shape[-1])], -1)
    cap = 1.0 / torch.finfo(sing.dtype).eps
    ratio = torch.where(sing[:, 7] * cap > sing[:, 0], sing[:, 0] / sing[:, 7].clamp_min(
        torch.finfo(sing.dtype).tiny), torch.full_like(sing[:, 0], cap))
    vector, value, condition = eig.vector.clone(), eig.value.clone(), eig.condition.clone()
    vector[:, todo] = vh[:, -1].T
    value[todo] = sing[:, 8].square() / trace[todo]
    condition[todo] = ratio
    return DLTEigen(vector, value, condition)


def dlt_moments(p: torch.Tensor, q: torch.Tensor, w: torch.Tensor):
    """Trace-normalized DLT moments (6, 4, B) and ``tr M`` (B,) (1 where it is 0).

    p, q: (2, N, B) points (batch last), w: (N, B) weights. Rows: the entries
    xx, xy, x, yy, y, 1 of ``P Pᵀ``; columns: ``c`` in (1, u, v, u² + v²).
    """
    x, y, u, v = p[0], p[1], q[0], q[1]  # (N, B) each
    pp = torch.stack([x * x, x * y, x, y * y, y, torch.ones_like(x)])  # (6, N, B)
    coef = torch.stack([w, w * u, w * v, w * (u * u + v * v)])  # (4, N, B)
    moments = (pp[:, None] * coef[None]).sum(2)  # (6, 4, B): Σ_n w c P Pᵀ
    # tr M = 2 tr S0 + tr Suv (entries xx, yy, 1 of P Pᵀ are rows 0, 3, 5)
    trace = 2 * (moments[0, 0] + moments[3, 0] + moments[5, 0]) + (
        moments[0, 3] + moments[3, 3] + moments[5, 3])  # (B,)
    trace_safe = torch.where(trace > 0, trace, torch.ones_like(trace))
    return moments / trace_safe, trace_safe  # M's eigenvalues in [0, 1]
