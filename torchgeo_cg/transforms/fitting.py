"""Gradient-descent fitting of 2D transforms to point correspondences, batched.

The design asks for homographies fitted by gradient descent, so that a network can
be trained through them. :func:`fit_transform` fits one transform per problem of a
batch with Adam, L-BFGS or Levenberg-Marquardt, and :class:`HomographyModel` is a
learnable homography with the same parametrizations.

Hartley normalization is built into every parametrization: the parameters live in
the frame where both point sets are centered with mean distance ``sqrt(2)``, where
plain gradient descent on the 8 raw entries converges (in pixel units it does not:
the entries differ in scale by orders of magnitude).

Convention:
    - Column vectors, ``dst ~ M @ [x, y, 1]ᵀ`` with the perspective divide;
      ``matrix`` maps ``src`` to ``dst`` (``dst_from_src``).
    - ``params`` are those of the *normalized* transform ``Ĥ = T_dst M T_src⁻¹``
      (see :func:`parameters_to_matrix`); angles in radians, scales as logs.
    - Homography and affine models normalize ``src`` and ``dst`` separately; the
      similarity, euclidean, translation and trs models share one scale between
      them, so that the normalized transform stays in its class.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import nn

from torchgeo_cg.core.check import check_choice, check_float, check_shape
from torchgeo_cg.core.coerce import check_same_dtype
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.transforms.estimation import (
    DLT_M_INDEX,
    DLT_M_SIGN,
    check_pair,
    check_points_nonempty,
    effective_weights,
    hartley_weighted,
    similarity_matrix,
)
from torchgeo_cg.transforms.homogeneous import inverse, transform_points

__all__ = [
    "FitResult",
    "LOSSES",
    "MODELS",
    "PARAMETRIZATIONS",
    "fit_transform",
    "parameters_to_matrix",
    "matrix_to_parameters",
    "HomographyModel",
]

#: Number of parameters of each model.
MODELS: dict[str, int] = {
    "homography": 8,
    "affine": 6,
    "similarity": 4,
    "euclidean": 3,
    "translation": 2,
    "trs": 5,
}
#: Parametrizations of the homography model.
PARAMETRIZATIONS: tuple[str, ...] = ("entries", "corners", "sl3")
_DEFAULT_STEPS = {"adam": 200, "lbfgs": 50, "lm": 10}
_DEFAULT_LR = {"adam": 0.05, "lbfgs": 1.0, "lm": 1e-3}


class FitResult(NamedTuple):
    """Result of :func:`fit_transform`.

    Attributes:
        matrix: ``(*, 3, 3)`` fitted ``dst_from_src`` (``matrix[..., 2, 2] = 1``).
        params: ``(*, P)`` parameters of the normalized transform (see
            :func:`parameters_to_matrix`).
        loss: ``(*)`` final loss in input units squared (mean squared transfer
            error, robust ``ρ`` of ``loss``, plus the backward one if ``symmetric``).
        history: ``(steps_run + 1, *)`` the loss at the start and after each step.
    """

    matrix: torch.Tensor
    params: torch.Tensor
    loss: torch.Tensor
    history: torch.Tensor


# ---------------------------------------------------------------- parametrizations

_CORNERS = ((-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0))


def _square_to_quad(quad: torch.Tensor) -> torch.Tensor:
    """Homography taking (0,0), (1,0), (1,1), (0,1) to ``quad`` (*, 4, 2) (Heckbert 1989)."""
    x, y = quad[..., 0], quad[..., 1]
    sx = x[..., 0] - x[..., 1] + x[..., 2] - x[..., 3]
    sy = y[..., 0] - y[..., 1] + y[..., 2] - y[..., 3]
    dx1, dx2 = x[..., 1] - x[..., 2], x[..., 3] - x[..., 2]
    dy1, dy2 = y[..., 1] - y[..., 2], y[..., 3] - y[..., 2]
    den = dx1 * dy2 - dx2 * dy1
    ok = den.abs() > 1e-12
    den = torch.where(ok, den, torch.ones_like(den))  # degenerate quad: affine fallback
    g = torch.where(ok, (sx * dy2 - dx2 * sy) / den, torch.zeros_like(den))
    h = torch.where(ok, (dx1 * sy - sx * dy1) / den, torch.zeros_like(den))
    a, b = x[..., 1] - x[..., 0] + g * x[..., 1], x[..., 3] - x[..., 0] + h * x[..., 3]
    d, e = y[..., 1] - y[..., 0] + g * y[..., 1], y[..., 3] - y[..., 0] + h * y[..., 3]
    one = torch.ones_like(a)
    rows = [a, b, x[..., 0], d, e, y[..., 0], g, h, one]
    return torch.stack(rows, dim=-1).unflatten(-1, (3, 3))


def _sl3_basis(like: torch.Tensor) -> torch.Tensor:
    """(8, 3, 3) traceless generators: x/y translation, shear, rotation, scales, perspective."""
    e = torch.zeros(8, 3, 3, dtype=like.dtype, device=like.device)
    e[0, 0, 2] = e[1, 1, 2] = 1.0  # translations
    e[2, 0, 1] = 1.0  # x shear
    e[3, 1, 0] = 1.0  # y shear
    e[4, 0, 0], e[4, 1, 1] = 1.0, -1.0  # anisotropic scale
    e[5, 0, 0] = e[5, 1, 1] = 1.0
    e[5, 2, 2] = -2.0  # isotropic scale (traceless)
    e[6, 2, 0] = e[7, 2, 1] = 1.0  # perspective
    return e


def _rows_to_matrix(rows: list[torch.Tensor]) -> torch.Tensor:
    return torch.stack(rows, dim=-1).unflatten(-1, (3, 3))


def parameters_to_matrix(
    params: torch.Tensor,
    model: str = "homography",
    parametrization: str = "entries",
    base: torch.Tensor | None = None,
) -> torch.Tensor:
    """The normalized-frame transform ``Ĥ`` of ``params`` for ``model``.

    Convention:
        Column vectors; ``params = 0`` is the identity (or ``base``). ``base``
        must have the dtype of ``params`` (else ``TypeError`` naming both);
        float16/bfloat16 are computed in float32 and returned in their dtype.

        - ``homography`` / ``entries``: ``Ĥ = I + [p0..p7, 0]`` row-major (``h33 = 1``).
        - ``homography`` / ``corners``: ``p`` moves the images of the corners
          ``(-1,-1), (1,-1), (1,1), (-1,1)`` (x, y pairs); ``Ĥ`` maps the corners there.
        - ``homography`` / ``sl3``: ``Ĥ = base · exp(Σ p_i G_i)`` with traceless
          generators ``G`` (translations, shears, scales, perspective).
        - ``affine``: ``Ĥ = I + [[p0, p1, p2], [p3, p4, p5], [0, 0, 0]]``.
        - ``similarity``: ``[[1 + p0, -p1, p2], [p1, 1 + p0, p3], [0, 0, 1]]``.
        - ``euclidean``: ``T(p1, p2) · R(p0)``, ``p0`` in radians, counter-clockwise.
        - ``translation``: ``T(p0, p1)``.
        - ``trs``: ``T(p0, p1) · R(p2) · S(exp p3, exp p4)``, the report's T·R·Xs·Ys.

    Args:
        params: ``(*, P)`` with ``P = MODELS[model]``.
        model: one of :data:`MODELS`.
        parametrization: homography parametrization, one of :data:`PARAMETRIZATIONS`.
        base: ``(*, 3, 3)`` left factor of the ``sl3`` parametrization (identity if None).

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> parameters_to_matrix(torch.tensor([1.0, 2.0, 0.0, 0.0, 0.0]), "trs")
        tensor([[1., 0., 1.],
                [0., 1., 2.],
                [0., 0., 1.]])
    """
    check_choice(model, MODELS, "model")
    check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
    check_shape(params, ["*", str(MODELS[model])], "params")
    check_float(params, "params")
    if base is not None:
        check_shape(base, ["*", "3", "3"], "base")
        check_same_dtype({"params": params, "base": check_float(base, "base")})
    work = working_dtype(params.dtype)  # float16/bfloat16: computed in float32
    out = _parameters_to_matrix(params.to(work), model, parametrization,
                                None if base is None else base.to(work))
    return cast_back(out, params.dtype)


def _parameters_to_matrix(params, model, parametrization, base):
    p = params.unbind(-1)
    one, zero = torch.ones_like(p[0]), torch.zeros_like(p[0])
    if model == "homography":
        if parametrization == "entries":
            return _rows_to_matrix([one + p[0], p[1], p[2], p[3], one + p[4], p[5], p[6], p[7],
                                    one])
        if parametrization == "corners":
            corners = torch.tensor(_CORNERS, dtype=params.dtype, device=params.device)
            quad = corners + params.unflatten(-1, (4, 2))  # (*, 4, 2)
            # unit square (u, v) from corner frame: u = (x + 1) / 2
            half = torch.tensor([[0.5, 0, 0.5], [0, 0.5, 0.5], [0, 0, 1.0]],
                                dtype=params.dtype, device=params.device)
            return _square_to_quad(quad) @ half
        gen = torch.einsum("...i,ijk->...jk", params, _sl3_basis(params))
        h = torch.linalg.matrix_exp(gen)
        return h if base is None else base @ h
    if model == "affine":
        return _rows_to_matrix([one + p[0], p[1], p[2], p[3], one + p[4], p[5], zero, zero, one])
    if model == "similarity":
        return _rows_to_matrix([one + p[0], -p[1], p[2], p[1], one + p[0], p[3], zero, zero, one])
    if model == "euclidean":
        c, s = torch.cos(p[0]), torch.sin(p[0])
        return _rows_to_matrix([c, -s, p[1], s, c, p[2], zero, zero, one])
    if model == "translation":
        return _rows_to_matrix([one, zero, p[0], zero, one, p[1], zero, zero, one])
    c, s = torch.cos(p[2]), torch.sin(p[2])
    sx, sy = torch.exp(p[3]), torch.exp(p[4])
    return _rows_to_matrix([c * sx, -s * sy, p[0], s * sx, c * sy, p[1], zero, zero, one])


def matrix_to_parameters(
    matrix: torch.Tensor, model: str = "homography", parametrization: str = "entries"
) -> torch.Tensor:
    """Parameters of ``matrix`` for ``model`` (the inverse of :func:`parameters_to_matrix`).

    Convention:
        Exact for matrices of the model's class; other matrices are projected
        (e.g. the rotation of a ``euclidean`` model is the polar angle of the
        linear part). For ``sl3`` the parameters are zero: pass ``matrix`` as
        ``base`` instead. ``h33`` is divided out first (unless it is exactly 0).
        A NaN or inf entry anywhere gives NaN parameters, also for an entry the
        model ignores. float16/bfloat16 are computed in float32.

    Args:
        matrix: ``(*, 3, 3)`` normalized-frame transforms.
        model: one of :data:`MODELS`.
        parametrization: one of :data:`PARAMETRIZATIONS`.

    Returns:
        ``(*, P)`` parameters.

    Example:
        >>> m = parameters_to_matrix(torch.tensor([0.1, 0.2, 0.3, 0.4, 0.5]), "trs")
        >>> matrix_to_parameters(m, "trs")
        tensor([0.1000, 0.2000, 0.3000, 0.4000, 0.5000])
    """
    check_choice(model, MODELS, "model")
    check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
    check_shape(matrix, ["*", "3", "3"], "matrix")
    check_float(matrix, "matrix")
    work = working_dtype(matrix.dtype)  # float16/bfloat16: computed in float32
    m = matrix.to(work)
    h33 = m[..., 2, 2]
    m = m / torch.where(h33 == 0, torch.ones_like(h33), h33)[..., None, None]  # NaN stays
    # a non-finite entry anywhere makes every parameter NaN, also those a model ignores
    poison = (m * 0).sum((-2, -1))[..., None]
    return cast_back(_matrix_to_parameters(m, model, parametrization) + poison, matrix.dtype)


def _matrix_to_parameters(m: torch.Tensor, model: str, parametrization: str) -> torch.Tensor:
    eye = torch.eye(3, dtype=m.dtype, device=m.device)
    if model == "homography":
        if parametrization == "entries":
            return (m - eye).flatten(-2)[..., :8]
        if parametrization == "corners":
            corners = torch.tensor(_CORNERS, dtype=m.dtype, device=m.device)
            return (transform_points(m, corners.expand(*m.shape[:-2], 4, 2)) - corners).flatten(-2)
        return m.new_zeros(*m.shape[:-2], 8)  # zeros: the matrix goes into ``base``
    if model == "affine":
        return (m - eye)[..., :2, :].flatten(-2)
    t = m[..., :2, 2]
    if model == "similarity":
        a = (m[..., 0, 0] + m[..., 1, 1]) / 2 - 1
        b = (m[..., 1, 0] - m[..., 0, 1]) / 2
        return torch.cat([torch.stack([a, b], -1), t], -1)
    if model == "euclidean":
        angle = torch.atan2(m[..., 1, 0] - m[..., 0, 1], m[..., 0, 0] + m[..., 1, 1])
        return torch.cat([angle[..., None], t], -1)
    if model == "translation":
        return t.clone()
    angle = torch.atan2(m[..., 1, 0], m[..., 0, 0])
    c, s = torch.cos(angle), torch.sin(angle)
    sx = torch.hypot(m[..., 0, 0], m[..., 1, 0])
    sy = -s * m[..., 0, 1] + c * m[..., 1, 1]
    tiny = torch.finfo(m.dtype).tiny
    log_s = torch.stack([sx, sy], -1).clamp_min(tiny).log()
    return torch.cat([t, angle[..., None], log_s], -1)


# ---------------------------------------------------------------- residuals


def _project(h: torch.Tensor, p: torch.Tensor):
    """π(H p) entrywise: h (B, 3, 3), batch-last points p (2, N, B) -> x', y', w (N, B) each.

    Batch-last keeps every reduction over N off the innermost axis (fast on CPU).
    """
    x, y = p[0], p[1]
    e = h.permute(1, 2, 0)  # (3, 3, B): e[i, j] broadcasts over N
    w = e[2, 0] * x + e[2, 1] * y + e[2, 2]
    w = torch.where(w.abs() > 1e-12, w, torch.full_like(w, 1e-12))  # guard before dividing
    return (e[0, 0] * x + e[0, 1] * y + e[0, 2]) / w, (e[1, 0] * x + e[1, 1] * y + e[1, 2]) / w, w


def _squared_transfer(h: torch.Tensor, p: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    """Squared transfer error per point (N, B) of ``π(H p) - q``; p, q (2, N, B)."""
    xp, yp, _ = _project(h, p)
    return (xp - q[0]).square() + (yp - q[1]).square()


#: Robust losses of :func:`fit_transform`, as functions of the squared residual.
LOSSES: tuple[str, ...] = ("l2", "huber", "cauchy", "tukey")


def robust_rho(sq: torch.Tensor, kind: str, c2: torch.Tensor) -> torch.Tensor:
    """``ρ(s)`` of squared residuals ``sq`` (N, B) with squared scale ``c2`` (B,).

    With ``s = r²`` and scale ``c`` (Triggs et al. 2000, table of M-estimators):
    l2 ``s``; huber ``s`` for ``s <= c²`` else ``2 c √s - c²``; cauchy
    ``c² log(1 + s / c²)``; tukey ``c²/3 (1 - (1 - s/c²)³)``, constant ``c²/3``
    beyond ``c``. Each is ``s`` near 0 and homogeneous: ``ρ(k² s; k c) = k² ρ(s; c)``.
    """
    if kind == "l2":
        return sq
    t = sq / c2
    if kind == "huber":
        inside = t <= 1
        t_safe = torch.where(inside, torch.ones_like(t), t)  # sqrt only where t > 1
        return torch.where(inside, sq, c2 * (2 * t_safe.sqrt() - 1))
    if kind == "cauchy":
        return c2 * torch.log1p(t)
    return c2 / 3 * (1 - (1 - t.clamp(max=1)).pow(3))


def robust_weight(sq: torch.Tensor, kind: str, c2: torch.Tensor) -> torch.Tensor:
    """IRLS weight ``ρ'(s)`` (N, B): the weight of each squared residual in one GN step."""
    if kind == "l2":
        return torch.ones_like(sq)
    t = sq / c2
    if kind == "huber":
        inside = t <= 1
        t_safe = torch.where(inside, torch.ones_like(t), t)
        return torch.where(inside, torch.ones_like(t), t_safe.rsqrt())
    if kind == "cauchy":
        return 1 / (1 + t)
    return (1 - t.clamp(max=1)).square()


