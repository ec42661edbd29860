"""Iterative closest point registration of point clouds, batched and ragged.

Each iteration matches every valid source point, moved by the current transform, to
its exact nearest target point (:mod:`~torchgeo_cg.points._search_grid`, with the
target's grid built once per call and reused by every iteration), rejects matches
farther than ``max_distance``, weighs the rest by a robust loss (IRLS) and solves for
the transform: weighted Procrustes for ``"point_to_point"`` (closed form), one
Gauss-Newton step for ``"point_to_plane"``. All ``B`` pairs iterate together; a pair
that has converged keeps its transform while the others go on.

Convention:
    - ``transform`` maps the source onto the target: ``target ~ transform @ source``
      (column vectors, homogeneous ``(*, 4, 4)``).
    - Convergence is relative: a pair stops when its update moves the valid source
      points by at most ``tol`` times their RMS radius about their centroid (RMS over
      the points), or when it moves them by at most ``sqrt(tol)`` times that radius,
      keeps the number of inlier matches and lowers their RMSE by at most ``tol`` times
      itself (or raises it): the matches of noisy scans can cycle between neighbours
      with a small motion that never dies out. (Open3D stops on the changes of fitness
      and RMSE, in absolute units.) No absolute epsilon.
    - ``rmse`` is the root mean square point-to-point distance over the inlier
      matches (those within ``max_distance``), ``inlier_fraction`` their share of
      the valid source points, as Open3D's ``inlier_rmse`` and ``fitness``.
    - Robust losses with ``scale=None`` estimate the scale of each pair at each
      iteration as ``1.4826 * median |r|`` of its inlier residuals (their mean where
      the median is 0), times the loss's
      95%-efficiency constant (Huber 1.345, Cauchy 2.385, Tukey 4.685). Tukey gives
      zero weight beyond its scale, so it needs a rough initial alignment (a start
      whose residuals on the true matches are within a few scales); Cauchy and Huber
      tolerate a poor start. Against many outliers (30% uniform in the box, no
      ``max_distance``) pair Cauchy with ``"point_to_plane"``: point-to-point steps move
      only part of the way to the optimum, and with the outliers' pull it needs far more
      than 40 iterations.
    - Differentiable: the returned ``transform`` is the solve on the last
      correspondences (indices and robust weights held constant), recomputed with
      gradients w.r.t. ``source``, ``target`` and ``target_normals``; ``rmse`` follows
      from it. ``iterations``, ``converged`` and the matches have no gradient.
    - Scale-free: the search runs on coordinates divided by a power of two per pair
      (exact), the solves have no unit, so ``s * source``, ``s * target`` (and
      ``s * max_distance``, ``s * scale``) give the same rotation, ``s`` times the
      translation and ``s`` times the RMSE.
    - A pair with a NaN or inf among its valid points (or in ``init``) gets NaN
      ``transform`` and ``rmse``. An empty source or target gives ``init`` (identity
      by default), ``rmse = 0``, ``inlier_fraction = 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_broadcastable, check_choice, check_float, check_shape
from torchgeo_cg.core.numerics import cast_back, safe_sqrt, working_dtype
from torchgeo_cg.engine import kernel_ready, resolve_backend
from torchgeo_cg.points._icp_steps import (
    apply_transform,
    dot3,
    point_to_plane_step,
    weighted_sum,
)
from torchgeo_cg.points._knn_kernels import kernel_grids, warp_knn_indices
from torchgeo_cg.points._search import check_lengths, search_scale
from torchgeo_cg.points._search_grid import build_grid, grid_knn_indices, grid_per_cell
from torchgeo_cg.points.normals import estimate_normals
from torchgeo_cg.transforms.estimation import find_euclidean, find_similarity
from torchgeo_cg.transforms.robust import LOSSES, robust_weights

__all__ = ["ICPConvergence", "ICPResult", "ICPRobust", "icp", "METHODS", "MODELS"]

#: Error functions of :func:`icp`.
METHODS: tuple[str, ...] = ("point_to_point", "point_to_plane")
#: Transform models of :func:`icp`.
MODELS: tuple[str, ...] = ("euclidean", "similarity")
#: Neighbours of the PCA normals :func:`icp` estimates for point-to-plane.
_NORMAL_NEIGHBOURS = 10
#: Grid levels of the kernel search: the first matches of a rough start lie far off
#: the target, where a coarser grid crosses fewer empty cells.
_KERNEL_LEVELS = 2
#: 95%-efficiency constants of the robust losses (in units of the residual's sigma).
_EFFICIENCY = {"huber": 1.345, "cauchy": 2.385, "tukey": 4.685}


@dataclass(frozen=True)
class ICPConvergence:
    """When :func:`icp` stops (Open3D's ``ICPConvergenceCriteria``, with one relative test).

    Attributes:
        max_iterations: at most this many updates, ``>= 0``.
        tol: a pair has converged when an update moves its valid source points by at most
            ``tol`` times their RMS radius about their centroid, or by at most
            ``sqrt(tol)`` times it while keeping the number of inliers and lowering their
            RMSE by at most ``tol`` times itself; ``> 0``.

    Example:
        >>> ICPConvergence(max_iterations=60).tol
        1e-06
        >>> ICPConvergence(tol=0)
        Traceback (most recent call last):
        ...
        ValueError: tol: expected a finite positive number, got 0
    """

    max_iterations: int = 30
    tol: float = 1e-6

    def __post_init__(self):
        _check_positive(self.tol, "tol", allow_none=False)
        it = self.max_iterations
        if isinstance(it, bool) or not isinstance(it, int) or it < 0:
            raise ValueError(f"max_iterations: expected a non-negative int, got {it!r}")


@dataclass(frozen=True)
class ICPRobust:
    """The robust loss of :func:`icp`'s IRLS weights (Open3D's robust kernels).

    Attributes:
        loss: ``"l2"``, ``"huber"``, ``"cauchy"`` or ``"tukey"``.
        scale: the loss's scale ``c``, a length; None: estimated per pair and iteration
            (see :mod:`torchgeo_cg.points.icp`).

    Example:
        >>> ICPRobust("cauchy").scale is None
        True
        >>> ICPRobust("l1")
        Traceback (most recent call last):
        ...
        ValueError: loss: expected one of 'l2', 'huber', 'cauchy', 'tukey', got 'l1'
    """

    loss: str = "l2"
    scale: float | None = None

    def __post_init__(self):
        check_choice(self.loss, LOSSES, "loss")
        _check_positive(self.scale, "scale")


class ICPResult(NamedTuple):
    """Result of :func:`icp`.

    Attributes:
        transform: ``(*, 4, 4)`` target-from-source homogeneous matrices.
        rmse: ``(*,)`` RMS distance of the inlier matches at ``transform``.
        inlier_fraction: ``(*,)`` share of the valid source points with an inlier match.
        iterations: ``(*,)`` long, iterations run per pair.
        converged: ``(*,)`` bool, the relative test passed within ``max_iterations``.

    Example:
        >>> target = torch.rand(200, 3, generator=torch.Generator().manual_seed(1),
        ...                     dtype=torch.float64)
        >>> res = icp(target + torch.tensor([0.01, 0.0, 0.0], dtype=torch.float64), target)
        >>> res.transform[:3, 3].round(decimals=9) + 0.0  # the shift undone
        tensor([-0.0100,  0.0000,  0.0000], dtype=torch.float64)
        >>> float(res.inlier_fraction), bool(res.converged)
        (1.0, True)
    """

    transform: torch.Tensor
    rmse: torch.Tensor
    inlier_fraction: torch.Tensor
    iterations: torch.Tensor
    converged: torch.Tensor


class _Pairs(NamedTuple):
    """Flattened, cleaned float64 inputs, normalised by the power of two ``scale_b``."""

    src: torch.Tensor  # (B, N, 3)
    tgt: torch.Tensor  # (B, M, 3)
    normals: torch.Tensor | None  # (B, M, 3)
    src_valid: torch.Tensor  # (B, N) bool
    sl: torch.Tensor  # (B,)
    tl: torch.Tensor  # (B,)
    scale_b: torch.Tensor  # (B,)
    bad_b: torch.Tensor  # (B,) non-finite input
    init: torch.Tensor  # (B, 4, 4), normalised


def _check_positive(value, name, allow_none=True):
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: expected a finite positive number, got {value!r}")


def _check_arguments(source, target, init, target_normals, method, model, options):
    check_float(source, "source")
    check_float(target, "target")
    ss = check_shape(source, ["*", "N", "3"], "source")
    st = check_shape(target, ["*", "M", "3"], "target")
    if source.dtype != target.dtype:
        raise TypeError(f"target: expected dtype {source.dtype} (of source), got {target.dtype}")
    shapes = {"source": ss["*"], "target": st["*"]}
    for name, x, pattern in (("init", init, ["*", "4", "4"]),
                             ("target_normals", target_normals, ["*", "M", "3"])):
        if x is not None:
            check_float(x, name)
            shapes[name] = check_shape(x, pattern, name, {"M": st["M"]})["*"]
            if x.dtype != source.dtype:
                raise TypeError(f"{name}: expected dtype {source.dtype} (of source), "
                                f"got {x.dtype}")
    check_choice(method, METHODS, "method")
    check_choice(model, MODELS, "model")
    _check_positive(options["max_distance"], "max_distance")
    for name, kind in (("robust", ICPRobust), ("convergence", ICPConvergence)):
        if not isinstance(options[name], kind):
            raise TypeError(f"{name}: expected a {kind.__name__}, got "
                            f"{type(options[name]).__name__}")
    return check_broadcastable(shapes), ss["N"], st["M"]


def _flatten(x, batch, tail):
    return x.expand(*batch, *tail).reshape(math.prod(batch), *tail)


def _prepare(source, target, init, target_normals, sl, tl, batch) -> _Pairs:
    """Flatten, mask non-finite pairs, divide by a power of two per pair (exact)."""
    B = math.prod(batch)
    N, M = source.shape[-2], target.shape[-2]
    src = _flatten(source.detach(), batch, (N, 3)).double()
    tgt = _flatten(target.detach(), batch, (M, 3)).double()
    sl_b, tl_b = sl.reshape(B), tl.reshape(B)
    src_valid = torch.arange(N, device=src.device) < sl_b[:, None]
    tgt_valid = torch.arange(M, device=src.device) < tl_b[:, None]
    eye = torch.eye(4, dtype=torch.float64, device=src.device)
    m0 = eye.expand(B, 4, 4) if init is None else _flatten(init.detach(), batch, (4, 4)).double()
    bad_b = ((~torch.isfinite(src).all(-1) & src_valid).any(-1)
             | (~torch.isfinite(tgt).all(-1) & tgt_valid).any(-1)
             | ~torch.isfinite(m0).all(-1).all(-1))
    normals = None
    if target_normals is not None:
        normals = _flatten(target_normals.detach(), batch, (M, 3)).double()
        bad_b |= (~torch.isfinite(normals).all(-1) & tgt_valid).any(-1)
    ok = ~bad_b[:, None, None]
    src = torch.where(ok & src_valid[..., None] & torch.isfinite(src), src, 0.0)
    tgt = torch.where(ok & tgt_valid[..., None] & torch.isfinite(tgt), tgt, 0.0)
    m0 = torch.where(ok, m0, eye)
    if normals is not None:
        normals = torch.where(ok & tgt_valid[..., None] & torch.isfinite(normals), normals, 0.0)
    moved = apply_transform(m0, src)
    scale_b = search_scale(moved, tgt, sl_b, tl_b)[:, 0, 0]
    m0 = m0.clone()
    m0[:, :3, 3] = m0[:, :3, 3] / scale_b[:, None]
    return _Pairs(src / scale_b[:, None, None], tgt / scale_b[:, None, None], normals, src_valid,
                  sl_b, tl_b, scale_b, bad_b, m0)


class _Match(NamedTuple):
    idx: torch.Tensor  # (B, N) long, clamped to >= 0
    inlier: torch.Tensor  # (B, N) bool
    d2: torch.Tensor  # (B, N) squared point-to-point distance
    r2: torch.Tensor  # (B, N) squared residual of the method


class _Geometry(NamedTuple):
    """The moved source points and their matches' target points and normals ``(A, N, 3)``
    of the pairs a step works on, and the point-to-plane residuals ``(A, N)`` (``n`` and
    ``residual`` None for point-to-point; ``residual`` None: not computed yet)."""

    moved: torch.Tensor
    q: torch.Tensor
    n: torch.Tensor | None
    residual: torch.Tensor | None = None


def _search(pairs: _Pairs, grid, moved: torch.Tensor, ids, search, previous) -> torch.Tensor:
    """Nearest target index ``(A, N)`` of the moved source points of pairs ``ids`` (``-1``
    where none); the search runs on the whole batch with the other pairs' lengths at 0.
    ``grid`` holds the target's grids of the search (the torch search's cache, or the
    kernel's levels); the kernel starts from the previous matches' distances (exact
    bounds)."""
    dtype, backend = search
    query, sl = moved, pairs.sl
    if ids is not None:
        query = moved.new_zeros(pairs.src.shape).index_copy_(0, ids, moved)
        sl = torch.zeros_like(pairs.sl).index_copy_(0, ids, pairs.sl.index_select(0, ids))
    args = (query.to(dtype), pairs.tgt.to(dtype), 1, sl, pairs.tl)
    if backend == "warp":
        idx = warp_knn_indices(*args, grids=grid, previous_bn=previous)[..., 0]
    else:
        idx = grid_knn_indices(*args, grid)[..., 0]
    return idx if ids is None else idx.index_select(0, ids)


def _gather(points_bm3: torch.Tensor, idx_an: torch.Tensor, ids=None) -> torch.Tensor:
    """``points[ids[a], idx[a, n]]`` ``(A, N, 3)`` (``ids`` None: every pair, in order)."""
    B, M, _ = points_bm3.shape
    rows = torch.arange(B, device=idx_an.device) if ids is None else ids
    flat = (idx_an + M * rows[:, None]).reshape(-1)
    return points_bm3.reshape(B * M, 3).index_select(0, flat).reshape(*idx_an.shape, 3)


def _rows(x: torch.Tensor, ids) -> torch.Tensor:
    return x if ids is None else x.index_select(0, ids)


def _match(pairs: _Pairs, grid, matrix, max_d2_b, search, ids=None, previous=None
           ) -> tuple[_Match, _Geometry]:
    """The nearest target point of every moved source point of the pairs ``ids`` (all
    when None; ``matrix`` and ``max_d2_b`` are theirs), the rejection by distance and the
    residuals; ``previous`` ``(B, N)`` holds every pair's last match."""
    moved = apply_transform(matrix, _rows(pairs.src, ids))
    idx = _search(pairs, grid, moved, ids, search, previous)
    found = idx >= 0
    idx = idx.clamp_min(0)
    q = _gather(pairs.tgt, idx, ids)
    diff = moved - q
    d2 = dot3(diff, diff)
    inlier = found & _rows(pairs.src_valid, ids) & (d2 <= max_d2_b[:, None])
    r2, n, residual = d2, None, None
    if pairs.normals is not None:
        n = _gather(pairs.normals, idx, ids)
        residual = dot3(diff, n)
        r2 = residual.square()
    return _Match(idx, inlier, d2, r2), _Geometry(moved, q, n, residual)


