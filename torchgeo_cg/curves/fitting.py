"""Least-squares Bezier fitting (report section 1.2; glyph outlines as in section 1.1).

Convention:
    - Points ``(*, M, D)`` are samples along one curve each, in order.
    - Parameters are assigned before solving: ``"uniform"`` (``k / (M - 1)``),
      ``"chord"`` (cumulative chord length, normalised to ``[0, 1]``) or
      ``"centripetal"`` (cumulative square-root chord length). A curve whose
      points all coincide falls back to uniform parameters.
    - The fit minimises ``sum_k |B(t_k) - x_k|^2`` over the control points; it is a
      batched linear least-squares problem solved in float64 (upcast, then cast
      back) and is differentiable with respect to the points. Chord and
      centripetal parameters are computed without gradients (treated as
      constants), so the gradient is the one at fixed parameters.
    - With ``correct_parameters=True`` each sample's parameter is then improved by
      safeguarded Newton steps on ``|B(t_k) - x_k|^2`` alternating with the solve
      (Hoschek's "parameter correction", Plass & Stone 1983), until the rms improves by
      less than ``tol`` (relative) or ``max_iterations`` solves. The parameters end up
      (locally) orthogonal: ``(B(t_k) - x_k) . B'(t_k) = 0``, so the gradient at fixed
      parameters is also the gradient of the optimal residual (envelope theorem).
    - Ragged batches: a list of ``(M_i, D)`` tensors, a nested tensor, or a padded
      ``(*, M, D)`` tensor with ``lengths (*,)``; padded rows are ignored and get
      ``t = 0``.
    - NaN in, NaN out per stroke: a NaN point or weight gives its stroke NaN
      parameters (chord, centripetal), control points and rms; the other strokes of
      the batch are unaffected. Coincident parameters (a singular system) give the
      minimum-norm least-squares control points.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import ShapeError, check_choice
from torchgeo_cg.core.numerics import safe_sqrt
from torchgeo_cg.curves._strokes import (
    PARAMETRIZATIONS,
    as_padded_strokes,
    fit_parameters,
    stroke_parameters,
)

__all__ = ["BezierFit", "fit_parameters", "fit_bezier"]


class BezierFit(NamedTuple):
    """Result of :func:`fit_bezier`.

    Attributes:
        control_points: ``(*, n + 1, D)``.
        t: ``(*, M)`` the parameters used.
        rms: ``(*)`` root-mean-square distance between ``B(t_k)`` and the points
            (weighted by ``weights`` when given: ``sqrt(sum w |r|^2 / sum w)``).

    Example:
        >>> fit = fit_bezier(torch.tensor([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]), 1)
        >>> fit.control_points.round(decimals=6) + 0.0, fit.t
        (tensor([[0.0000, 0.0000],
                [2.0000, 2.0000]]), tensor([0.0000, 0.5000, 1.0000]))
    """

    control_points: torch.Tensor
    t: torch.Tensor
    rms: torch.Tensor


def _degree(degree: object) -> int:
    if isinstance(degree, bool) or not isinstance(degree, int):
        raise TypeError(f"degree: expected an int, got {type(degree).__name__}")
    if degree < 0:
        raise ValueError(f"degree: expected a non-negative degree, got {degree}")
    return degree


def _bases(t: torch.Tensor, degree: int) -> torch.Tensor:
    """Bernstein basis ``(n + 1, *, M)`` at ``t`` (degree first, for cheap reductions)."""
    basis = [torch.ones_like(t)]
    for _ in range(degree):  # loop over degrees: b_{k,n} = (1-t) b_{k,n-1} + t b_{k-1,n-1}
        nxt = [(1 - t) * basis[0]]
        nxt += [(1 - t) * basis[k] + t * basis[k - 1] for k in range(1, len(basis))]
        basis = nxt + [t * basis[-1]]
    return torch.stack(basis)


def _solve(t, points, w, degree: int) -> torch.Tensor:
    """Weighted least-squares control points ``(*, n + 1, D)`` (call in float64).

    Normal equations ``(A^T W A) c = A^T W x`` solved by LU (small ``(n+1)^2`` systems,
    much faster than a batched ``lstsq``); the strokes whose system is singular
    (coincident parameters) fall back to the pseudo-inverse (minimum-norm solution). A stroke
    with a non-finite point, weight or parameter gets NaN control points (its system is
    replaced by the identity first, so it cannot break the solver or the other
    strokes). The products are elementwise sums, not BLAS calls: tiny float64 GEMMs are
    slow and, with several threads on a busy machine, erratic.
    """
    batch, (m, d) = t.shape[:-1], points.shape[-2:]
    t, points, w = t.reshape(-1, m), points.reshape(-1, m, d), w.reshape(-1, m)  # flat batch
    basis_k = _bases(t, degree)  # (K, B, M)
    weighted_k = basis_k * w
    gram = (weighted_k[:, None] * basis_k[None]).sum(-1).movedim(0, -1).movedim(0, -1)
    points_d = points.movedim(-1, 0)  # (D, *, M)
    rhs = (weighted_k[:, None] * points_d[None]).sum(-1).movedim(0, -1).movedim(0, -1)
    bad = ~(torch.isfinite(gram).all(-1).all(-1) & torch.isfinite(rhs).all(-1).all(-1))  # (B,)
    eye = torch.eye(degree + 1, dtype=gram.dtype, device=gram.device)
    gram = torch.where(bad[..., None, None], eye, gram)
    rhs = torch.where(bad[..., None, None], 0.0, rhs)
    solution, info = torch.linalg.solve_ex(gram, rhs)
    singular = (info != 0) | ~torch.isfinite(solution).all(-1).all(-1)  # (B,)
    if bool(singular.any()):
        root_w = w[singular].sqrt().unsqueeze(-1)
        basis = basis_k.movedim(0, -1)[singular]
        # pseudo-inverse (SVD, scale-free cut-off): the minimum-norm solution on every
        # device; lstsq's default CPU driver (gelsy) returns a non-solution here
        fallback = torch.linalg.pinv(basis * root_w) @ (points[singular] * root_w)
        solution = solution.index_put((singular,), fallback)
    solution = torch.where(bad[..., None, None], torch.nan, solution)
    return solution.reshape(*batch, degree + 1, d)


def _evaluate(cp: torch.Tensor, basis_k: torch.Tensor) -> torch.Tensor:
    """Curve points ``(D, *, M)`` from control points ``(*, K, D)`` and basis ``(K, *, M)``."""
    cp_kd = cp.movedim(-2, 0).movedim(-1, 1).unsqueeze(-1)  # (K, D, *, 1)
    return (basis_k[:, None] * cp_kd).sum(0)


def _power_coefficients(cp: torch.Tensor) -> torch.Tensor:
    """Monomial coefficients ``(n + 1, D, *, 1)`` of Bezier control points ``(*, n + 1, D)``.

    ``B(t) = sum_j a_j t^j`` with ``a_j = C(n, j) sum_{i<=j} (-1)^(j-i) C(j, i) c_i``.
    """
    n = cp.shape[-2] - 1
    table = [[math.comb(n, j) * math.comb(j, i) * (-1) ** (j - i) if i <= j else 0
              for i in range(n + 1)] for j in range(n + 1)]
    convert = torch.tensor(table, dtype=cp.dtype, device=cp.device)  # (K, K)
    cp_kd = cp.movedim(-2, 0).movedim(-1, 1)  # (K, D, *)
    extra = (1,) * (cp_kd.dim() - 1)
    return (convert.view(n + 1, n + 1, *extra) * cp_kd[None]).sum(1).unsqueeze(-1)


def _horner(a: torch.Tensor, t: torch.Tensor, order: int) -> torch.Tensor:
    """``order``-th derivative ``(D, *, M)`` of ``sum_j a_j t^j`` by Horner's rule."""
    n = a.shape[0] - 1
    if order > n:
        return torch.zeros_like(a[0] * t)
    value = a[n] * math.perm(n, order)
    for j in range(n - 1, order - 1, -1):  # loop over degrees
        value = value * t + a[j] * math.perm(j, order)
    return value


