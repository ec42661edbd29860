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
      the points). No absolute epsilon.
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
from torchgeo_cg.points._icp_steps import apply_transform, point_to_plane_step
from torchgeo_cg.points._knn_kernels import kernel_per_cell, warp_knn_indices
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
#: 95%-efficiency constants of the robust losses (in units of the residual's sigma).
_EFFICIENCY = {"huber": 1.345, "cauchy": 2.385, "tukey": 4.685}


@dataclass(frozen=True)
class ICPConvergence:
    """When :func:`icp` stops (Open3D's ``ICPConvergenceCriteria``, with one relative test).

    Attributes:
        max_iterations: at most this many updates, ``>= 0``.
        tol: a pair has converged when an update moves its valid source points by at most
            ``tol`` times their RMS radius about their centroid, ``> 0``.

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


def _match(pairs: _Pairs, grid, matrix, max_d2_b, search, previous=None, moved_b=None
           ) -> _Match:
    """The nearest target point of every moved source point; ``search`` is ``(dtype,
    backend)``: the Warp kernel reuses the target's finest grid ``grid[0]``. With
    ``previous`` and ``moved_b`` (the pairs whose transform changed), only those pairs are
    searched; the others keep their previous match (the same answer)."""
    moved = apply_transform(matrix, pairs.src)
    B, N, _ = moved.shape
    dtype, backend = search
    sl = pairs.sl if moved_b is None else torch.where(moved_b, pairs.sl, 0)
    args = (moved.to(dtype), pairs.tgt.to(dtype), 1, sl, pairs.tl)
    if backend == "warp":
        idx = warp_knn_indices(*args, grid=grid[0])[..., 0]
    else:
        idx = grid_knn_indices(*args, grid)[..., 0]
    found = idx >= 0
    idx = idx.clamp_min(0)
    q = torch.gather(pairs.tgt, 1, idx[..., None].expand(B, N, 3))
    d2 = (moved - q).square().sum(-1)
    inlier = found & pairs.src_valid & (d2 <= max_d2_b[:, None])
    r2 = d2
    if pairs.normals is not None:
        n = torch.gather(pairs.normals, 1, idx[..., None].expand(B, N, 3))
        r2 = ((moved - q) * n).sum(-1).square()
    match = _Match(idx, inlier, d2, r2)
    if previous is None:
        return match
    keep = moved_b[:, None]
    return _Match(*(torch.where(keep, new, old) for new, old in zip(match, previous)))


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


def _solve(method, model, src, tgt_all, normals_all, matrix, match, w):
    """The next transform ``(B, 4, 4)`` from the matches (differentiable in the points).

    A pair without a weighted match keeps ``matrix`` (the closed forms would read an
    all-zero weight set as uniform weights); so does an empty source (``N = 0``, which
    the closed forms reject as undefined).
    """
    B, N, _ = src.shape
    if N == 0:
        return matrix
    q = torch.gather(tgt_all, 1, match.idx[..., None].expand(B, N, 3))
    similarity = model == "similarity"
    if method == "point_to_point":
        closed = find_similarity if similarity else find_euclidean
        fit = closed(src, q, w).matrix  # Kabsch / Umeyama, no reflection
        return torch.where((w.sum(-1) > 0)[:, None, None], fit, matrix)
    n = torch.gather(normals_all, 1, match.idx[..., None].expand(B, N, 3))
    step = point_to_plane_step(apply_transform(matrix, src), q, n, w, similarity)
    return step @ matrix


def _motion(pairs: _Pairs, old, new, radius_b):
    """RMS displacement of the valid source points between two transforms / radius."""
    d2 = (apply_transform(new, pairs.src) - apply_transform(old, pairs.src)).square().sum(-1)
    count = pairs.sl.clamp_min(1).to(d2)
    return (torch.where(pairs.src_valid, d2, 0.0).sum(-1) / count).sqrt() <= radius_b


def _iterate(pairs, grid, method, model, loss, scale_b, max_d2_b, max_iterations, tol, search):
    """The IRLS loop over iterations; returns the last matrix, matches and counters."""
    B = pairs.src.shape[0]
    centre = pairs.src.sum(1) / pairs.sl.clamp_min(1)[:, None].to(pairs.src)
    spread = torch.where(pairs.src_valid, (pairs.src - centre[:, None]).square().sum(-1), 0.0)
    radius_b = tol * (spread.sum(-1) / pairs.sl.clamp_min(1).to(spread)).sqrt()
    matrix = pairs.init
    active = (pairs.sl > 0) & (pairs.tl > 0) & ~pairs.bad_b
    iterations = torch.zeros(B, dtype=torch.long, device=matrix.device)
    converged = torch.zeros(B, dtype=torch.bool, device=matrix.device)
    match = _match(pairs, grid, matrix, max_d2_b, search)
    for _ in range(max_iterations):  # loop over iterations
        if not bool(active.any()):
            break
        w = _weights(match, loss, scale_b)
        new = _solve(method, model, pairs.src, pairs.tgt, pairs.normals, matrix, match, w)
        new = torch.where(active[:, None, None], new, matrix)
        done = _motion(pairs, matrix, new, radius_b) & active
        iterations += active.long()
        converged |= done
        matrix = new
        match = _match(pairs, grid, matrix, max_d2_b, search, match, active.clone())
        active &= ~done
    return matrix, match, iterations, converged


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
        per_cell = kernel_per_cell(1) if backend == "warp" else grid_per_cell(1)
        grid = [build_grid(pairs.tgt.to(sdtype), pairs.tl, per_cell)]  # reused
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
