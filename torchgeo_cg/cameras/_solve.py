"""The solvers behind undistortion: a bracketed 1D Newton and a 2D trust-region Newton.

Both run on every point at once with a convergence mask, and keep only the points
still iterating (compacted each iteration), so a few slow points do not cost a pass
over all of them. The loops run over iterations, never over points, and stop once
every point has converged. Tolerances are relative to the dtype's precision and to the
values solved for, so the same points scaled give the same answer. Everything here
runs without autograd (the gradients come by implicit differentiation).
"""

from __future__ import annotations

from collections.abc import Callable

import torch


def _flat(shape: torch.Size, tensors) -> list[torch.Tensor]:
    return [t.expand(shape).reshape(-1) for t in tensors]


def upper_bracket(target: torch.Tensor, radial: Callable, limit: torch.Tensor,
                  params, doublings: int = 64) -> torch.Tensor:
    """A radius ``hi`` with ``radial(hi) >= target``, or the domain end ``limit``.

    Where ``limit`` is finite it is the bracket; elsewhere ``hi`` starts at ``target`` and
    doubles until the map passes the target (``doublings`` at most: a map whose supremum
    lies below the target leaves it short, and the caller marks the point invalid).
    """
    finite = torch.isfinite(limit)
    start = torch.where(target > 0, target, torch.ones_like(target))
    hi = torch.where(finite, limit, start)
    short = ~finite & (radial(hi, params)[0] < target)
    for _ in range(doublings):
        if not bool(short.any()):
            break
        hi = torch.where(short, 2 * hi, hi)
        short = short & (radial(hi, params)[0] < target)
    return hi


def solve_monotone(target: torch.Tensor, radial: Callable, hi: torch.Tensor, params,
                   skip: torch.Tensor, max_iterations: int = 100, rtol: float = 0.0):
    """``r`` in ``[0, hi]`` with ``radial(r, params) = target`` for an increasing ``radial``.

    Newton where its step stays inside the bracket, bisection elsewhere (rtsafe), so it
    cannot leave the monotone domain. ``radial(r, params) -> (value, slope)``; ``params``
    broadcast against ``target``; ``skip`` marks points not to solve (left at ``hi``).
    ``rtol > 0`` stops at that relative step instead of at rounding level (a start for a
    solver that polishes the result).

    Returns:
        ``(r, converged)``, shaped like ``target``.
    """
    shape = torch.broadcast_shapes(target.shape, hi.shape, skip.shape,
                                   *(p.shape for p in params))
    eps = torch.finfo(target.dtype).eps
    t_all, hi_all = _flat(shape, (target, hi))
    params_all = _flat(shape, params)
    skip = skip.expand(shape).reshape(-1)
    # start: one fixed-point step from the target (r0 = t^2 / radial(t)), else mid-bracket
    value0, _ = radial(t_all, params_all)
    guess = t_all * t_all / torch.where(value0 > 0, value0, torch.ones_like(value0))
    good = (value0 > 0) & (guess < hi_all)
    r_all = torch.where(skip, hi_all, torch.where(good, guess, 0.5 * hi_all))
    r_all = torch.where(t_all == 0, torch.zeros_like(r_all), r_all)
    done_all = skip | (t_all == 0)
    idx = (~done_all).nonzero().squeeze(1)
    t, hi, r = t_all[idx], hi_all[idx], r_all[idx]
    lo = torch.zeros_like(t)
    ps = [p[idx] for p in params_all]
    for _ in range(max_iterations):
        if idx.numel() == 0:
            break
        value, slope = radial(r, ps)
        h = value - t
        lo = torch.where(h <= 0, r, lo)
        hi = torch.where(h >= 0, r, hi)
        ok = slope > 0
        newton = r - h / torch.where(ok, slope, torch.ones_like(slope))
        inside = ok & (newton > lo) & (newton < hi)
        # converged: Newton's own step is at rounding level (it may land on a bracket end)
        small = ok & ((newton - r).abs() <= max(2 * eps, rtol) * r)
        # or the residual is at the target's rounding level: nothing more can be known
        now = (h.abs() <= eps * t) | small | (hi - lo <= 2 * eps * hi)
        r = torch.where(h == 0, r, torch.where(small | inside, newton, 0.5 * (lo + hi)))
        if bool(now.any()):
            r_all[idx[now]] = r[now]
            done_all[idx[now]] = True
            keep = ~now
            idx, t, hi, lo, r = idx[keep], t[keep], hi[keep], lo[keep], r[keep]
            ps = [p[keep] for p in ps]
    if idx.numel():
        r_all[idx] = r
    return r_all.reshape(shape), done_all.reshape(shape)