def _normal_equations(h, p, q, wn):
    """Gauss-Newton ``JᵀJ`` (B, 9, 9) and ``Jᵀr`` (B, 9) of the transfer error wrt vec(H).

    The rows of ``J`` for one point are ``jx = [P, 0, -x' P] / w`` and
    ``jy = [0, P, -y' P] / w`` with ``P = (x, y, 1)``, so ``JᵀJ`` has the block
    structure of the DLT matrix, ``[[S0, 0, -Sx], [0, S0, -Sy], [-Sx, -Sy, Sxy]]``
    with ``S_c = Σ wn c P Pᵀ / w²``: it is built from 24 moments, not from ``J``.
    Points p, q are batch-last (2, N, B), ``wn`` is (N, B).
    """
    x, y = p[0], p[1]
    xp, yp, w = _project(h, p)
    rx, ry = xp - q[0], yp - q[1]
    a = wn / w.square()  # (N, B)
    b = wn / w
    one = torch.ones_like(x)
    pp = torch.stack([x * x, x * y, x, y * y, y, one])  # (6, N, B)
    coef = torch.stack([a, a * xp, a * yp, a * (xp * xp + yp * yp)])  # (4, N, B)
    moments = (pp[:, None] * coef[None]).sum(2).flatten(0, 1)  # (24, B)
    moments = torch.cat([moments, torch.zeros_like(moments[:1])])  # (25, B)
    index = torch.tensor(DLT_M_INDEX, device=x.device)
    sign = torch.tensor(DLT_M_SIGN, dtype=x.dtype, device=x.device)
    jtj = (torch.index_select(moments, 0, index) * sign[:, None]).T.unflatten(-1, (9, 9))
    c = torch.stack([b * rx, b * ry, -b * (xp * rx + yp * ry)])  # (3, N, B)
    ph = torch.stack([x, y, one])  # (3, N, B)
    jtr = (c[:, None] * ph[None]).sum(2).flatten(0, 1).T  # (B, 9): Σ c_i P_j
    return jtj, jtr


