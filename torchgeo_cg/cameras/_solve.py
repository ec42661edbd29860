"""The solvers behind undistortion: a bracketed 1D Newton and a 2D trust-region Newton.

Both run on every point at once with a convergence mask; the loops run over
iterations, never over points, and stop early once every point has converged.
Tolerances are relative to the dtype's precision and to the values solved for, so the
same points scaled give the same answer.
"""

from __future__ import annotations

from collections.abc import Callable

import torch


def upper_bracket(target: torch.Tensor, radial: Callable, limit: torch.Tensor,
                  doublings: int = 64) -> torch.Tensor:
    """A radius ``hi`` with ``radial(hi) >= target``, or the domain end ``limit``.

    Where ``limit`` is finite it is the bracket; elsewhere ``hi`` starts at ``target`` and
    doubles until the map passes the target (``doublings`` at most: a map whose supremum
    lies below the target leaves it short, and the caller marks the point invalid).
    """
    finite = torch.isfinite(limit)
    start = torch.where(target > 0, target, torch.ones_like(target))
    hi = torch.where(finite, limit, start)
    short = ~finite & (radial(hi)[0] < target)
    for _ in range(doublings):
        if not bool(short.any()):
            break
        hi = torch.where(short, 2 * hi, hi)
        short = short & (radial(hi)[0] < target)
    return hi


def solve_monotone(target: torch.Tensor, radial: Callable, hi: torch.Tensor,
                   max_iterations: int = 100):
    """``r`` in ``[0, hi]`` with ``radial(r) = target`` for an increasing ``radial``.

    Newton where its step stays inside the bracket, bisection elsewhere (rtsafe), so it
    cannot leave the monotone domain. ``radial(r) -> (value, slope)``.

    Returns:
        ``(r, converged)``.
    """
    eps = torch.finfo(target.dtype).eps
    lo = torch.zeros_like(target)
    hi = hi.expand_as(target).clone()
    r = torch.minimum(target, 0.5 * hi)
    done = target == 0
    r = torch.where(done, torch.zeros_like(r), r)
    for _ in range(max_iterations):
        value, slope = radial(r)
        h = value - target
        lo = torch.where(h <= 0, r, lo)
        hi = torch.where(h >= 0, r, hi)
        ok = slope > 0
        newton = r - h / torch.where(ok, slope, torch.ones_like(slope))
        inside = ok & (newton > lo) & (newton < hi)
        step = torch.where(inside, newton, 0.5 * (lo + hi))
        now = (h == 0) | ((step - r).abs() <= 2 * eps * step) | (hi - lo <= 2 * eps * hi)
        r = torch.where(done, r, torch.where(h == 0, r, step))
        done = done | now
        if bool(done.all()):
            break
    return r, done


def _norm2(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.sqrt(a * a + b * b)


def newton_2d(x: torch.Tensor, y: torch.Tensor, tx: torch.Tensor, ty: torch.Tensor,
              model: Callable, max_iterations: int = 100):
    """Solve ``model(x, y) = (tx, ty)`` from ``(x, y)`` by Newton in a trust region.

    ``model(x, y) -> (fx, fy, j00, j01, j10, j11)``. A step is accepted when it lowers
    the residual, and the region then grows; a rejected step shrinks it. Converged:
    the residual is at rounding level, or the accepted step is below the precision.

    Returns:
        ``(x, y, converged)``.
    """
    eps = torch.finfo(x.dtype).eps
    fx, fy, j00, j01, j10, j11 = model(x, y)
    rx, ry = fx - tx, fy - ty
    res = _norm2(rx, ry)
    size = _norm2(x, y) + _norm2(tx, ty)
    tol = 16 * eps * size
    done = res <= tol
    radius = torch.where(size > 0, 0.5 * size, torch.ones_like(size))
    for _ in range(max_iterations):
        if bool(done.all()):
            break
        det = j00 * j11 - j01 * j10
        good = det != 0
        inv = 1 / torch.where(good, det, torch.ones_like(det))
        dx = -(j11 * rx - j01 * ry) * inv
        dy = -(j00 * ry - j10 * rx) * inv
        length = _norm2(dx, dy)
        shrink = torch.where(length > radius, radius / torch.where(length > 0, length, 1.0),
                             torch.ones_like(length))
        nx, ny = x + shrink * dx, y + shrink * dy
        gx, gy, k00, k01, k10, k11 = model(nx, ny)
        sx, sy = gx - tx, gy - ty
        new = _norm2(sx, sy)
        accept = good & (new < res) & ~done
        tiny = shrink * length <= 2 * eps * _norm2(x, y)
        x, y = torch.where(accept, nx, x), torch.where(accept, ny, y)
        rx, ry = torch.where(accept, sx, rx), torch.where(accept, sy, ry)
        res = torch.where(accept, new, res)
        j00, j01 = torch.where(accept, k00, j00), torch.where(accept, k01, j01)
        j10, j11 = torch.where(accept, k10, j10), torch.where(accept, k11, j11)
        radius = torch.where(accept, torch.maximum(radius, 2 * shrink * length),
                             0.25 * shrink * length)
        size = _norm2(x, y) + _norm2(tx, ty)
        floor = res <= 64 * eps * size  # rounding floor of the residual
        done = done | (res <= 16 * eps * size) | (tiny & accept & floor) \
            | (~accept & floor & (radius <= 2 * eps * _norm2(x, y)))
    return x, y, done
