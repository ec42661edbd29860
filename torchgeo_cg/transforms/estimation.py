"""Closed-form, batched estimation of 2D transforms from point correspondences.

Report section 2.4 estimates, by hand, the transform from a start shape to eight
targets (Table 3). The functions here recover such transforms from matched points
``src -> dst`` in one batched call:

- :func:`find_homography_dlt`: Hartley-normalized DLT (Hartley & Zisserman,
  *Multiple View Geometry*, alg. 4.2), flags degenerate problems.
- :func:`find_affine`: linear least squares (6 dof).
- :func:`find_similarity`: Umeyama (1991), rotation + uniform scale + translation.
- :func:`find_euclidean`: rotation + translation (Kabsch / Umeyama without scale).
- :func:`find_translation`: the weighted mean offset.
- :func:`hartley_normalize`: the isotropic normalization used inside all of them.

Convention:
    - Column vectors: the returned ``dst_from_src`` maps ``dst ~ M @ [x, y, 1]^T``
      (perspective divide for homographies), as :func:`transform_points` applies it.
    - Points are ``(x, y)``; every function is batched over leading dims ``(*)``.
    - ``weights`` (optional, ``(*, N)``, non-negative) multiply each
      correspondence's *squared* residual; a weight of 0 removes a point (it is
      also left out of the normalization). As in kornia.
    - float16/bfloat16 inputs are computed in float32 (``find_homography_dlt`` in
      float64 unless ``double=False``) and returned in their dtype, saturating.
    - Degenerate input (too few points, collinear or coincident points) never
      gives NaN or inf: the homography is flagged by ``rank_ok``; the affine
      family falls back to the minimum-norm least-squares solution.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape
from torchgeo_cg.core.coerce import check_same_dtype
from torchgeo_cg.core.numerics import cast_back, safe_sqrt, working_dtype

__all__ = [
    "HartleyNormalization",
    "HomographyFit",
    "hartley_normalize",
    "find_homography_dlt",
    "find_affine",
    "find_similarity",
    "find_euclidean",
    "find_translation",
    "reprojection_error",
]


class HartleyNormalization(NamedTuple):
    """Result of :func:`hartley_normalize`.

    Attributes:
        points: ``(*, N, 2)`` normalized points, ``T @ p``.
        transform: ``(*, 3, 3)`` the similarity ``T`` (``normalized_from_input``).
        centroid: ``(*, 2)`` the (weighted) centroid removed.
        scale: ``(*)`` the isotropic scale applied after centering.
    """

    points: torch.Tensor
    transform: torch.Tensor
    centroid: torch.Tensor
    scale: torch.Tensor


class HomographyFit(NamedTuple):
    """Result of :func:`find_homography_dlt`.

    Attributes:
        matrix: ``(*, 3, 3)`` ``dst_from_src``, scaled so ``matrix[..., 2, 2] = 1``
            (or to unit Frobenius norm where ``|h33|`` is tiny).
        rank_ok: ``(*)`` bool, False for degenerate problems (fewer than 4 points
            with positive weight, collinear/coincident points, or a singular fit).
        condition: ``(*)`` estimated condition of the normalized DLT system
            ``σ_max / σ_8``, the largest singular value of the (trace-normalized)
            DLT matrix over its second smallest; the estimate lies between 1 and 3
            times the true ratio (exact for problems solved by ``eigh`` or SVD).
            Large means ill-posed (the solution is not unique to working
            precision); always finite.
    """

    matrix: torch.Tensor
    rank_ok: torch.Tensor
    condition: torch.Tensor


def check_points_nonempty(points: torch.Tensor, name: str) -> None:
    """ShapeError naming ``name`` when ``points`` (*, N, 2) has N = 0 (nothing to fit)."""
    if points.shape[-2] == 0:
        raise ShapeError(
            f"{name}: expected (*, N, 2) with N >= 1 (a transform of zero points is "
            f"undefined), got {tuple(points.shape)}"
        )


def check_pair(src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None):
    """Validate a correspondence set; returns ``weights`` cast to ``src``'s dtype (or None)."""
    sizes = check_shape(src, ["*", "N", "2"], "src")
    check_float(src, "src")
    check_shape(dst, ["*", "N", "2"], "dst", sizes={"N": sizes["N"]})
    check_float(dst, "dst")
    if src.shape != dst.shape:
        raise ShapeError(
            f"dst: expected the shape of src {tuple(src.shape)}, got {tuple(dst.shape)}"
        )
    check_points_nonempty(src, "src")
    if src.dtype != dst.dtype or src.device != dst.device:
        raise TypeError(
            f"dst: expected dtype {src.dtype} on {src.device} like src, "
            f"got {dst.dtype} on {dst.device}"
        )
    if weights is not None:
        check_shape(weights, ["*", "N"], "weights", sizes={"N": sizes["N"]})
        check_float(weights, "weights")
        if weights.shape != src.shape[:-1]:
            raise ShapeError(
                f"weights: expected shape {tuple(src.shape[:-1])}, got {tuple(weights.shape)}"
            )
        weights = weights.to(src.dtype)
    return weights