def _weights(match: _Match, loss: str, scale_b) -> torch.Tensor:
    """IRLS weights ``(B, N)``, zero off the inliers."""
    w = match.inlier.to(match.r2.dtype)
    if loss == "l2":
        return w
    if scale_b is None:  # robust sigma of each pair: 1.4826 median |r| over its inliers
        r = torch.where(match.inlier, match.r2, float("nan")).sqrt()
        sigma = 1.4826 * torch.nanmedian(r, dim=-1).values
        count = match.inlier.sum(-1).clamp_min(1).to(r)
        mean = torch.where(match.inlier, r, 0.0).sum(-1) / count  # when over half are exact
        sigma = torch.where(torch.isfinite(sigma) & (sigma > 0), sigma, mean)
        # all residuals zero: every weight is 1 at any positive scale
        scale_b = _EFFICIENCY[loss] * torch.where(sigma > 0, sigma, torch.ones_like(sigma))
    return w * robust_weights(match.r2, loss, scale_b[:, None])


def _step(method, model, src, geometry: _Geometry, matrix, w):
    """The next transform ``(B, 4, 4)`` from the matches' geometry at ``matrix``
    (differentiable in the points).

    A pair without a weighted match keeps ``matrix`` (the closed forms would read an
    all-zero weight set as uniform weights); so does an empty source (``N = 0``, which
    the closed forms reject as undefined).
    """
    if src.shape[1] == 0:
        return matrix
    similarity = model == "similarity"
    if method == "point_to_point":
        closed = find_similarity if similarity else find_euclidean
        fit = closed(src, geometry.q, w).matrix  # Kabsch / Umeyama, no reflection
        return torch.where((w.sum(-1) > 0)[:, None, None], fit, matrix)
    step = point_to_plane_step(geometry.moved, geometry.q, geometry.n, w, similarity,
                               geometry.residual)
    return step @ matrix