def _newton(cp, t, points_d, degree: int) -> tuple[torch.Tensor, torch.Tensor]:
    """One safeguarded Newton step on every ``t_k`` for ``|B(t_k) - x_k|^2`` (float64).

    ``points_d`` is ``(D, *, M)``. Newton where ``f'' > 0``, else Gauss-Newton
    (``f'' ~ |B'|^2``). The trials are 2, 1, 1/2 and 1/4 Newton steps, the best that
    decreases the residual is kept: alternating with the solve, a plain Newton step
    under-corrects ``t`` (the control points follow each move), so the doubled trial is the
    one usually kept and the alternation converges in fewer iterations.
    Returns the new parameters and the squared residuals ``(*, M)`` at the old ones.
    """
    a = _power_coefficients(cp)
    r = _horner(a, t, 0) - points_d
    d1 = _horner(a, t, 1)
    d2 = _horner(a, t, 2)
    grad = (r * d1).sum(0)
    speed2 = (d1 * d1).sum(0)
    hess = speed2 + (r * d2).sum(0)
    hess = torch.where(hess > 0, hess, speed2)
    step = torch.where(hess > 0, -2 * grad / torch.where(hess > 0, hess, 1.0), 0.0)
    best_t, best_r2 = t, r.square().sum(0)
    for _ in range(4):  # backtracking halvings (a loop over attempts, not samples)
        trial = (t + step).clamp(0, 1)
        trial_r2 = (_horner(a, trial, 0) - points_d).square().sum(0)
        better = trial_r2 < best_r2
        best_t = torch.where(better, trial, best_t)
        best_r2 = torch.where(better, trial_r2, best_r2)
        step = 0.5 * step
    return best_t, r.square().sum(0)