def to_working(*tensors: torch.Tensor | None) -> tuple:
    """The tensors in their working dtype (float16/bfloat16 -> float32); None stays None."""
    return tuple(None if t is None else t.to(working_dtype(t.dtype)) for t in tensors)


def effective_weights(points: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    """(*, N) non-negative weights; an all-zero (or absent) set becomes all ones."""
    if weights is None:
        return torch.ones_like(points[..., 0])
    w = torch.where(weights < 0, torch.zeros_like(weights), weights)  # NaN stays NaN
    total = w.sum(-1, keepdim=True)
    return torch.where(total == 0, torch.ones_like(w), w)


def _weighted_mean(x: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Weighted mean over the N axis: x (*, N, D), w (*, N) with positive sum -> (*, D)."""
    return (x * w[..., None]).sum(-2) / w.sum(-1, keepdim=True)


def similarity_matrix(scale: torch.Tensor, centroid: torch.Tensor) -> torch.Tensor:
    """[[s, 0, -s cx], [0, s, -s cy], [0, 0, 1]] from (*) scale and (*, 2) centroid."""
    one, zero = torch.ones_like(scale), torch.zeros_like(scale)
    rows = [scale, zero, -scale * centroid[..., 0], zero, scale, -scale * centroid[..., 1],
            zero, zero, one]
    return torch.stack(rows, dim=-1).unflatten(-1, (3, 3))


def point_norm(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """``hypot(x, y)`` without overflow or underflow, zero gradient at the origin, NaN kept."""
    nonzero = (x != 0) | (y != 0)
    one = torch.ones_like(x)
    return torch.where(nonzero, torch.hypot(torch.where(nonzero, x, one),
                                            torch.where(nonzero, y, one)), torch.zeros_like(x))


def hartley_weighted(points: torch.Tensor, w: torch.Tensor) -> HartleyNormalization:
    """:func:`hartley_normalize` with prepared weights w (*, N), non-negative, positive sum."""
    centroid = _weighted_mean(points, w)  # (*, 2)
    centered = points - centroid[..., None, :]  # (*, N, 2)
    radius = (point_norm(centered[..., 0], centered[..., 1]) * w).sum(-1) / w.sum(-1)  # (*)
    ok = radius > 0  # only coincident points leave the scale undefined
    radius_safe = torch.where(ok, radius, torch.ones_like(radius))
    scale = torch.where(ok, math.sqrt(2.0) / radius_safe, torch.ones_like(radius))
    return HartleyNormalization(
        centered * scale[..., None, None], similarity_matrix(scale, centroid), centroid, scale
    )


def _hartley_last(points: torch.Tensor, w: torch.Tensor):
    """Batch-last Hartley normalization: points (2, N, B), w (N, B) -> (points, centroid (2, B),
    scale (B,)), with the same conventions as :func:`_hartley`."""
    w_sum = w.sum(0)  # (B,)
    centroid = (points * w).sum(1) / w_sum  # (2, B)
    centered = points - centroid[:, None]  # (2, N, B)
    radius = (point_norm(centered[0], centered[1]) * w).sum(0) / w_sum  # (B,)
    ok = radius > 0
    radius_safe = torch.where(ok, radius, torch.ones_like(radius))
    scale = torch.where(ok, math.sqrt(2.0) / radius_safe, torch.ones_like(radius))
    return centered * scale, centroid, scale


def hartley_normalize(points: torch.Tensor, weights: torch.Tensor | None = None):
    """Hartley's isotropic normalization: centroid to 0, mean distance to ``sqrt(2)``.

    Convention:
        ``transform`` maps input points to normalized ones, ``p_n = T @ p``
        (column vectors), ``T = S(s) @ T(-c)``. Zero-weight points do not count;
        an all-zero weight set counts every point. Coincident points (mean
        distance 0) get ``s = 1``: no NaN, forward or backward. ``weights``
        follow the dtype of ``points`` (as in the ``find_*`` functions).

    Args:
        points: ``(*, N, 2)`` float points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        :class:`HartleyNormalization` ``(points (*, N, 2), transform (*, 3, 3),
        centroid (*, 2), scale (*))``.

    Example:
        >>> pts = torch.tensor([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
        >>> out = hartley_normalize(pts)
        >>> out.points
        tensor([[-1., -1.],
                [ 1., -1.],
                [ 1.,  1.],
                [-1.,  1.]])
        >>> out.transform
        tensor([[ 1.,  0., -1.],
                [ 0.,  1., -1.],
                [ 0.,  0.,  1.]])
    """
    check_shape(points, ["*", "N", "2"], "points")
    check_float(points, "points")
    check_points_nonempty(points, "points")
    if weights is not None:
        check_shape(weights, ["*", "N"], "weights", sizes={"N": points.shape[-2]})
        check_float(weights, "weights")
        weights = weights.to(points.dtype)  # weights follow the points, as in check_pair
    low = points.dtype
    points, weights = to_working(points, weights)
    out = hartley_weighted(points, effective_weights(points, weights))
    return HartleyNormalization(*(cast_back(t, low) for t in out))


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


def _dlt_moments(p: torch.Tensor, q: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """The 24 DLT moments Σ_n w c P Pᵀ: p, q (B, N, 2), w (B, N) -> (B, 6, 4).

    Rows: the entries xx, xy, x, yy, y, 1 of P Pᵀ; columns: c in (1, u, v, u² + v²).
    """
    x, y = p[..., 0], p[..., 1]
    u, v = q[..., 0], q[..., 1]
    pp = torch.stack([x * x, x * y, x, y * y, y, torch.ones_like(x)], dim=-1)  # (B, N, 6)
    coef = torch.stack([w, w * u, w * v, w * (u * u + v * v)], dim=-1)  # (B, N, 4)
    return pp.mT @ coef


def _dlt_normal_matrix(moments: torch.Tensor) -> torch.Tensor:
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
        m_sub = _dlt_normal_matrix(moments[..., todo].permute(2, 0, 1))  # (B', 9, 9)
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


def _svd_polish(eig: DLTEigen, p, q, w, trace) -> DLTEigen:
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


def find_homography_dlt(
    src: torch.Tensor,
    dst: torch.Tensor,
    weights: torch.Tensor | None = None,
    double: bool = True,
    max_condition: float = 1e6,
    iters: int = 6,
) -> HomographyFit:
    """Homography ``dst_from_src`` by the Hartley-normalized DLT, exact, batched, flagged.

    Both point sets are normalized (:func:`hartley_normalize`), the 9x9 normal
    matrix ``M = Aᵀ W A`` of the DLT rows ``q × (H p) = 0`` is formed, and its
    smallest eigenvector (the algebraic least-squares solution, ``‖h‖ = 1``,
    the last right singular vector of ``A``) is found by inverse iteration
    through a 3x3 Schur complement, then denormalized: ``H = T_dst⁻¹ Ĥ T_src``.
    Every problem is checked: the Davis-Kahan bound on the eigenvector error
    (or a rounding-level residual) accepts it, and the few that fail (close
    eigenvalues, rank-deficient systems) are solved again by LAPACK ``eigh``.
    The result is the SVD solution to solver precision (tested: relative
    difference <= 1e-6 in float64 on noisy and outlier data).

    Convention:
        Column vectors, ``dst ~ H @ [x, y, 1]ᵀ``; ``H`` maps ``src`` to ``dst``
        as kornia's ``find_homography_dlt(points1=src, points2=dst)`` and
        OpenCV's ``findHomography(src, dst)``. ``H[2, 2] = 1`` unless
        ``|h33| <= 1e-8 ‖H‖``, then ``‖H‖_F = 1``. Weights multiply squared
        algebraic residuals. Differentiable: the eigenvector's derivative is
        ``-(M - λ₁I)⁺ dM v``; problems with ``rank_ok = False`` get zero
        gradient. Never NaN for finite input, forward or backward.

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.
        double: compute in float64 inside (the result has the input dtype).
        max_condition: problems whose ``condition`` exceeds this, or whose normalized
            fit ``Ĥ`` has a Frobenius condition number above it (a singular
            homography, e.g. from a duplicated source point), are not ``rank_ok``.
        iters: inverse-iteration steps before the convergence check (the error
            shrinks by ``λ₁/λ₂`` per step); unconverged problems go to ``eigh``.

    Returns:
        :class:`HomographyFit` ``(matrix (*, 3, 3), rank_ok (*), condition (*))``.

    Example:
        >>> from torchgeo_cg.transforms import homography, transform_points
        >>> h = homography(torch.tensor([0.27, 0, -0.85, -0.25, -0.2, 5.65, -0.02, -0.09]))
        >>> src = torch.tensor([[0.0, 0.0], [4.0, 0.0], [4.0, 5.0], [0.0, 5.0], [2.0, 1.0]])
        >>> fit = find_homography_dlt(src, transform_points(h, src))
        >>> fit.matrix.round(decimals=4) + 0.0
        tensor([[ 0.2700,  0.0000, -0.8500],
                [-0.2500, -0.2000,  5.6500],
                [-0.0200, -0.0900,  1.0000]])
        >>> fit.rank_ok, find_homography_dlt(src[:3], src[:3]).rank_ok
        (tensor(True), tensor(False))
    """
    weights = check_pair(src, dst, weights)
    batch, n = src.shape[:-2], src.shape[-2]
    work = torch.float64 if double else working_dtype(src.dtype)
    # batch-last layout inside: every entry is a contiguous B-vector (fast on CPU)
    p_in = src.reshape(-1, n, 2).to(work).permute(2, 1, 0)  # (2, N, B)
    q_in = dst.reshape(-1, n, 2).to(work).permute(2, 1, 0)
    w_in = None if weights is None else weights.reshape(-1, n).to(work).T  # (N, B)
    if w_in is None:
        w = torch.ones_like(p_in[0])  # (N, B)
    else:
        w = torch.where(w_in < 0, torch.zeros_like(w_in), w_in)  # NaN stays NaN
        w = torch.where(w.sum(0) == 0, torch.ones_like(w), w)  # all-zero: count every point
    (p, cs, ss), (q, cd, sd) = _hartley_last(p_in, w), _hartley_last(q_in, w)
    moments, trace_safe = dlt_moments(p, q, w)
    shift = 1e-13 if work == torch.float64 else 1e-6
    with torch.no_grad():
        eig = dlt_smallest_eigenpair(moments.detach(), iters, shift)
        eig = _svd_polish(eig, p, q, w, trace_safe)
    h_vec, condition = eig.vector.T, eig.condition  # (B, 9), (B,)
    n_eff = (w > 0).sum(0) if w_in is None else (w_in > 0).sum(0)
    limit = min(max_condition, 0.3 / math.sqrt(shift))  # the shift hides larger conditions
    rank_ok = (n_eff >= 4) & (condition <= limit) & torch.isfinite(condition)
    if torch.is_grad_enabled() and moments.requires_grad:
        # first-order eigenvector perturbation with a detached pseudo-inverse:
        # value = v, derivative = -(M - λ₁I)⁺ (dM) v, where (M - λ₁I)⁺ = P K⁻¹ P with
        # K = M - λ₁I + v vᵀ and P = I - v vᵀ.
        m_unit = _dlt_normal_matrix(moments.permute(2, 0, 1))  # (B, 9, 9)
        m0 = m_unit.detach()
        eye = torch.eye(9, dtype=work, device=src.device)
        vv = h_vec[:, :, None] * h_vec[:, None, :]  # (B, 9, 9)
        lam = eig.value
        k_chol, _ = torch.linalg.cholesky_ex(m0 - lam[:, None, None] * eye + vv + shift * eye)
        dm_v = (m_unit - m0) @ h_vec[..., None]  # (B, 9, 1)
        proj = eye - vv
        corr = proj @ torch.cholesky_solve(proj @ dm_v, k_chol)
        corr = torch.where(rank_ok[:, None, None], corr, torch.zeros_like(corr))
        h_vec = h_vec - corr.squeeze(-1)
    hn = h_vec.T.unflatten(0, (3, 3))  # (3, 3, B): Ĥ in normalized coordinates
    with torch.no_grad():  # 1 / κ_F(Ĥ) = |det Ĥ| / (‖Ĥ‖_F ‖adj Ĥ‖_F): singular fits fail
        adj = adjugate3(hn)
        det = (hn[0] * adj[:, 0]).sum(0)
        inv_kappa = det.abs() / (hn.square().sum((0, 1)) * adj.square().sum((0, 1))).sqrt()
    rank_ok = rank_ok & (inv_kappa * max_condition >= 1)
    # H = T_dst⁻¹ Ĥ T_src with T = [[s, 0, -s cx], [0, s, -s cy], [0, 0, 1]], entrywise
    c0, c1 = hn[:, 0] * ss, hn[:, 1] * ss  # (3, B) columns of Ĥ T_src
    c2 = hn[:, 2] - c0 * cs[0] - c1 * cs[1]
    cols = torch.stack([c0, c1, c2], dim=1)  # (3, 3, B)
    h = torch.stack([cols[0] / sd + cd[0] * cols[2], cols[1] / sd + cd[1] * cols[2], cols[2]])
    h33 = h[2, 2]
    fro = safe_sqrt(h.square().sum((0, 1)))
    use_h33 = h33.abs() > 1e-8 * fro
    fro_safe = torch.where(fro > 0, fro, torch.ones_like(fro))
    den = torch.where(use_h33, h33, fro_safe)
    h = (h / den).permute(2, 0, 1)  # (B, 3, 3)
    return HomographyFit(
        cast_back(h, src.dtype).reshape(*batch, 3, 3),
        rank_ok.reshape(batch),
        cast_back(condition, src.dtype).reshape(batch),
    )


def _centered_stats(src, dst, weights):
    """Weighted centroids (*, 2) and centered points (*, N, 2) of both sets, weights (*, N)."""
    w = effective_weights(src, weights)
    cs, cd = _weighted_mean(src, w), _weighted_mean(dst, w)
    return w, cs, cd, src - cs[..., None, :], dst - cd[..., None, :]


def _affine_from(lin: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """(*, 2, 2) linear part and (*, 2) translation -> (*, 3, 3)."""
    top = torch.cat([lin, t[..., None]], dim=-1)  # (*, 2, 3)
    bottom = torch.zeros_like(top[..., :1, :])
    bottom = torch.cat([bottom[..., :2], torch.ones_like(bottom[..., 2:])], dim=-1)
    return torch.cat([top, bottom], dim=-2)


def find_affine(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Least-squares affine ``dst_from_src``: minimizes ``Σ w ‖A p + t - q‖²``, batched.

    Closed form: ``A = (Σ w q̃ p̃ᵀ)(Σ w p̃ p̃ᵀ)⁺`` on centered points, ``t = q̄ - A p̄``.

    Convention:
        Column vectors; result ``[[a, b, tx], [c, d, ty], [0, 0, 1]]``. For
        collinear ``src`` the covariance is rank 1 and its pseudo-inverse
        ``C / tr(C)²`` gives the minimum-norm solution; coincident ``src`` give
        ``A = 0``. Always finite; differentiable.

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        >>> find_affine(src, src @ torch.tensor([[2.0, 0.0], [1.0, 1.0]]) + 1.0)
        tensor([[2., 1., 1.],
                [0., 1., 1.],
                [0., 0., 1.]])
    """
    weights = check_pair(src, dst, weights)
    low = src.dtype
    src, dst, weights = to_working(src, dst, weights)
    w, cs, cd, ps, qs = _centered_stats(src, dst, weights)
    cov_pp = ps.mT @ (ps * w[..., None])  # (*, 2, 2) Σ w p̃ p̃ᵀ
    cov_qp = qs.mT @ (ps * w[..., None])  # (*, 2, 2) Σ w q̃ p̃ᵀ
    a, b, d = cov_pp[..., 0, 0], cov_pp[..., 0, 1], cov_pp[..., 1, 1]
    det = a * d - b * b
    tr = a + d
    full = det.abs() > 1e-10 * tr * tr  # full rank, relative to scale
    rank1 = ~full & (tr > 0)
    det_safe = torch.where(full, det, torch.ones_like(det))
    tr2_safe = torch.where(rank1, tr * tr, torch.ones_like(tr))
    adj = torch.stack([d, -b, -b, a], dim=-1).unflatten(-1, (2, 2))
    inv_full = adj / det_safe[..., None, None]
    inv_rank1 = cov_pp / tr2_safe[..., None, None]  # pseudo-inverse of a rank-1 PSD matrix
    pinv = torch.where(full[..., None, None], inv_full,
                       torch.where(rank1[..., None, None], inv_rank1, torch.zeros_like(inv_full)))
    pinv = torch.where(torch.isnan(tr)[..., None, None], tr[..., None, None], pinv)  # NaN kept
    lin = cov_qp @ pinv  # (*, 2, 2)
    t = cd - (lin @ cs[..., None]).squeeze(-1)
    return cast_back(_affine_from(lin, t), low)


def _rotation_scale(src, dst, weights):
    """2D Umeyama terms: centroids, Σ w p̃·q̃, Σ w p̃×q̃, Σ w ‖p̃‖²."""
    w, cs, cd, ps, qs = _centered_stats(src, dst, weights)
    dot = ((ps * qs).sum(-1) * w).sum(-1)  # (*)
    cross = ((ps[..., 0] * qs[..., 1] - ps[..., 1] * qs[..., 0]) * w).sum(-1)  # (*)
    var = (ps.square().sum(-1) * w).sum(-1)  # (*)
    return cs, cd, dot, cross, var


def _from_cos_sin(cos, sin, cs, cd):
    lin = torch.stack([cos, -sin, sin, cos], dim=-1).unflatten(-1, (2, 2))
    return _affine_from(lin, cd - (lin @ cs[..., None]).squeeze(-1))


def find_similarity(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Least-squares similarity ``dst_from_src`` (Umeyama 1991), batched.

    Minimizes ``Σ w ‖s R p + t - q‖²`` over rotations ``R`` (det +1, no
    reflection), scales ``s >= 0`` and ``t``. In 2D Umeyama's SVD reduces to
    ``s cos θ = Σ w p̃·q̃ / Σ w ‖p̃‖²`` and ``s sin θ = Σ w p̃×q̃ / Σ w ‖p̃‖²``.

    Convention:
        Column vectors; ``[[s cos θ, -s sin θ, tx], [s sin θ, s cos θ, ty], [0, 0, 1]]``
        with θ counter-clockwise. Coincident ``src`` give ``s = 0``. Always
        finite; differentiable.

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        >>> dst = torch.tensor([[1.0, 1.0], [1.0, 3.0], [-1.0, 1.0]])  # R(90°)·S(2) then T(1, 1)
        >>> find_similarity(src, dst).round(decimals=6) + 0.0
        tensor([[ 0., -2.,  1.],
                [ 2.,  0.,  1.],
                [ 0.,  0.,  1.]])
    """
    weights = check_pair(src, dst, weights)
    low = src.dtype
    cs, cd, dot, cross, var = _rotation_scale(*to_working(src, dst, weights))
    ok = var != 0  # NaN passes through
    var_safe = torch.where(ok, var, torch.ones_like(var))
    zero = torch.zeros_like(var)
    return cast_back(_from_cos_sin(torch.where(ok, dot / var_safe, zero),
                                   torch.where(ok, cross / var_safe, zero), cs, cd), low)


def find_euclidean(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Least-squares rigid motion ``dst_from_src`` (rotation + translation), batched.

    Minimizes ``Σ w ‖R p + t - q‖²``: ``θ = atan2(Σ w p̃×q̃, Σ w p̃·q̃)`` (the 2D
    Kabsch / Umeyama solution without scale).

    Convention:
        Column vectors; θ counter-clockwise. Where the angle is undefined
        (coincident points) ``R = I``. Always finite; differentiable.

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        >>> find_euclidean(src, src.flip(-1) * torch.tensor([-1.0, 1.0])).round(decimals=6) + 0.0
        tensor([[ 0., -1.,  0.],
                [ 1.,  0.,  0.],
                [ 0.,  0.,  1.]])
    """
    weights = check_pair(src, dst, weights)
    low = src.dtype
    cs, cd, dot, cross, _ = _rotation_scale(*to_working(src, dst, weights))
    length = point_norm(dot, cross)  # scale-free: only exactly (0, 0) is undefined
    ok = length != 0  # NaN passes through
    length_safe = torch.where(ok, length, torch.ones_like(length))
    cos = torch.where(ok, dot / length_safe, torch.ones_like(dot))
    sin = torch.where(ok, cross / length_safe, torch.zeros_like(dot))
    return cast_back(_from_cos_sin(cos, sin, cs, cd), low)


def find_translation(
    src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Least-squares translation ``dst_from_src``: ``t = Σ w (q - p) / Σ w``, batched.

    Convention:
        Column vectors; ``[[1, 0, tx], [0, 1, ty], [0, 0, 1]]``.

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
        >>> find_translation(src, src + torch.tensor([5.0, 1.0]))
        tensor([[1., 0., 5.],
                [0., 1., 1.],
                [0., 0., 1.]])
    """
    weights = check_pair(src, dst, weights)
    low = src.dtype
    src, dst, weights = to_working(src, dst, weights)
    w = effective_weights(src, weights)
    t = _weighted_mean(dst - src, w)
    eye = torch.eye(2, dtype=src.dtype, device=src.device).expand(*t.shape[:-1], 2, 2)
    return cast_back(_affine_from(eye, t), low)


def reprojection_error(
    matrix: torch.Tensor,
    src: torch.Tensor,
    dst: torch.Tensor,
    weights: torch.Tensor | None = None,
    symmetric: bool = False,
) -> torch.Tensor:
    """Weighted mean squared transfer error ``Σ w ‖π(M p) - q‖² / Σ w``, batched.

    With ``symmetric=True`` the backward transfer ``Σ w ‖π(M⁻¹ q) - p‖² / Σ w``
    is added (symmetric transfer error).

    Convention:
        Column vectors with the perspective divide of :func:`transform_points`;
        units are the input units squared (pixels²).

    Args:
        matrix: ``(*, 3, 3)`` ``dst_from_src``.
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        weights: optional ``(*, N)`` non-negative weights.
        symmetric: add the backward transfer error.

    Returns:
        ``(*)`` errors.

    Example:
        >>> from torchgeo_cg.transforms import translation
        >>> src = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
        >>> reprojection_error(translation(torch.tensor([1.0, 0.0])), src, src)
        tensor(1.)
    """
    from torchgeo_cg.transforms.homogeneous import inverse, transform_points

    weights = check_pair(src, dst, weights)
    check_shape(matrix, ["*", "3", "3"], "matrix")
    check_same_dtype({"src": src, "matrix": check_float(matrix, "matrix")})
    low = src.dtype
    matrix, src, dst, weights = to_working(matrix, src, dst, weights)
    w = effective_weights(src, weights)
    fwd = (transform_points(matrix, src) - dst).square().sum(-1)
    err = (fwd * w).sum(-1) / w.sum(-1)
    if symmetric:
        bwd = (transform_points(inverse(matrix), dst) - src).square().sum(-1)
        err = err + (bwd * w).sum(-1) / w.sum(-1)
    return cast_back(err, low)