class _Objective(NamedTuple):
    symmetric: bool
    kind: str  # one of LOSSES
    c2_dst: torch.Tensor | None  # (B,) squared robust scale in the normalized dst frame
    c2_src: torch.Tensor | None  # (B,) the same in the normalized src frame


def _irls(h, p, q, wn, kind, c2):
    """Weights (N, B) of the IRLS step at ``h``: ``wn ρ'(s)``."""
    if kind == "l2":
        return wn
    return wn * robust_weight(_squared_transfer(h, p, q), kind, c2)


def _system(hn, prob, objective: _Objective):
    """``JᵀJ`` (B, 9, 9) and ``Jᵀr`` (B, 9) of the (IRLS-reweighted) objective wrt vec(Ĥ)."""
    kind = objective.kind
    wn = _irls(hn, prob.p, prob.q, prob.wn, kind, objective.c2_dst)
    jtj, jtr = _normal_equations(hn, prob.p, prob.q, wn)
    if objective.symmetric:
        g = inverse(hn)
        wn_b = _irls(g, prob.q, prob.p, prob.wn, kind, objective.c2_src)
        jtj_b, jtr_b = _normal_equations(g, prob.q, prob.p, wn_b)
        # dG = -G dĤ G: d vec(G)_ij / d vec(Ĥ)_kl = -G_ik G_lj
        dg = -torch.einsum("bik,blj->bijkl", g, g).flatten(1, 2).flatten(2, 3)  # (B, 9, 9)
        jtj = jtj + dg.mT @ jtj_b @ dg
        jtr = jtr + (dg.mT @ jtr_b[..., None]).squeeze(-1)
    return jtj, jtr