def _rms(cp, t, points, w, degree: int) -> torch.Tensor:
    r2 = (_evaluate(cp, _bases(t, degree)) - points.movedim(-1, 0)).square().sum(0)
    total_w = w.sum(-1)
    mean = (w * r2).sum(-1) / torch.where(total_w > 0, total_w, 1.0)
    return safe_sqrt(mean, eps=0.0)


def _correct(t, points64, w64, degree, tol, max_iterations, progress):
    """Alternate solve and Newton steps on ``t`` until the rms stalls (float64, no grad).

    Each stroke stops on its own, as soon as its rms improves by less than ``tol``
    (relative) in one iteration; later iterations only process the strokes still running,
    so a batch gives the same result as a loop over its strokes.
    """
    from tqdm.auto import tqdm

    batch = t.shape[:-1]
    m, d = points64.shape[-2:]
    t_sm = t.reshape(-1, m).clone()
    p_smd, w_sm = points64.reshape(-1, m, d), w64.reshape(-1, m)
    active = torch.arange(t_sm.shape[0], device=t.device)
    previous = None
    bar = tqdm(range(max_iterations), disable=not progress, desc="fit_bezier", unit="it")
    for _ in bar:  # loop over iterations
        t_a, p_a, w_a = t_sm[active], p_smd[active], w_sm[active]
        cp = _solve(t_a, p_a, w_a, degree)
        t_new, r2 = _newton(cp, t_a, p_a.movedim(-1, 0), degree)
        rms = ((w_a * r2).sum(-1) / w_a.sum(-1).clamp_min(torch.finfo(w_a.dtype).tiny)).sqrt()
        if previous is not None:
            going = (previous - rms) > tol * previous
            bar.set_postfix(running=int(going.sum()))
            active, t_new, rms = active[going], t_new[going], rms[going]
            if active.numel() == 0:
                break
        previous = rms
        t_sm[active] = t_new
    bar.close()
    return t_sm.reshape(*batch, m)