def _solve(method, model, src, tgt_all, normals_all, matrix, match, w):
    """The next transform from the matches ``match`` at ``matrix`` (differentiable in
    the points): :func:`_step` on the gathered geometry."""
    n = None if method == "point_to_point" else _gather(normals_all, match.idx)
    geometry = _Geometry(apply_transform(matrix, src), _gather(tgt_all, match.idx), n)
    return _step(method, model, src, geometry, matrix, w)


class _Spread(NamedTuple):
    """The valid source points' centroid ``(B, 3)`` and second moment about it
    ``(B, 3, 3)`` (means over the points): an update's RMS motion in closed form."""

    centre: torch.Tensor
    moment: torch.Tensor

    @staticmethod
    def of(pairs: _Pairs) -> _Spread:
        count = pairs.sl.clamp_min(1).to(pairs.src)[:, None]
        w = pairs.src_valid.to(pairs.src)
        centre = weighted_sum(w, pairs.src) / count
        pc = (pairs.src - centre[:, None]) * w[..., None]
        return _Spread(centre, pc.transpose(1, 2) @ pc / count[..., None])

    def select(self, ids) -> _Spread:
        return _Spread(self.centre.index_select(0, ids), self.moment.index_select(0, ids))

    def rms_radius(self) -> torch.Tensor:
        return self.moment.diagonal(dim1=-2, dim2=-1).sum(-1).clamp_min(0).sqrt()

    def rms_motion(self, old, new) -> torch.Tensor:
        """RMS displacement of the points from ``old`` to ``new`` ``(B, 4, 4)``: with
        ``D`` the change of the linear part and ``e`` that of the centroid's image,
        ``tr(D S D^T) + |e|^2`` (two non-negative terms: no cancellation)."""
        d = new[:, :3, :3] - old[:, :3, :3]
        e = apply_transform(new, self.centre[:, None])[:, 0] - apply_transform(
            old, self.centre[:, None])[:, 0]
        spread = ((d @ self.moment) * d).sum((-2, -1))
        return (spread.clamp_min(0) + dot3(e, e)).sqrt()