class _Problem(NamedTuple):
    p: torch.Tensor  # (2, N, B) normalized src, batch last
    q: torch.Tensor  # (2, N, B) normalized dst
    wn: torch.Tensor  # (N, B) weights / Σ weights
    t_src: torch.Tensor  # (B, 3, 3)
    t_dst: torch.Tensor
    scale_src: torch.Tensor  # (B,)
    scale_dst: torch.Tensor


def _normalize(src, dst, w, model: str) -> _Problem:
    ns, nd = hartley_weighted(src, w), hartley_weighted(dst, w)
    wn = (w / w.sum(-1, keepdim=True)).T.contiguous()  # (N, B)

    def last(points):  # (B, N, 2) -> (2, N, B)
        return points.permute(2, 1, 0).contiguous()

    if model in ("homography", "affine"):
        return _Problem(last(ns.points), last(nd.points), wn, ns.transform, nd.transform,
                        ns.scale, nd.scale)
    # one shared scale keeps similarity/euclidean/translation/trs in their class
    scale = 2.0 / (1.0 / ns.scale + 1.0 / nd.scale)
    t_src, t_dst = similarity_matrix(scale, ns.centroid), similarity_matrix(scale, nd.centroid)
    p = (src - ns.centroid[..., None, :]) * scale[..., None, None]
    q = (dst - nd.centroid[..., None, :]) * scale[..., None, None]
    return _Problem(last(p), last(q), wn, t_src, t_dst, scale, scale)