def fit_bezier(
    points,
    degree: int,
    parametrization: str = "chord",
    correct_parameters: bool = False,
    tol: float = 3e-5,
    max_iterations: int = 100,
    weights=None,
    lengths=None,
    progress: bool = False,
) -> BezierFit:
    """Fit one Bezier curve of ``degree`` to each ordered point set by least squares.

    Convention:
        See the module docstring. ``M >= degree + 1`` points are needed for a
        unique solution; fewer raise :class:`ShapeError`. Minimises
        ``sum_k w_k |B(t_k) - x_k|^2`` (``w_k = 1`` by default).

    Args:
        points: ``(*, M, D)``, a list of ``(M_i, D)`` tensors, or a nested tensor.
        degree: ``n >= 0``.
        parametrization: initial parameters, ``"uniform"``, ``"chord"`` or ``"centripetal"``.
        correct_parameters: improve each ``t_k`` by safeguarded Newton steps
            alternating with the solve (see the module docstring).
        tol: relative rms improvement below which the correction stops.
        max_iterations: most solves of the correction.
        weights: ``(*, M)`` non-negative per-sample weights (a list for list input),
            cast to the dtype of ``points``; a NaN weight gives its stroke NaN results.
        lengths: ``(*,)`` valid rows of each stroke of a padded ``points`` tensor.
        progress: show a tqdm progress bar over the correction iterations.

    Returns:
        :class:`BezierFit` ``(control_points (*, n + 1, D), t (*, M), rms (*))``; for
        list input ``*`` is the number of strokes and ``M`` the longest.

    Example:
        >>> t = torch.linspace(0, 1, 9, dtype=torch.float64)
        >>> parabola = torch.stack([t, t * t], dim=-1)
        >>> fit = fit_bezier(parabola, 2, parametrization="uniform")
        >>> fit.control_points.round(decimals=6) + 0.0
        tensor([[0.0000, 0.0000],
                [0.5000, 0.0000],
                [1.0000, 1.0000]], dtype=torch.float64)
        >>> bool(fit.rms < 1e-12)
        True
        >>> s = torch.linspace(0, 1, 9, dtype=torch.float64) ** 2  # uneven sampling
        >>> quarter = torch.stack([torch.cos(s), torch.sin(s)], -1)
        >>> chord = fit_bezier(quarter, 2).rms
        >>> corrected = fit_bezier(quarter, 2, correct_parameters=True).rms
        >>> bool(corrected < 0.2 * chord)
        True
    """
    degree = _degree(degree)
    check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
    if not (isinstance(max_iterations, int) and max_iterations >= 1):
        raise ValueError(f"max_iterations: expected a positive int, got {max_iterations!r}")
    if not tol >= 0:
        raise ValueError(f"tol: expected a non-negative number, got {tol}")
    points, valid, weights = as_padded_strokes(points, lengths, weights)
    least = int(valid.sum(-1).min()) if valid.numel() else degree + 1
    if least < degree + 1:
        raise ShapeError(
            f"points: fitting degree {degree} needs at least degree + 1 = {degree + 1} points, "
            f"got {least} (shape {tuple(points.shape)})"
        )
    points = torch.where(valid[..., None], points, 0.0)  # padded rows are ignored, NaN too
    t = stroke_parameters(points, valid, parametrization)
    w = valid.to(points.dtype) if weights is None else torch.where(valid, weights, 0.0)
    if correct_parameters:
        with torch.no_grad():
            t64 = _correct(t.double(), points.detach().double(), w.double(), degree, tol,
                           max_iterations, progress)
            t = torch.where(valid, t64.to(points.dtype), 0.0)
    cp64 = _solve(t.double(), points.double(), w.double(), degree)  # differentiable
    control_points = cp64.to(points.dtype)
    rms = _rms(control_points, t, points, w, degree)
    return BezierFit(control_points, t, rms)