def _inlier_stats(match: _Match) -> tuple[torch.Tensor, torch.Tensor]:
    """Inlier count ``(B,)`` and RMS inlier distance ``(B,)`` of the matches."""
    count = match.inlier.sum(-1)
    ms = torch.where(match.inlier, match.d2, 0.0).sum(-1) / count.clamp_min(1).to(match.d2)
    return count, ms.sqrt()


def _stationary(before: _Match, after: _Match, tol: float) -> torch.Tensor:
    """``(B,)``: the same number of inliers, and their RMSE fell by at most ``tol`` of it
    (or rose)."""
    count0, rmse0 = _inlier_stats(before)
    count1, rmse1 = _inlier_stats(after)
    return (count0 == count1) & (rmse0 - rmse1 <= tol * rmse0)


def _converged(spread: _Spread, old, new, before: _Match, after: _Match, tol: float
               ) -> torch.Tensor:
    """``(A,)``: the update moved the points by at most ``tol`` of their RMS radius, or by
    at most ``sqrt(tol)`` of it without lowering the inliers' RMSE by more than ``tol``
    (the discrete matches cycle)."""
    motion, radius = spread.rms_motion(old, new), spread.rms_radius()
    return (motion <= tol * radius) | ((motion <= math.sqrt(tol) * radius)
                                       & _stationary(before, after, tol))