def _loss_terms(hn, prob: _Problem, objective: _Objective):
    """(objective (B,) in normalized units, loss (B,) in input units)."""
    kind = objective.kind
    fwd = (robust_rho(_squared_transfer(hn, prob.p, prob.q), kind, objective.c2_dst)
           * prob.wn).sum(0)
    loss = fwd / prob.scale_dst.square()
    if objective.symmetric:
        bwd = (robust_rho(_squared_transfer(inverse(hn), prob.q, prob.p), kind,
                          objective.c2_src) * prob.wn).sum(0)
        return fwd + bwd, loss + bwd / prob.scale_src.square()
    return fwd, loss


def _denormalize(hn: torch.Tensor, prob: _Problem) -> torch.Tensor:
    """M = T_dst⁻¹ Ĥ T_src, scaled to ``m33 = 1`` where possible (entrywise, no tiny bmm)."""
    # T = [[s, 0, -s cx], [0, s, -s cy], [0, 0, 1]]: Ĥ T_src scales the first two columns
    # and shifts the third; T_dst⁻¹ = [[1/s, 0, cx], [0, 1/s, cy], [0, 0, 1]] acts on rows.
    ss, sd = prob.t_src[:, 0, 0, None], prob.t_dst[:, 0, 0, None]  # (B, 1)
    cs = -prob.t_src[:, :2, 2] / ss  # (B, 2) centroids
    cd = -prob.t_dst[:, :2, 2] / sd
    c0, c1 = hn[..., 0] * ss, hn[..., 1] * ss  # (B, 3) columns of Ĥ T_src
    c2 = hn[..., 2] - c0 * cs[:, :1] - c1 * cs[:, 1:]
    cols = torch.stack([c0, c1, c2], dim=-1)  # (B, 3, 3)
    h = torch.stack([cols[:, 0] / sd + cd[:, :1] * cols[:, 2],
                     cols[:, 1] / sd + cd[:, 1:] * cols[:, 2], cols[:, 2]], dim=1)
    h33 = h[..., 2, 2]
    ok = h33 != 0  # only 0 is undefined (pixel units: no absolute threshold)
    return h / torch.where(ok, h33, torch.ones_like(h33))[..., None, None]


# ---------------------------------------------------------------- optimizers


def _param_jacobian(fn, theta: torch.Tensor) -> torch.Tensor:
    """d vec(fn(θ)) / dθ, (B, 9, P), batched with torch.func (row-major vec)."""
    from torch.func import jacrev, vmap

    jac = vmap(jacrev(lambda t: fn(t[None], with_base=False)[0].flatten()))(theta)
    if fn.base is None:
        return jac
    # d vec(base · E) = base applied to each column block of d vec(E)
    return torch.einsum("bik,bkjp->bijp", fn.base, jac.unflatten(1, (3, 3))).flatten(1, 2)