def _norm2(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.sqrt(a * a + b * b)


def _newton_step(x, y, rx, ry, jac, radius):
    """The Newton step ``-J^-1 r`` cut to the trust radius, and whether ``J`` is regular."""
    j00, j01, j10, j11 = jac
    det = j00 * j11 - j01 * j10
    good = det != 0
    inv = 1 / torch.where(good, det, torch.ones_like(det))
    dx = -(j11 * rx - j01 * ry) * inv
    dy = -(j00 * ry - j10 * rx) * inv
    length = _norm2(dx, dy)
    cut = torch.where(length > radius, radius / torch.where(length > 0, length, 1.0),
                      torch.ones_like(length))
    return cut * dx, cut * dy, cut * length, good


def newton_2d(x: torch.Tensor, y: torch.Tensor, tx: torch.Tensor, ty: torch.Tensor,
              model: Callable, params, skip: torch.Tensor, max_iterations: int = 100):
    """Solve ``model(x, y, params) = (tx, ty)`` from ``(x, y)`` by Newton in a trust region.

    ``model(x, y, params) -> (fx, fy, j00, j01, j10, j11)``. A step is accepted when it
    lowers the residual, and the region then grows; a rejected step shrinks it.
    Converged: the residual is at rounding level (``4 eps`` of the sizes), or Newton's step
    or the region has shrunk below the precision with the residual at its rounding floor.

    Returns:
        ``(x, y, converged, det)``, shaped like ``x``: ``det`` is the Jacobian's
        determinant at the returned point.
    """
    shape = torch.broadcast_shapes(x.shape, y.shape, tx.shape, ty.shape, skip.shape,
                                   *(p.shape for p in params))
    eps = torch.finfo(x.dtype).eps
    x_all, y_all, tx_all, ty_all = _flat(shape, (x, y, tx, ty))
    x_all, y_all = x_all.clone(), y_all.clone()
    params_all = _flat(shape, params)
    done_all = torch.zeros(x_all.shape, dtype=torch.bool, device=x.device)
    det_all = torch.zeros_like(x_all)
    live = ~skip.expand(shape).reshape(-1)
    idx = live.nonzero().squeeze(1)
    x, y, tx, ty = x_all[idx], y_all[idx], tx_all[idx], ty_all[idx]
    ps = [p[idx] for p in params_all]
    fx, fy, *jac = model(x, y, ps)
    rx, ry = fx - tx, fy - ty
    res = _norm2(rx, ry)
    size = _norm2(x, y) + _norm2(tx, ty)
    radius = torch.where(size > 0, 0.5 * size, torch.ones_like(size))
    for it in range(max_iterations + 1):
        dx, dy, length, good = _newton_step(x, y, rx, ry, jac, radius)
        span = _norm2(x, y)
        floor = res <= 64 * eps * size  # the residual's rounding floor
        # converged: the residual at rounding level, or Newton's own (uncut) step below the
        # precision of x with the residual at its floor, or a region shrunk to nothing
        now = (res <= 4 * eps * size) | (good & (length <= 2 * eps * span) & floor) \
            | (floor & (radius <= 2 * eps * span))
        if bool(now.any()):
            done_all[idx[now]] = True
            x_all[idx[now]], y_all[idx[now]] = x[now], y[now]
            det_all[idx[now]] = (jac[0] * jac[3] - jac[1] * jac[2])[now]
            keep = ~now
            idx, x, y, tx, ty, rx, ry = (a[keep] for a in (idx, x, y, tx, ty, rx, ry))
            res, size, radius = res[keep], size[keep], radius[keep]
            dx, dy, length, good = dx[keep], dy[keep], length[keep], good[keep]
            jac = [j[keep] for j in jac]
            ps = [p[keep] for p in ps]
        if idx.numel() == 0 or it == max_iterations:
            break
        nx, ny = x + dx, y + dy
        gx, gy, *jac_new = model(nx, ny, ps)
        sx, sy = gx - tx, gy - ty
        new = _norm2(sx, sy)
        accept = good & (new < res)
        x, y = torch.where(accept, nx, x), torch.where(accept, ny, y)
        rx, ry = torch.where(accept, sx, rx), torch.where(accept, sy, ry)
        res = torch.where(accept, new, res)
        jac = [torch.where(accept, b, a) for a, b in zip(jac, jac_new)]
        radius = torch.where(accept, torch.maximum(radius, 2 * length), 0.25 * length)
        size = _norm2(x, y) + _norm2(tx, ty)
    if idx.numel():
        x_all[idx], y_all[idx] = x, y
        det_all[idx] = jac[0] * jac[3] - jac[1] * jac[2]
    return (x_all.reshape(shape), y_all.reshape(shape), done_all.reshape(shape),
            det_all.reshape(shape))