def _iterate(pairs, grid, method, model, loss, scale_b, max_d2_b, max_iterations, tol, search):
    """The IRLS loop over iterations; returns the last matrix, matches and counters. Each
    iteration works on the pairs still active only (``ids``)."""
    B = pairs.src.shape[0]
    spread_all = _Spread.of(pairs)
    matrix = pairs.init
    active = (pairs.sl > 0) & (pairs.tl > 0) & ~pairs.bad_b
    iterations = torch.zeros(B, dtype=torch.long, device=matrix.device)
    converged = torch.zeros(B, dtype=torch.bool, device=matrix.device)
    match, geometry = _match(pairs, grid, matrix, max_d2_b, search)
    ids = active.nonzero()[:, 0]
    m_sub, geometry = _Match(*(x.index_select(0, ids) for x in match)), _select(geometry, ids)
    for _ in range(max_iterations):  # loop over iterations
        if ids.numel() == 0:
            break
        old = matrix.index_select(0, ids)
        w = _weights(m_sub, loss, None if scale_b is None else scale_b.index_select(0, ids))
        new = _step(method, model, pairs.src.index_select(0, ids), geometry, old, w)
        matrix = matrix.index_copy(0, ids, new)
        fresh, geometry = _match(pairs, grid, new, max_d2_b.index_select(0, ids), search,
                                 ids, match.idx)
        done = _converged(spread_all.select(ids), old, new, m_sub, fresh, tol)
        iterations.index_add_(0, ids, torch.ones_like(ids))
        converged.index_copy_(0, ids, done)
        match = _Match(*(x.index_copy(0, ids, y) for x, y in zip(match, fresh)))
        keep = (~done).nonzero()[:, 0]
        ids, geometry = ids.index_select(0, keep), _select(geometry, keep)
        m_sub = _Match(*(x.index_select(0, keep) for x in fresh))
    return matrix, match, iterations, converged