def _spd_solve(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Solve ``a x = b`` for small SPD ``a`` (B, P, P), ``b`` (B, P) by Cholesky, batch last.

    Loops over the P <= 9 columns only; every operation acts on all B problems at
    once, which beats per-matrix LAPACK calls for thousands of 8x8 systems on CPU.
    Differentiable; a non-positive pivot is clamped (no NaN).
    """
    size = a.shape[-1]
    al, bl = a.permute(1, 2, 0), b.T  # (P, P, B), (P, B)
    tiny = torch.finfo(a.dtype).tiny
    cols = []  # cols[j] = L[j:, j], (P - j, B)
    for j in range(size):
        s = al[j:, j]
        for k in range(j):
            s = s - cols[k][j - k:] * cols[k][j - k]
        cols.append(s / s[0].clamp_min(tiny).sqrt())
    z, r = [], bl  # forward substitution, L z = b
    for j in range(size):
        z.append(r[0] / cols[j][0])
        r = r[1:] - cols[j][1:] * z[j]
    x = [None] * size  # back substitution, Lᵀ x = z
    for i in reversed(range(size)):
        rest = z[i]
        if i + 1 < size:
            rest = rest - (cols[i][1:] * torch.stack(x[i + 1:])).sum(0)
        x[i] = rest / cols[i][0]
    return torch.stack(x, dim=-1)


def _lm(fn, theta, prob, objective, steps, mu0, tol, bar, history):
    """Levenberg-Marquardt (Marquardt's diagonal scaling), per problem, unrolled."""
    constant_jac = None
    mu = torch.full_like(theta[:, 0], mu0)
    obj, loss = _loss_terms(fn(theta), prob, objective)
    for _ in bar:
        jtj, jtr = _system(fn(theta), prob, objective)  # wrt vec(Ĥ)
        if fn.model == "homography" and fn.parametrization == "entries":
            a, g = jtj[:, :8, :8], jtr[:, :8, None]  # d vec(Ĥ) / dθ selects 8 entries
        elif fn.linear:  # one constant (9, P) Jacobian: plain GEMMs, no tiny bmm
            if constant_jac is None:  # constant: taken at θ = 0 (also for an empty batch)
                constant_jac = _param_jacobian(fn, theta.new_zeros(1, theta.shape[-1]))[0]
            d = constant_jac
            a = (jtj @ d).mT @ d  # (B, P, P)
            g = (jtr @ d)[..., None]  # (B, P, 1)
        else:
            d = _param_jacobian(fn, theta)  # (B, 9, P)
            a = d.mT @ jtj @ d
            g = d.mT @ jtr[..., None]
        diag = a.diagonal(dim1=-2, dim2=-1)
        damp = mu[:, None] * diag + 1e-12 * diag.sum(-1, keepdim=True) + 1e-30
        step = -_spd_solve(a + torch.diag_embed(damp), g.squeeze(-1))  # (B, P)
        step = torch.where(torch.isfinite(step), step, torch.zeros_like(step))
        trial = theta + step
        obj_new, loss_new = _loss_terms(fn(trial), prob, objective)
        accept = obj_new < obj
        theta = torch.where(accept[:, None], trial, theta)
        decrease = torch.where(accept, obj - obj_new, torch.zeros_like(obj))
        obj = torch.where(accept, obj_new, obj)
        loss = torch.where(accept, loss_new, loss)
        mu = torch.where(accept, mu * 0.1, mu * 10.0).clamp(1e-12, 1e12)
        history.append(loss.detach())
        bar.set_postfix(loss=float(loss.detach().mean()))
        small = step.norm(dim=-1) <= math.sqrt(tol) * (1 + theta.norm(dim=-1))
        converged = ((decrease <= tol * obj) & small) | (obj <= 1e-30) | (mu >= 1e12)
        if bool(converged.all()):
            break
    return theta


def _gauss_newton_step(fn, theta, prob, objective):
    """One Gauss-Newton step from a detached optimum: carries the implicit gradient."""
    theta = theta.detach()
    with torch.no_grad():
        d = _param_jacobian(fn, theta)  # (B, 9, P)
        jtj, _ = _system(fn(theta), prob, objective)
        a = d.mT @ jtj @ d
        diag = a.diagonal(dim1=-2, dim2=-1)
        eye = torch.eye(theta.shape[-1], dtype=theta.dtype, device=theta.device)
        chol, _ = torch.linalg.cholesky_ex(a + 1e-12 * diag.sum(-1)[:, None, None] * eye)
    _, jtr = _system(fn(theta), prob, objective)  # attached to the inputs
    return theta - torch.cholesky_solve(d.mT @ jtr[..., None], chol).squeeze(-1)


def _first_order(kind, fn, theta, prob, objective, steps, lr, tol, patience, bar, history):
    if theta.shape[0] == 0:  # an empty batch: nothing to descend (torch's L-BFGS raises)
        return theta.detach()
    theta = theta.detach().clone().requires_grad_(True)
    prob_d = _Problem(*(t.detach() for t in prob))
    objective = objective._replace(c2_dst=objective.c2_dst.detach(),
                                   c2_src=objective.c2_src.detach())
    if kind == "adam":
        opt = torch.optim.Adam([theta], lr=lr)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(steps, 1),
                                                           eta_min=lr * 1e-3)
    else:
        # one iteration per step (for the history); max_eval leaves room for the line search
        opt = torch.optim.LBFGS([theta], lr=lr, max_iter=1, max_eval=25, history_size=20,
                                tolerance_grad=0.0, tolerance_change=0.0,
                                line_search_fn="strong_wolfe")
        sched = None
    with torch.no_grad():
        best, _ = _loss_terms(fn(theta), prob_d, objective)
    best_theta = theta.detach().clone()
    stale = 0
    for _ in bar:
        def closure():
            opt.zero_grad()
            obj, _ = _loss_terms(fn(theta), prob_d, objective)
            total = obj.sum()
            total.backward()
            return total

        with torch.enable_grad():
            opt.step(closure)
        if sched is not None:
            sched.step()
        with torch.no_grad():
            obj, loss = _loss_terms(fn(theta), prob_d, objective)
        history.append(loss)
        bar.set_postfix(loss=float(loss.mean()))
        improved = obj < best * (1 - tol)
        lower = obj < best  # keep the best iterate of each problem (Adam may overshoot)
        best_theta = torch.where(lower[:, None], theta.detach(), best_theta)
        best = torch.where(lower, obj, best)
        stale = 0 if bool(improved.any()) else stale + 1
        if stale >= patience or bool((obj <= 1e-30).all()):
            break
    return best_theta


class _ParamFn:
    """θ -> Ĥ for one model, with ``linear`` telling whether d vec(Ĥ)/dθ is constant."""

    def __init__(self, model: str, parametrization: str, base: torch.Tensor | None):
        self.model, self.parametrization, self.base = model, parametrization, base
        self.linear = model in ("affine", "similarity", "translation") or (
            model == "homography" and parametrization == "entries")

    def __call__(self, theta: torch.Tensor, with_base: bool = True) -> torch.Tensor:
        base = self.base if with_base else None
        return parameters_to_matrix(theta, self.model, self.parametrization, base)


def fit_transform(
    src: torch.Tensor,
    dst: torch.Tensor,
    model: str = "homography",
    optimizer: str = "lm",
    steps: int | None = None,
    init: torch.Tensor | None = None,
    parametrization: str = "entries",
    loss: str = "l2",
    weights: torch.Tensor | None = None,
    lr: float | None = None,
    tol: float | None = None,
    patience: int = 20,
    progress: bool = False,
    scale: float = 1.0,
    symmetric: bool = False,
) -> FitResult:
    """Fit ``dst_from_src`` of a ``model`` to correspondences by iterative optimization, batched.

    Every problem of the batch is fitted at once (the losses are independent, so
    Adam and LM treat each problem separately; L-BFGS sees their sum).

    Convention:
        Column vectors; ``dst ~ matrix @ [x, y, 1]ᵀ``. The loss is the weighted
        mean robust transfer error ``Σ w ρ(‖π(M p) - q‖²) / Σ w`` (plus
        ``Σ w ρ(‖π(M⁻¹ q) - p‖²) / Σ w`` if ``symmetric``), with ``ρ`` of
        ``robust_rho`` (this module) at ``scale`` (input units, pixels): ``"l2"`` is the
        plain mean squared error. It is optimized in the Hartley-normalized
        frame (the scale moves with it) and reported in input units squared.
        ``"lm"`` solves robust losses by iteratively reweighted least squares
        (the weights ``ρ'(r²)`` are recomputed at every LM iteration, and a step
        is accepted only if the robust cost decreases); ``"adam"``/``"lbfgs"``
        descend the robust cost directly. Robust losses need a good start
        (``init``, e.g. from :func:`find_transform_ransac`): Cauchy and Tukey
        are not convex. ``init=None``
        starts from the identity of the normalized frame (which maps the src
        centroid to the dst centroid). float16/bfloat16 inputs are fitted in
        float32 and the results returned in their dtype. Differentiable with
        respect to ``src``, ``dst`` and ``weights``: ``"lm"`` is unrolled (exact derivative of the
        result); ``"adam"`` and ``"lbfgs"`` run detached and, only when an
        input requires grad, end with one Gauss-Newton step that carries the
        implicit-function gradient (exact at a zero-residual optimum; the
        returned value then moves by that one refining step).

    Args:
        src: ``(*, N, 2)`` source points.
        dst: ``(*, N, 2)`` destination points.
        model: one of :data:`MODELS` (``"trs"`` is the report's ``T·R·Xs·Ys``).
        optimizer: ``"adam"``, ``"lbfgs"`` or ``"lm"`` (Levenberg-Marquardt).
        steps: maximum iterations (default: adam 200, lbfgs 50, lm 10).
        init: optional ``(*, 3, 3)`` starting ``dst_from_src``.
        parametrization: for ``model="homography"``: ``"entries"``, ``"corners"``
            (4-corner offsets) or ``"sl3"`` (Lie-algebra exponential).
        loss: ``"l2"``, ``"huber"``, ``"cauchy"`` or ``"tukey"`` (:data:`LOSSES`);
            ``"transfer"`` (= ``"l2"``) and ``"symmetric"`` (= ``"l2"`` with
            ``symmetric=True``) are kept for compatibility.
        weights: optional ``(*, N)`` non-negative weights.
        lr: learning rate (adam 0.05, lbfgs 1) or initial LM damping (1e-3).
        tol: relative improvement below which a problem counts as converged
            (default ``1000 * eps`` of the dtype: 2.2e-13 in float64, 1.2e-4 in float32).
        patience: adam/lbfgs stop after this many steps without improvement.
        progress: show a tqdm progress bar.
        scale: robust scale ``c`` in input units (pixels), > 0; unused by ``"l2"``.
        symmetric: add the backward transfer error.

    Returns:
        :class:`FitResult` ``(matrix (*, 3, 3), params (*, P), loss (*),
        history (steps_run + 1, *))``.

    Example:
        >>> from torchgeo_cg.transforms import homography, transform_points
        >>> h = homography(torch.tensor([0.27, 0, -0.85, -0.25, -0.2, 5.65, -0.02, -0.09],
        ...                             dtype=torch.float64))
        >>> src = torch.tensor([[0.0, 0], [4, 0], [4, 5], [0, 5], [2, 1]], dtype=torch.float64)
        >>> fit = fit_transform(src, transform_points(h, src), optimizer="lm")
        >>> torch.allclose(fit.matrix, h, atol=1e-9), fit.history.shape[0] <= 11
        (True, True)
    """
    weights = check_pair(src, dst, weights)
    if working_dtype(src.dtype) != src.dtype:  # float16/bfloat16: fitted in float32
        work = working_dtype(src.dtype)
        fit = fit_transform(src.to(work), dst.to(work), model, optimizer, steps,
                            None if init is None else check_float(init, "init").to(work),
                            parametrization, loss, None if weights is None else weights.to(work),
                            lr, tol, patience, progress, scale, symmetric)
        return FitResult(*(cast_back(t, src.dtype) for t in fit))
    check_choice(model, MODELS, "model")
    check_choice(optimizer, _DEFAULT_STEPS, "optimizer")
    check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
    check_choice(loss, (*LOSSES, "transfer", "symmetric"), "loss")
    scale = float(scale)
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale: expected a finite positive number of pixels, got {scale!r}")
    steps = _DEFAULT_STEPS[optimizer] if steps is None else steps
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise ValueError(f"steps: expected a non-negative int, got {steps!r}")
    lr = _DEFAULT_LR[optimizer] if lr is None else float(lr)
    tol = 1000 * torch.finfo(src.dtype).eps if tol is None else float(tol)
    batch, n = src.shape[:-2], src.shape[-2]
    p_in, q_in = src.reshape(-1, n, 2), dst.reshape(-1, n, 2)
    w = effective_weights(p_in, None if weights is None else weights.reshape(-1, n))
    prob = _normalize(p_in, q_in, w, model)
    base = None
    if init is not None:
        check_shape(init, ["*", "3", "3"], "init")
        check_float(init, "init")
        init = init.to(src).expand(*batch, 3, 3).reshape(-1, 3, 3)
        init_n = prob.t_dst @ init @ inverse(prob.t_src)
        theta = matrix_to_parameters(init_n, model, parametrization).detach()
        if model == "homography" and parametrization == "sl3":
            base = init_n.detach()
    else:
        theta = src.new_zeros(p_in.shape[0], MODELS[model])
    fn = _ParamFn(model, parametrization, base)
    symmetric = bool(symmetric) or loss == "symmetric"
    kind = "l2" if loss in ("transfer", "symmetric") else loss
    objective = _Objective(symmetric, kind, (scale * prob.scale_dst).square(),
                           (scale * prob.scale_src).square())
    from tqdm.auto import tqdm

    bar = tqdm(range(steps), disable=not progress, desc=f"fit {model} ({optimizer})")
    with torch.no_grad():
        history = [_loss_terms(fn(theta), prob, objective)[1]]
    if optimizer == "lm":
        theta = _lm(fn, theta, prob, objective, steps, lr, tol, bar, history)
    else:
        theta = _first_order(optimizer, fn, theta, prob, objective, steps, lr, tol, patience,
                             bar, history)
        if torch.is_grad_enabled() and any(
            t.requires_grad for t in (src, dst, weights) if t is not None
        ):
            theta = _gauss_newton_step(fn, theta, prob, objective)
    bar.close()
    hn = fn(theta)
    matrix = _denormalize(hn, prob)
    _, final = _loss_terms(hn, prob, objective)
    return FitResult(
        matrix.reshape(*batch, 3, 3),
        theta.reshape(*batch, theta.shape[-1]),
        final.reshape(batch),
        torch.stack([h.detach() for h in history]).reshape(len(history), *batch),
    )


class HomographyModel(nn.Module):
    """A learnable homography ``dst_from_src`` with the parametrizations of :func:`fit_transform`.

    ``matrix() = T_dst⁻¹ Ĥ(params) T_src`` where ``T_src``/``T_dst`` are Hartley
    normalizations (buffers, identity unless ``src``/``dst`` are given) and
    ``Ĥ = parameters_to_matrix(params, "homography", parametrization, base)``.

    Convention:
        Column vectors; ``forward(points)`` is ``transform_points(matrix(), points)``.
        ``params`` is an ``nn.Parameter`` of shape ``(*batch_shape, 8)``, zero
        (the identity, or ``init``) at construction; the normalizations and the
        ``sl3`` base are non-persistent buffers, so ``.to()`` moves everything.

    Args:
        parametrization: ``"entries"``, ``"corners"`` or ``"sl3"`` (same default as
            :func:`fit_transform`).
        batch_shape: leading shape of the parameters (one homography per item).
        src: optional ``(*batch_shape, N, 2)`` points defining ``T_src`` (``N >= 1``,
            else ``ShapeError``).
        dst: optional ``(*batch_shape, N, 2)`` points defining ``T_dst``.
        init: optional ``(*batch_shape, 3, 3)`` starting ``dst_from_src``.
        device: device of the parameters (when no tensor is given).
        dtype: dtype of the parameters (when no tensor is given).

    Example:
        >>> model = HomographyModel()
        >>> model(torch.tensor([[1.0, 2.0]])).detach()
        tensor([[1., 2.]])
        >>> model.params.shape
        torch.Size([8])
    """

    def __init__(
        self,
        parametrization: str = "entries",
        batch_shape: tuple[int, ...] = (),
        src: torch.Tensor | None = None,
        dst: torch.Tensor | None = None,
        init: torch.Tensor | None = None,
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__()
        check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
        self.parametrization = parametrization
        given = [(name, t) for name, t in (("src", src), ("dst", dst), ("init", init))
                 if t is not None]
        for name, t in given[1:]:
            if t.dtype != given[0][1].dtype:
                raise TypeError(f"{name}: expected the dtype of {given[0][0]} "
                                f"({given[0][1].dtype}), got {t.dtype}")
        ref = given[0][1] if given else None
        kw = {"device": device if ref is None else ref.device,
              "dtype": (dtype or torch.get_default_dtype()) if ref is None else ref.dtype}
        batch_shape = tuple(batch_shape)
        eye = torch.eye(3, **kw).expand(*batch_shape, 3, 3)
        t_src, t_dst = eye, eye
        for name, pts in (("src", src), ("dst", dst)):
            if pts is None:
                continue
            check_shape(pts, [*map(str, batch_shape), "N", "2"], name)
            check_float(pts, name)
            check_points_nonempty(pts, name)  # no normalization of zero points (was NaN)
            t = hartley_weighted(pts, torch.ones_like(pts[..., 0])).transform
            t_src, t_dst = (t, t_dst) if name == "src" else (t_src, t)
        self.register_buffer("src_transform", t_src.clone(), persistent=False)
        self.register_buffer("dst_transform", t_dst.clone(), persistent=False)
        params = torch.zeros(*batch_shape, 8, **kw)
        base = None
        if init is not None:
            check_shape(init, [*map(str, batch_shape), "3", "3"], "init")
            check_float(init, "init")
            init_n = t_dst @ init.to(**kw) @ inverse(t_src)
            params = matrix_to_parameters(init_n, "homography", parametrization)
            if parametrization == "sl3":
                base = init_n
        self.register_buffer("base", base, persistent=False)
        self.params = nn.Parameter(params.detach().clone())

    def matrix(self) -> torch.Tensor:
        """The current ``(*batch_shape, 3, 3)`` ``dst_from_src``.

        Example:
            >>> HomographyModel(batch_shape=(2,)).matrix().shape
            torch.Size([2, 3, 3])
        """
        hn = parameters_to_matrix(self.params, "homography", self.parametrization, self.base)
        h = inverse(self.dst_transform) @ hn @ self.src_transform
        h33 = h[..., 2, 2]
        return h / torch.where(h33 != 0, h33, torch.ones_like(h33))[..., None, None]

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """Transform ``points`` ``(*batch_shape, N, 2)`` -> ``(*batch_shape, N, 2)``."""
        check_shape(points, ["*", "N", "2"], "points")
        return transform_points(self.matrix(), points)

