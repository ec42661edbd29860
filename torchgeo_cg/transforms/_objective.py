"""The objective of iterative transform fitting: the normalized problem, the robust transfer
error and its Gauss-Newton normal equations, batch last.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.transforms._correspondences import hartley_weighted, similarity_matrix
from torchgeo_cg.transforms._dlt import DLT_M_INDEX, DLT_M_SIGN
from torchgeo_cg.transforms.homogeneous import inverse
from torchgeo_cg.transforms.robust import robust_loss, robust_weights


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


class Objective(NamedTuple):
    symmetric: bool
    kind: str  # one of LOSSES
    c_dst: torch.Tensor | None  # (B,) robust scale in the normalized dst frame
    c_src: torch.Tensor | None  # (B,) the same in the normalized src frame


def irls_weights(h, p, q, wn, kind, c):
    """Weights (N, B) of the IRLS step at ``h``: ``wn ρ'(s)``."""
    if kind == "l2":
        return wn
    return wn * robust_weights(_squared_transfer(h, p, q), kind, c)


def normal_system(hn, prob, objective: Objective):
    """``JᵀJ`` (B, 9, 9) and ``Jᵀr`` (B, 9) of the (IRLS-reweighted) objective wrt vec(Ĥ)."""
    kind = objective.kind
    wn = irls_weights(hn, prob.p, prob.q, prob.wn, kind, objective.c_dst)
    jtj, jtr = _normal_equations(hn, prob.p, prob.q, wn)
    if objective.symmetric:
        g = inverse(hn)
        wn_b = irls_weights(g, prob.q, prob.p, prob.wn, kind, objective.c_src)
        jtj_b, jtr_b = _normal_equations(g, prob.q, prob.p, wn_b)
        # dG = -G dĤ G: d vec(G)_ij / d vec(Ĥ)_kl = -G_ik G_lj
        dg = -torch.einsum("bik,blj->bijkl", g, g).flatten(1, 2).flatten(2, 3)  # (B, 9, 9)
        jtj = jtj + dg.mT @ jtj_b @ dg
        jtr = jtr + (dg.mT @ jtr_b[..., None]).squeeze(-1)
    return jtj, jtr


class Problem(NamedTuple):
    p: torch.Tensor  # (2, N, B) normalized src, batch last
    q: torch.Tensor  # (2, N, B) normalized dst
    wn: torch.Tensor  # (N, B) weights / Σ weights
    t_src: torch.Tensor  # (B, 3, 3)
    t_dst: torch.Tensor
    scale_src: torch.Tensor  # (B,)
    scale_dst: torch.Tensor


def normalize_problem(src, dst, w, model: str) -> Problem:
    ns, nd = hartley_weighted(src, w), hartley_weighted(dst, w)
    wn = (w / w.sum(-1, keepdim=True)).T.contiguous()  # (N, B)

    def last(points):  # (B, N, 2) -> (2, N, B)
        return points.permute(2, 1, 0).contiguous()

    if model in ("homography", "affine"):
        return Problem(last(ns.points), last(nd.points), wn, ns.transform, nd.transform,
                        ns.scale, nd.scale)
    # one shared scale keeps similarity/euclidean/translation/trs in their class
    scale = 2.0 / (1.0 / ns.scale + 1.0 / nd.scale)
    t_src, t_dst = similarity_matrix(scale, ns.centroid), similarity_matrix(scale, nd.centroid)
    p = (src - ns.centroid[..., None, :]) * scale[..., None, None]
    q = (dst - nd.centroid[..., None, :]) * scale[..., None, None]
    return Problem(last(p), last(q), wn, t_src, t_dst, scale, scale)


def loss_terms(hn, prob: Problem, objective: Objective):
    """(objective (B,) in normalized units, loss (B,) in input units)."""
    kind = objective.kind
    fwd = (robust_loss(_squared_transfer(hn, prob.p, prob.q), kind, objective.c_dst)
           * prob.wn).sum(0)
    loss = fwd / prob.scale_dst.square()
    if objective.symmetric:
        bwd = (robust_loss(_squared_transfer(inverse(hn), prob.q, prob.p), kind,
                          objective.c_src) * prob.wn).sum(0)
        return fwd + bwd, loss + bwd / prob.scale_src.square()
    return fwd, loss


def denormalize(hn: torch.Tensor, prob: Problem) -> torch.Tensor:
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