def _select(geometry: _Geometry, rows: torch.Tensor) -> _Geometry:
    """The rows ``rows`` of every tensor of ``geometry``."""
    return _Geometry(*(None if x is None else x.index_select(0, rows) for x in geometry))


def _finish(source, target, target_normals, pairs, batch, matrix, match, w, method, model):
    """The last solve with gradients, in the input units, and the RMSE."""
    B, N, M = pairs.src.shape[0], source.shape[-2], target.shape[-2]
    src = _flatten(source, batch, (N, 3)).double()
    tgt = _flatten(target, batch, (M, 3)).double()
    ok = ~pairs.bad_b[:, None, None]
    src = torch.where(ok & pairs.src_valid[..., None], src, 0.0)
    tgt = torch.where(ok & (torch.arange(M, device=src.device) < pairs.tl[:, None])[..., None],
                      tgt, 0.0)
    normals = None
    if method == "point_to_plane":
        normals = (pairs.normals if target_normals is None else torch.where(
            ok, _flatten(target_normals, batch, (M, 3)).double(), 0.0))
    unit = matrix.clone()
    unit[:, :3, 3] = unit[:, :3, 3] * pairs.scale_b[:, None]
    out = _solve(method, model, src, tgt, normals, unit, match, w)
    has_step = w.sum(-1) > 0
    out = torch.where(has_step[:, None, None], out, unit)
    q = torch.gather(tgt, 1, match.idx[..., None].expand(B, N, 3))
    d2 = (apply_transform(out, src) - q).square().sum(-1)
    count = match.inlier.sum(-1)
    rmse = safe_sqrt(torch.where(match.inlier, d2, 0.0).sum(-1) / count.clamp_min(1).to(d2))
    fraction = count.to(d2) / pairs.sl.clamp_min(1).to(d2)
    nan = torch.full_like(rmse, float("nan"))
    out = torch.where(pairs.bad_b[:, None, None], float("nan"), out)
    return out, torch.where(pairs.bad_b, nan, rmse), torch.where(pairs.bad_b, nan, fraction)


