"""Robust, batched estimation of 2D and 3D transforms: LO-RANSAC with MSAC scoring.

:func:`find_transform_ransac` fits one transform per problem of a batch to
correspondences with outliers. Every round draws ``K`` minimal samples for
every unfinished problem at once, solves them in closed form, drops
degenerate samples, ranks the hypotheses on a random preview of the points
(preemptive scoring, Nistér 2005), scores the best few on all points with the
truncated quadratic of MSAC (Torr & Zisserman 2000), and keeps the best per
problem. The winner is then refined as in LO-RANSAC (Chum et al. 2003):
refit on its inliers (least squares), rescore, repeat; homographies end with a
few Levenberg-Marquardt steps on the geometric transfer error of the inliers.
There is no Python loop over problems or hypotheses, only over rounds and LO
iterations.

Convention:
    - Column vectors: ``matrix`` is ``dst_from_src``, ``dst ~ M @ [x, y, 1]ᵀ``
      with the perspective divide, as :func:`find_homography_dlt`.
    - Residual: the one-way transfer error ``e = ‖π(M p) - q‖`` in ``dst``
      units (pixels). A point is an inlier when ``e <= threshold`` and its
      weight is positive. Score (lower is better):
      ``Σ w min(e², threshold²)``.
    - Sampling, minimal solvers and scoring run in Hartley-normalized
      coordinates (the threshold is scaled with them), so the result does not
      depend on the units of the points.
    - 3D: ``(*, N, 3)`` points and ``(*, 4, 4)`` matrices for the euclidean,
      similarity and affine models (minimal samples of 3, 3 and 4 points:
      :data:`SAMPLE_SIZES_3D`), with the same algorithm; the minimal solvers are
      the closed forms (Kabsch/Umeyama on 3 points, the affine solve on 4), batched
      over all hypotheses.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_choice
from torchgeo_cg.core.numerics import cast_back, safe_norm, working_dtype
from torchgeo_cg.transforms._correspondences import check_pair, hartley_weighted, similarity_matrix
from torchgeo_cg.transforms._dlt import adjugate3, dlt_moments, dlt_smallest_eigenpair, matmul3
from torchgeo_cg.transforms.estimation import (
    find_affine,
    find_euclidean,
    find_similarity,
)
from torchgeo_cg.transforms.fitting import SolverOptions, fit_transform

__all__ = ["RobustFit", "SAMPLE_SIZES", "SAMPLE_SIZES_3D", "find_transform_ransac"]

#: Minimal sample size of each model (2D points).
SAMPLE_SIZES: dict[str, int] = {"homography": 4, "affine": 3, "similarity": 2, "euclidean": 2}

#: Minimal sample size of each model for 3D points.
SAMPLE_SIZES_3D: dict[str, int] = {"affine": 4, "similarity": 3, "euclidean": 3}

# the 1 - 1e-6 quantile of the chi-square distribution with D degrees of freedom
# (scipy.stats.chi2.isf(1e-6, D)): squared errors of Gaussian inliers stay below it
_CHI2_WIDE = {2: 27.631021115928547, 3: 30.664849706213598}
_CLOSED_FORMS = {"affine": find_affine, "similarity": find_similarity,
                 "euclidean": find_euclidean}


class RobustFit(NamedTuple):
    """Result of :func:`find_transform_ransac`.

    Attributes:
        matrix: ``(*, 3, 3)`` (3D: ``(*, 4, 4)``) ``dst_from_src`` (``matrix[..., 2, 2] = 1`` for
            homographies); the identity where no model was found. Never NaN for
            finite input.
        inliers: ``(*, N)`` bool, ``‖π(M p) - q‖ <= threshold`` (and positive weight).
        num_inliers: ``(*)`` int64, the number of inliers.
        rank_ok: ``(*)`` bool, False where the problem is not solved: too few
            points, fewer than ``min_inliers`` inliers (all-outlier data), or a
            degenerate refit.
    """

    matrix: torch.Tensor
    inliers: torch.Tensor
    num_inliers: torch.Tensor
    rank_ok: torch.Tensor


class _Frame(NamedTuple):
    p: torch.Tensor  # (B, N, D) normalized src
    q: torch.Tensor  # (B, N, D) normalized dst
    t_src: torch.Tensor  # (B, D + 1, D + 1) normalized_from_src
    t_dst: torch.Tensor  # (B, D + 1, D + 1) normalized_from_dst
    thr2: torch.Tensor  # (B,) squared threshold in normalized dst units
    w: torch.Tensor  # (B, N) weights (0 for non-finite points)
    ph: torch.Tensor  # (B, D + 1, N) homogeneous normalized src, for the batched matmuls


def _frame_3d(src, dst, w, threshold: float) -> _Frame:
    """3D frames: both sets centred, one shared scale (mean distance sqrt(3)) for every
    model, so the similarity-class models stay in their class."""
    wn = w / w.sum(-1, keepdim=True)
    cs, cd = (src * wn[..., None]).sum(-2), (dst * wn[..., None]).sum(-2)  # (B, 3)
    ps, qs = src - cs[:, None], dst - cd[:, None]
    radius = (wn * (safe_norm(ps) + safe_norm(qs))).sum(-1) / 2  # (B,)
    ok = radius > 0  # only coincident points leave the scale undefined
    scale = torch.where(ok, math.sqrt(3.0) / torch.where(ok, radius, torch.ones_like(radius)),
                        torch.ones_like(radius))

    def similarity(centroid):  # [[k I, -k c], [0, 1]], (B, 4, 4)
        eye = torch.eye(3, dtype=src.dtype, device=src.device) * scale[:, None, None]
        top = torch.cat([eye, (-scale[:, None] * centroid)[..., None]], -1)
        bottom = torch.zeros_like(top[:, :1])
        bottom[..., 3] = 1.0
        return torch.cat([top, bottom], -2)

    p, q = ps * scale[:, None, None], qs * scale[:, None, None]
    return _Frame(p, q, similarity(cs), similarity(cd), (threshold * scale).square(), w,
                  _homogeneous(p))


def _normalized_frame(src, dst, w, model: str, threshold: float) -> _Frame:
    """Hartley frames; similarity-class models share one scale between src and dst."""
    if src.shape[-1] == 3:
        return _frame_3d(src, dst, w, threshold)
    ns, nd = hartley_weighted(src, w), hartley_weighted(dst, w)
    if model in ("homography", "affine"):
        return _Frame(ns.points, nd.points, ns.transform, nd.transform,
                      (threshold * nd.scale).square(), w, _homogeneous(ns.points))
    scale = 2.0 / (1.0 / ns.scale + 1.0 / nd.scale)
    p = (src - ns.centroid[..., None, :]) * scale[..., None, None]
    q = (dst - nd.centroid[..., None, :]) * scale[..., None, None]
    return _Frame(p, q, similarity_matrix(scale, ns.centroid),
                  similarity_matrix(scale, nd.centroid), (threshold * scale).square(), w,
                  _homogeneous(p))


def _cross(a: torch.Tensor, b: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
    """Twice the signed area of triangles a, b, c (..., 2) -> (...)."""
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (
        b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])


def _homography_4pt(ps: torch.Tensor, qs: torch.Tensor):
    """Homographies (..., 3, 3) through 4 correspondences (..., 4, 2), and a validity mask.

    ``Q = [λ1 p1, λ2 p2, λ3 p3]`` with ``[p1 p2 p3] λ = p4`` maps the projective
    basis to the points; ``H = Q_dst adj(Q_src)``. A sample is rejected when
    three of its points are (nearly) collinear, in src or dst (triangle area
    below ``sqrt(eps)`` in the normalized frame), or when the orientations of
    its four triangles are not preserved consistently (no homography without a
    point at infinity between them maps them: OpenCV's USAC does the same check).
    """
    triples = ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3))
    area_s = torch.stack([_cross(ps[..., i, :], ps[..., j, :], ps[..., k, :])
                          for i, j, k in triples])  # (4, ...)
    area_d = torch.stack([_cross(qs[..., i, :], qs[..., j, :], qs[..., k, :])
                          for i, j, k in triples])
    tol = math.sqrt(torch.finfo(ps.dtype).eps)
    sign = torch.sign(area_s * area_d)
    valid = ((area_s.abs() > tol) & (area_d.abs() > tol)).all(0) & (sign == sign[:1]).all(0)

    def basis(pts):  # (..., 4, 2) -> (3, 3, ...) batch-last Q
        homog = torch.cat([pts, torch.ones_like(pts[..., :1])], -1)  # (..., 4, 3)
        cols = homog.movedim(-1, 0).movedim(-1, 0)  # (4, 3, ...): cols[i] = p_i
        p3 = torch.stack([cols[0], cols[1], cols[2]], dim=1)  # (3, 3, ...) columns p1 p2 p3
        lam = (adjugate3(p3) * cols[3][None]).sum(1)  # (3, ...) = det · [p1 p2 p3]⁻¹ p4
        return p3 * lam[None]

    h = matmul3(basis(qs), adjugate3(basis(ps)))  # (3, 3, ...)
    return h.movedim(0, -1).movedim(0, -1), valid  # (..., 3, 3)


def _spread_3d(pts: torch.Tensor, model: str) -> torch.Tensor:
    """Volume of the 4 points' tetrahedron (affine) or squared area of the 3 points'
    triangle (rigid models), (B, K), in the normalized frame."""
    d = pts[..., 1:, :] - pts[..., :1, :]  # (B, K, m - 1, 3)
    if model == "affine":
        return torch.linalg.det(d).abs()
    return torch.linalg.cross(d[..., 0, :], d[..., 1, :], dim=-1).square().sum(-1)


def _minimal_fits(model: str, ps: torch.Tensor, qs: torch.Tensor):
    """Hypotheses (B, K, D + 1, D + 1) and validity (B, K) from samples (B, K, m, D)."""
    if model == "homography":
        return _homography_4pt(ps, qs)
    tol = math.sqrt(torch.finfo(ps.dtype).eps)
    if ps.shape[-1] == 3:  # collinear (rigid) or coplanar (affine) samples are rejected
        valid = (_spread_3d(ps, model) > tol) & (_spread_3d(qs, model) > tol)
    elif model == "affine":
        valid = (_cross(ps[..., 0, :], ps[..., 1, :], ps[..., 2, :]).abs() > tol) & (
            _cross(qs[..., 0, :], qs[..., 1, :], qs[..., 2, :]).abs() > tol)
    else:
        dp, dq = ps[..., 1, :] - ps[..., 0, :], qs[..., 1, :] - qs[..., 0, :]
        valid = (dp.square().sum(-1) > tol) & (dq.square().sum(-1) > tol)
    return _CLOSED_FORMS[model](ps, qs).matrix, valid


def _squared_errors(h: torch.Tensor, homog: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    """``‖π(H p) - q‖²`` (B, K, N) for hypotheses (B, K, D+1, D+1), points ``p`` given
    homogeneous and transposed, ``homog`` (B, D + 1, N) (:func:`_homogeneous`), and
    ``q`` (B, N, D).

    One batched matmul maps all points by all hypotheses. A point mapped to
    infinity (``w = 0``) gives inf or NaN, which :func:`_msac` and the inlier
    test count as an outlier (no grad flows here, so no guard is needed).
    """
    b, k, size = h.shape[0], h.shape[1], h.shape[-1]
    d = size - 1
    uvw = (h.reshape(b, k * size, size) @ homog).unflatten(1, (k, size))  # (B, K, D + 1, N)
    if d == 3:  # affine-class models only in 3D: the last row is (0, 0, 0, 1)
        e = uvw[:, :, :3] - q.mT[:, None]
        return e.square().sum(2)
    inv_w = uvw[:, :, 2].reciprocal()
    ex = torch.addcmul(-q[:, None, :, 0], uvw[:, :, 0], inv_w)
    ey = torch.addcmul(-q[:, None, :, 1], uvw[:, :, 1], inv_w)
    return torch.addcmul(ex * ex, ey, ey)


def _homogeneous(p: torch.Tensor) -> torch.Tensor:
    """(B, N, D) -> (B, D + 1, N) homogeneous columns."""
    return torch.cat([p, torch.ones_like(p[..., :1])], -1).mT


def _msac(err2: torch.Tensor, thr2: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """MSAC score (B, K): ``Σ w min(e², t²)``; err2 (B, K, N), thr2 (B,), w (B, N)."""
    t2 = thr2[:, None, None].expand_as(err2)
    return (torch.where(err2 < t2, err2, t2) @ w[:, :, None]).squeeze(-1)  # NaN -> t²


def _sample(frame: _Frame, m: int, k: int, weighted: bool, generator):
    """Minimal samples (B, K, m, D) of src and dst."""
    p, q, w = frame.p, frame.q, frame.w
    b, n, d = p.shape
    if weighted:
        idx = torch.multinomial(w, k * m, replacement=True, generator=generator)
    else:
        idx = torch.randint(0, n, (b, k * m), generator=generator, device=p.device)
    idx = idx.reshape(b, k * m, 1).expand(b, k * m, d)
    return (torch.gather(p, 1, idx).reshape(b, k, m, d),
            torch.gather(q, 1, idx).reshape(b, k, m, d))


def _round(frame: _Frame, model, k, preview, keep, weighted, generator):
    """One round: best hypothesis (B, D+1, D+1) of K samples per problem and its score (B,)."""
    m = _sample_size(model, frame.p.shape[-1])
    ps, qs = _sample(frame, m, k, weighted, generator)
    hyp, valid = _minimal_fits(model, ps, qs)  # (B, K, 3, 3), (B, K)
    hyp = torch.where(valid[..., None, None], hyp, torch.zeros_like(hyp))
    p, q, w, thr2 = frame.p, frame.q, frame.w, frame.thr2
    b, n, d = p.shape
    if preview < n:  # preemptive ranking on a random subset of the points
        sub = torch.randint(0, n, (b, preview), generator=generator, device=p.device)
        sub2 = sub[..., None].expand(b, preview, d)
        rough = _msac(_squared_errors(hyp, _homogeneous(torch.gather(p, 1, sub2)),
                                      torch.gather(q, 1, sub2)),
                      thr2, torch.gather(w, 1, sub))
        rough = torch.where(valid, rough, torch.full_like(rough, math.inf))
        top = rough.topk(min(keep, k), dim=1, largest=False).indices  # (B', T)
        hyp = torch.gather(hyp, 1, top[..., None, None].expand(-1, -1, d + 1, d + 1))
        valid = torch.gather(valid, 1, top)
    score = _msac(_squared_errors(hyp, frame.ph, q), thr2, w)
    score = torch.where(valid, score, torch.full_like(score, math.inf))
    best = score.argmin(1)  # (B',)
    rows = torch.arange(b, device=p.device)
    return hyp[rows, best], score[rows, best]


def _count(h, frame: _Frame):
    """Squared errors (B, N) of one hypothesis per problem (B, D+1, D+1), and the inliers."""
    err = _squared_errors(h[:, None], frame.ph, frame.q)[:, 0]
    return err, (err <= frame.thr2[:, None]) & (frame.w > 0)


def _search(frame: _Frame, model, confidence, max_iterations, k, lo_iterations, weighted,
            generator, start):
    """Adaptive rounds of :func:`_round` + LO: best hypothesis (B, D+1, D+1), score (B,).

    After each round the round's winner is locally optimized (LO-RANSAC), and a
    problem stops once ``K · rounds >= log(1 - confidence) / log(1 - ε^m)``
    with ``ε`` its best inlier fraction so far (the classical RANSAC bound).
    """
    b, d = frame.p.shape[0], frame.p.shape[-1]
    m = _sample_size(model, d)
    eye = torch.eye(d + 1, dtype=frame.p.dtype, device=frame.p.device)
    best = eye.expand(b, d + 1, d + 1).clone()
    score = torch.full_like(frame.thr2, math.inf)
    drawn = torch.zeros(b, dtype=torch.long, device=frame.p.device)
    needed = torch.where(start, max_iterations, 0)
    n_eff = (frame.w > 0).sum(-1).clamp_min(1)
    log_fail = math.log1p(-confidence)
    while True:
        active = (drawn < needed).nonzero().squeeze(-1)
        if active.numel() == 0:
            break
        sub = _Frame(*(t[active] for t in frame))
        # later rounds have few problems left: give each more samples, as many as the
        # median one still needs (at most the work of the first round)
        left = int((needed[active] - drawn[active]).median())
        k_round = k * max(1, min(b // active.numel(), -(-left // k)))
        hyp, sc = _round(sub, model, k_round, min(32, frame.p.shape[1]), 4, weighted,
                         generator)
        hyp, sc = _local_optimization(sub, model, hyp, sc, lo_iterations)
        better = sc < score[active]
        best[active] = torch.where(better[:, None, None], hyp, best[active])
        score[active] = torch.where(better, sc, score[active])
        drawn[active] += k_round
        _, inl = _count(best[active], sub)
        eps = (inl.sum(-1) / n_eff[active]).to(frame.p.dtype).pow(m)
        log_miss = torch.log1p(-eps.clamp(max=1 - 1e-12))
        bound = torch.where(eps > 0, torch.ceil(log_fail / log_miss.clamp(max=-1e-300)),
                            torch.full_like(eps, max_iterations))
        needed[active] = bound.clamp(max=max_iterations).long()
    return best, score


def _dlt_in_frame(frame: _Frame, w_fit: torch.Tensor):
    """Weighted DLT (B, 3, 3) directly in the (already normalized) RANSAC frame, and ok (B,).

    The lean core of :func:`find_homography_dlt`: the exact smallest eigenvector
    of the DLT matrix, no renormalization, no gradient path.
    """
    work = torch.float64
    p = frame.p.to(work).permute(2, 1, 0)  # (2, N, B)
    q = frame.q.to(work).permute(2, 1, 0)
    moments, _ = dlt_moments(p, q, w_fit.to(work).T)
    eig = dlt_smallest_eigenpair(moments, 4, 1e-13)
    h = eig.vector.T.reshape(-1, 3, 3)
    ok = ((w_fit > 0).sum(-1) >= 4) & (eig.condition <= 1e6) & torch.isfinite(h).flatten(-2).all(-1)
    h33 = h[:, 2, 2]
    return (h / torch.where(h33 != 0, h33, torch.ones_like(h33))[:, None, None]).to(
        frame.p.dtype), ok


def _refit(model: str, frame: _Frame, w_fit: torch.Tensor, init: torch.Tensor, final: bool):
    """Least-squares refit on weights w_fit (B, N): DLT (or LM from ``init`` when ``final``)."""
    if model != "homography":
        enough = (w_fit > 0).sum(-1) >= _sample_size(model, frame.p.shape[-1])
        return _CLOSED_FORMS[model](frame.p, frame.q, w_fit).matrix, enough
    if not final:
        return _dlt_in_frame(frame, w_fit)
    ok = (w_fit > 0).sum(-1) >= 4
    safe_w = torch.where(ok[:, None], w_fit, frame.w)
    return fit_transform(frame.p, frame.q, "homography", init=init, weights=safe_w,
                         solver=SolverOptions("lm", steps=5)).matrix, ok


def _local_optimization(frame: _Frame, model, best, score, lo_iterations: int):
    """LO-RANSAC: refit on the inliers by least squares, keep it where MSAC improves."""
    for _ in range(lo_iterations):
        _, inl = _count(best, frame)
        refit, ok = _refit(model, frame, frame.w * inl, best, False)
        new = _msac(_squared_errors(refit[:, None], frame.ph, frame.q), frame.thr2,
                    frame.w)[:, 0]
        better = ok & (new < score) & torch.isfinite(refit).flatten(-2).all(-1)
        best = torch.where(better[:, None, None], refit, best)
        score = torch.where(better, new, score)
    return best, score


def _final_refit(frame: _Frame, model, best):
    """The maximum-likelihood refit of the winner.

    The noise scale is estimated from the inliers (``σ² = mean e² / D``, as for a
    Gaussian error in D dimensions; the truncation at the threshold biases it a little
    low) and every point with ``e <= max(threshold, 5.26 σ)`` (5.54 σ in 3D: the
    1 - 1e-6 quantile) is fitted, so that no
    true inlier is cut at the threshold (MAGSAC's observation); homographies
    use LM on the transfer error, the other models their closed forms.
    """
    err, inl = _count(best, frame)
    d = frame.p.shape[-1]
    count = inl.sum(-1).clamp_min(1)
    sigma2 = torch.where(inl, err, torch.zeros_like(err)).sum(-1) / (d * count)  # E e² = Dσ²
    wide2 = torch.maximum(frame.thr2, _CHI2_WIDE[d] * sigma2.nan_to_num(0.0))
    wide = (err <= wide2[:, None]) & (frame.w > 0)
    refit, ok = _refit(model, frame, frame.w * wide, best, True)
    ok = ok & torch.isfinite(refit).flatten(-2).all(-1)
    return torch.where(ok[:, None, None], refit, best)


def _sample_size(model: str, d: int) -> int:
    return (SAMPLE_SIZES_3D if d == 3 else SAMPLE_SIZES)[model]


def _validate(model, threshold, confidence, max_iterations, hypotheses_per_round,
              lo_iterations, min_inliers, d):
    check_choice(model, SAMPLE_SIZES_3D if d == 3 else SAMPLE_SIZES,
                 "model (3D points)" if d == 3 else "model")
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and threshold > 0):
        raise ValueError(f"threshold: expected a finite positive number, got {threshold!r}")
    if not (isinstance(confidence, (int, float)) and 0 < confidence < 1):
        raise ValueError(f"confidence: expected a number in (0, 1), got {confidence!r}")
    for name, value, low in (("max_iterations", max_iterations, 1),
                             ("hypotheses_per_round", hypotheses_per_round, 1),
                             ("lo_iterations", lo_iterations, 0),
                             ("min_inliers", min_inliers, 0)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or value < low):
            raise ValueError(f"{name}: expected an int >= {low}, got {value!r}")


def _prepare(src, dst, weights):
    """Flattened (B, N, D) points with non-finite ones zeroed, weights (B, N), NaN-weight flag."""
    n, d = src.shape[-2:]
    p, q = src.reshape(-1, n, d), dst.reshape(-1, n, d)
    finite = torch.isfinite(p).all(-1) & torch.isfinite(q).all(-1)  # (B, N)
    w = torch.ones_like(p[..., 0]) if weights is None else weights.reshape(-1, n)
    nan_weight = torch.isnan(w).any(-1)
    w = torch.where(finite & (w > 0), w, torch.zeros_like(w))  # NaN and negatives -> 0
    zero = torch.zeros_like(p)
    return torch.where(finite[..., None], p, zero), torch.where(finite[..., None], q, zero), \
        w, nan_weight


def find_transform_ransac(
    src: torch.Tensor,
    dst: torch.Tensor,
    model: str = "homography",
    threshold: float = 3.0,
    confidence: float = 0.999,
    max_iterations: int = 1000,
    weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
    hypotheses_per_round: int = 64,
    lo_iterations: int = 2,
    min_inliers: int | None = None,
) -> RobustFit:
    """Robust ``dst_from_src`` of a ``model`` from correspondences with outliers, batched.

    LO-RANSAC with MSAC scoring (see the module docstring): rounds of
    ``hypotheses_per_round`` minimal samples per problem, all problems and
    hypotheses solved and scored together; samples with three collinear points
    (or, for homographies, inconsistent orientations) are rejected before
    scoring; the winner is refit on its inliers ``lo_iterations`` times (DLT
    or closed-form least squares), and a homography finally gets 5 LM steps on
    the transfer error of its inliers (:func:`fit_transform`). 3D points
    ``(*, N, 3)`` give ``(*, 4, 4)`` matrices for the euclidean, similarity and
    affine models (minimal samples of 3, 3 and 4 points, :data:`SAMPLE_SIZES_3D`;
    collinear, respectively coplanar, samples are rejected).

    Convention:
        Column vectors, ``dst ~ M @ [x, y, 1]ᵀ``; ``threshold`` is in ``dst``
        units (pixels) on the one-way transfer error ``‖π(M p) - q‖``.
        ``weights`` scale each point's sampling probability and MSAC term;
        zero-weight and non-finite points are never sampled and never inliers
        (a robust estimator treats them as outliers). A NaN weight makes the
        problem's ``matrix`` NaN and ``rank_ok`` False. Problems that cannot
        be solved (fewer than ``m`` usable points, fewer than ``min_inliers``
        inliers) get ``rank_ok = False`` and a finite matrix (the identity if
        no hypothesis was valid). Reproducible: all randomness comes from
        ``generator``. Not differentiable (refit the inliers with
        :func:`fit_transform` for gradients). float16/bfloat16 inputs are
        solved in float32 and the matrix is returned in their dtype.

    Args:
        src: ``(*, N, 2)`` or ``(*, N, 3)`` source points.
        dst: ``(*, N, D)`` destination points.
        model: ``"homography"``, ``"affine"``, ``"similarity"`` or ``"euclidean"``
            (minimal samples of 4, 3, 2, 2 points: :data:`SAMPLE_SIZES`); in 3D
            ``"affine"``, ``"similarity"`` or ``"euclidean"``.
        threshold: inlier threshold on the transfer error, input units, > 0.
        confidence: probability of drawing at least one all-inlier sample, in (0, 1).
        max_iterations: most minimal samples drawn per problem.
        weights: optional ``(*, N)`` non-negative weights.
        generator: ``torch.Generator`` for the samples (default: the global one).
        hypotheses_per_round: samples per problem per round.
        lo_iterations: local-optimization refits.
        min_inliers: fewest inliers of a solved problem (default ``3 m + 2``:
            14 for homographies, more than random outliers reach).

    Returns:
        :class:`RobustFit` ``(matrix (*, D + 1, D + 1), inliers (*, N), num_inliers (*),
        rank_ok (*))``.

    Example:
        >>> from torchgeo_cg.transforms import homography, transform_points
        >>> gen = torch.Generator().manual_seed(0)
        >>> h = homography(torch.tensor([0.9, 0.1, 5.0, -0.1, 1.1, -3.0, 1e-3, 0.0]))
        >>> src = torch.rand(2, 100, 2, generator=gen) * 100
        >>> dst = transform_points(h, src)
        >>> dst[:, :40] = torch.rand(2, 40, 2, generator=gen) * 100  # 40% outliers
        >>> fit = find_transform_ransac(src, dst, generator=gen)
        >>> fit.num_inliers, fit.rank_ok
        (tensor([60, 60]), tensor([True, True]))
        >>> bool(fit.inliers[:, 40:].all()), torch.allclose(fit.matrix, h.expand(2, 3, 3),
        ...                                                 atol=1e-3)
        (True, True)

        In 3D, a rigid motion with 50% outliers:

        >>> from torchgeo_cg.transforms import se3_exp
        >>> m = se3_exp(torch.tensor([1.0, -2.0, 0.5, 0.4, 0.1, -0.8]))
        >>> src = torch.randn(200, 3, generator=gen)
        >>> dst = transform_points(m, src)
        >>> dst[:100] = torch.randn(100, 3, generator=gen) * 3
        >>> fit = find_transform_ransac(src, dst, "euclidean", threshold=0.01, generator=gen)
        >>> fit.matrix.shape, int(fit.num_inliers), bool(fit.inliers[100:].all())
        (torch.Size([4, 4]), 100, True)
        >>> bool((fit.matrix - m).abs().max() < 1e-5)
        True
    """
    weights = check_pair(src, dst, weights, dims=(2, 3))
    d = src.shape[-1]
    _validate(model, threshold, confidence, max_iterations, hypotheses_per_round,
              lo_iterations, min_inliers, d)
    if working_dtype(src.dtype) != src.dtype:  # float16/bfloat16: solved in float32
        work = working_dtype(src.dtype)
        fit = find_transform_ransac(src.to(work), dst.to(work), model, threshold, confidence,
                                    max_iterations,
                                    None if weights is None else weights.to(work), generator,
                                    hypotheses_per_round, lo_iterations, min_inliers)
        return fit._replace(matrix=cast_back(fit.matrix, src.dtype))
    m = _sample_size(model, d)
    min_inliers = 3 * m + 2 if min_inliers is None else min_inliers
    batch, n = src.shape[:-2], src.shape[-2]
    p, q, w, nan_weight = _prepare(src, dst, weights)
    usable = (w > 0).sum(-1) >= m
    w_frame = torch.where(usable[:, None], w, torch.ones_like(w))  # normalization only
    frame = _normalized_frame(p, q, w_frame, model, float(threshold))._replace(w=w)
    best, score = _search(frame, model, confidence, max_iterations, hypotheses_per_round,
                          lo_iterations, weights is not None, generator, usable)
    best = _final_refit(frame, model, best)
    _, inliers = _count(best, frame)
    matrix = torch.linalg.solve(frame.t_dst, best @ frame.t_src)  # T_dst⁻¹ Ĥ T_src
    h33 = matrix[..., d, d]
    matrix = matrix / torch.where(h33 != 0, h33, torch.ones_like(h33))[..., None, None]
    num = inliers.sum(-1)
    rank_ok = usable & (num >= min_inliers) & torch.isfinite(score) & ~nan_weight
    matrix = torch.where(nan_weight[:, None, None], torch.full_like(matrix, math.nan), matrix)
    return RobustFit(matrix.reshape(*batch, d + 1, d + 1), inliers.reshape(*batch, n),
                     num.reshape(batch), rank_ok.reshape(batch))