def icp(
    source: torch.Tensor,
    target: torch.Tensor,
    *,
    source_lengths: torch.Tensor | None = None,
    target_lengths: torch.Tensor | None = None,
    init: torch.Tensor | None = None,
    method: str = "point_to_point",
    model: str = "euclidean",
    max_distance: float | None = None,
    robust: ICPRobust = ICPRobust(),
    convergence: ICPConvergence = ICPConvergence(),
    target_normals: torch.Tensor | None = None,
    backend: str = "auto",
) -> ICPResult:
    """Register ``B`` pairs of point clouds by iterative closest point, all at once.

    Convention:
        See the module docstring: ``target ~ transform @ source``; relative
        convergence; differentiable given the last correspondences; scale-free.

    Args:
        source: ``(*, N, 3)`` floating point, the moving clouds.
        target: ``(*, M, 3)``, same dtype; batch dims broadcast.
        source_lengths, target_lengths: ``(*,)`` integer, valid rows (default all).
        init: ``(*, 4, 4)`` initial target-from-source transforms (default identity).
        method: ``"point_to_point"`` or ``"point_to_plane"`` (needs target normals:
            ``target_normals``, or :func:`estimate_normals` with 10 neighbours).
        model: ``"euclidean"`` (rotation + translation) or ``"similarity"`` (+ scale).
        max_distance: matches farther than this are rejected (default: none).
        robust: the loss of the IRLS weights and its scale (:class:`ICPRobust`; default
            least squares).
        convergence: the iteration limit and the relative tolerance
            (:class:`ICPConvergence`).
        target_normals: ``(*, M, 3)`` unit normals of the target (point-to-plane).
        backend: the nearest-neighbour search: ``"auto"``, ``"torch"`` or ``"warp"``
            (:func:`torchgeo_cg.engine.resolve_backend`); identical matches, so identical
            results. The target's grid is built once per call and reused by every
            iteration.

    Returns:
        :class:`ICPResult` ``(transform (*, 4, 4), rmse (*,), inlier_fraction (*,),
        iterations (*,), converged (*,))``.

    Example:
        >>> g = torch.Generator().manual_seed(0)
        >>> target = torch.rand(500, 3, generator=g, dtype=torch.float64)
        >>> c, s = math.cos(0.1), math.sin(0.1)
        >>> rot = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
        ...                    dtype=torch.float64)
        >>> source = (target - 0.5) @ rot + 0.5 + 0.02  # target rotated back and shifted
        >>> res = icp(source, target)
        >>> bool(res.converged), float(res.rmse) < 1e-9
        (True, True)
        >>> (res.transform[:3, :3] - rot).abs().max() < 1e-9
        tensor(True)
    """
    options = {"max_distance": max_distance, "robust": robust, "convergence": convergence}
    batch, N, M = _check_arguments(source, target, init, target_normals, method, model,
                                   options)
    backend = resolve_backend(backend, source.device)
    if not kernel_ready(source, target):  # under torch.func or tracing: torch path
        backend = "torch"
    loss, scale = robust.loss, robust.scale
    max_iterations, tol = convergence.max_iterations, convergence.tol
    sl = check_lengths(source_lengths, batch, N, "source_lengths", source.device)
    tl = check_lengths(target_lengths, batch, M, "target_lengths", source.device)
    dtype = source.dtype
    sdtype = working_dtype(dtype)
    if math.prod(batch) == 0:  # no pair: empty results
        z = source.new_zeros(batch)
        return ICPResult(source.new_zeros(*batch, 4, 4), z, z.clone(),
                         torch.zeros(batch, dtype=torch.long, device=source.device),
                         torch.zeros(batch, dtype=torch.bool, device=source.device))
    with torch.no_grad():
        if method == "point_to_plane" and target_normals is None and M > 0:
            k = max(2, min(_NORMAL_NEIGHBOURS, M))
            est = estimate_normals(target.detach().expand(*batch, M, 3).to(sdtype), k, tl)
            target_normals_d = est.to(dtype)
        else:
            target_normals_d = target_normals
        if method == "point_to_plane" and target_normals_d is None:  # M == 0
            target_normals_d = target.new_zeros(*batch, M, 3)
        pairs = _prepare(source, target, init, target_normals_d if method == "point_to_plane"
                         else None, sl, tl, batch)
        if backend == "warp":  # the target's grids, reused by every iteration
            grid = kernel_grids(pairs.tgt.to(sdtype), pairs.tl, 1, levels=_KERNEL_LEVELS)
        else:
            grid = [build_grid(pairs.tgt.to(sdtype), pairs.tl, grid_per_cell(1))]
        max_d2_b = torch.full_like(pairs.scale_b, float("inf"))
        if max_distance is not None:
            max_d2_b = (max_distance / pairs.scale_b).square()
        scale_b = None if scale is None else scale / pairs.scale_b
        matrix, match, iterations, converged = _iterate(
            pairs, grid, method, model, loss, scale_b, max_d2_b, max_iterations, tol,
            (sdtype, backend))
        w = _weights(match, loss, scale_b)
    out, rmse, fraction = _finish(source, target, target_normals, pairs, batch, matrix, match,
                                  w, method, model)
    return ICPResult(cast_back(out, dtype).reshape(*batch, 4, 4),
                     cast_back(rmse, dtype).reshape(batch),
                     cast_back(fraction, dtype).reshape(batch),
                     iterations.reshape(batch), converged.reshape(batch))
