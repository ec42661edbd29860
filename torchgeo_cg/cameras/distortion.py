"""Lens distortion on normalised image coordinates, and its exact inverse.

Two models, both acting on normalised coordinates ``(x, y) = (X / Z, Y / Z)`` of the
camera frame (x right, y down, z forward):

- OpenCV's (:func:`distort_points`), the model of ``cv2.projectPoints``, with
  ``distortion = (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tx, ty]]]])``::

      r2 = x^2 + y^2
      c  = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
      x' = x c + 2 p1 x y + p2 (r2 + 2 x^2) + s1 r2 + s2 r2^2
      y' = y c + p1 (r2 + 2 y^2) + 2 p2 x y + s3 r2 + s4 r2^2
      (x'', y'') = the tilt of the sensor by (tx, ty) applied to (x', y')

- Kannala-Brandt (:func:`fisheye_distort_points`), the model of
  ``cv2.fisheye.projectPoints``, ``distortion = (k1, k2, k3, k4)``::

      r = |(x, y)|, theta = atan(r)
      theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
      (x', y') = (theta_d / r) (x, y)

The inverse (:func:`undistort_points`, :func:`fisheye_undistort_points`) is exact where
the model is invertible and says where it is not: the radial map ``r -> r c(r)``
(``theta -> theta_d``) is monotone on ``[0, r*)``, ``r*`` the first positive root of its
derivative (or of the rational model's denominator), isolated in the Bernstein basis;
inside that bracket a safeguarded Newton finds the radius; the tangential, thin-prism
terms are then removed by a trust-region Newton in 2D, to convergence. ``valid`` is
False outside the domain and where the solve did not converge. Gradients come by
implicit differentiation (no unrolled iterations).

Precision: every function computes in float64 and returns the input's dtype. A lens
evaluated in float32 near its fold, or at 4K pixel coordinates, loses a few thousandths
of a pixel per pass; in float64 the round trip ``project(unproject(p))`` of a float32
camera stays within 1e-3 pixel, as OpenCV (which computes in double) does.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
import torch.nn.functional as F

from torchgeo_cg.cameras._fisheye import fisheye_angle, theta_d
from torchgeo_cg.cameras._implicit import implicit_solution
from torchgeo_cg.cameras._roots import first_root
from torchgeo_cg.cameras._solve import newton_2d, solve_monotone, upper_bracket
from torchgeo_cg.core.check import ShapeError, check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import check_same_dtype
from torchgeo_cg.core.numerics import cast_back

__all__ = [
    "UndistortResult",
    "distort_points",
    "undistort_points",
    "fisheye_distort_points",
    "fisheye_undistort_points",
]

_LENGTHS = (4, 5, 8, 12, 14)


class UndistortResult(NamedTuple):
    """The result of :func:`undistort_points` and :func:`fisheye_undistort_points`.

    Attributes:
        points: ``(*, N, 2)`` undistorted normalised coordinates; where ``valid`` is
            False, the solver's last iterate, clamped into the invertible domain.
        valid: ``(*, N)`` bool: the point has a preimage in the invertible domain and
            the solve converged to rounding level.
    """

    points: torch.Tensor
    valid: torch.Tensor


# ----------------------------------------------------------------------------- checks


def _check_pair(xy: torch.Tensor, distortion: torch.Tensor, lengths: tuple[int, ...],
                xy_name: str = "xy") -> int:
    """Validate ``xy (*, N, 2)`` and ``distortion (*, P)``; return ``P``."""
    check_float(xy, xy_name)
    check_float(distortion, "distortion")
    check_shape(xy, ["*", "N", "2"], xy_name)
    p = check_shape(distortion, ["*", "P"], "distortion")["P"]
    if p not in lengths:
        raise ShapeError(f"distortion: expected shape (*, P) with P in "
                         f"{{{', '.join(map(str, lengths))}}}, got {tuple(distortion.shape)}")
    check_same_dtype({xy_name: xy, "distortion": distortion})
    check_broadcastable({xy_name: xy.shape[:-2], "distortion": distortion.shape[:-1]})
    return p


def _coeffs(distortion: torch.Tensor) -> list[torch.Tensor]:
    """The 14 OpenCV coefficients, zero-padded, each ``(*, 1)`` to meet ``(*, N)``."""
    k = F.pad(distortion, (0, 14 - distortion.shape[-1]))
    return [k[..., i, None] for i in range(14)]


# ----------------------------------------------------------------------------- OpenCV model


def _rational(r2: torch.Tensor, k: list[torch.Tensor]):
    """``c(r2) = N / D`` and ``dc/dr2``."""
    k1, k2, k3, k4, k5, k6 = k[0], k[1], k[4], k[5], k[6], k[7]
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    dnum = k1 + r2 * (2 * k2 + 3 * r2 * k3)
    dden = k4 + r2 * (2 * k5 + 3 * r2 * k6)
    ok = den != 0
    inv = torch.where(ok, 1 / torch.where(ok, den, torch.ones_like(den)), 0.0)
    c = num * inv
    return c, (dnum - c * dden) * inv


def _plain(x: torch.Tensor, y: torch.Tensor, k: list[torch.Tensor], jacobian: bool = False):
    """The OpenCV model without the tilt: ``(x', y')`` and, optionally, its Jacobian."""
    p1, p2, s1, s2, s3, s4 = k[2], k[3], k[8], k[9], k[10], k[11]
    xx, yy, xy = x * x, y * y, x * y
    r2 = xx + yy
    c, dc = _rational(r2, k)
    px, py = s1 + s2 * r2, s3 + s4 * r2
    xd = x * c + 2 * p1 * xy + p2 * (r2 + 2 * xx) + px * r2
    yd = y * c + p1 * (r2 + 2 * yy) + 2 * p2 * xy + py * r2
    if not jacobian:
        return xd, yd
    dpx, dpy = 2 * (s1 + 2 * s2 * r2), 2 * (s3 + 2 * s4 * r2)
    j00 = c + 2 * xx * dc + 2 * p1 * y + 6 * p2 * x + dpx * x
    j01 = 2 * xy * dc + 2 * p1 * x + 2 * p2 * y + dpx * y
    j10 = 2 * xy * dc + 2 * p1 * x + 2 * p2 * y + dpy * x
    j11 = c + 2 * yy * dc + 6 * p1 * y + 2 * p2 * x + dpy * y
    return xd, yd, j00, j01, j10, j11


def _tilt(k: list[torch.Tensor]) -> torch.Tensor:
    """OpenCV's tilt ``M = P_z R_y(ty) R_x(tx)`` (``computeTiltProjectionMatrix``).

    Returns ``(*, 1, 3, 3)``, to meet points ``(*, N)``.
    """
    tx, ty = k[12], k[13]
    cx, sx, cy, sy = torch.cos(tx), torch.sin(tx), torch.cos(ty), torch.sin(ty)
    one, zero = torch.ones_like(tx), torch.zeros_like(tx)
    rot_x = torch.stack([torch.stack([one, zero, zero], -1), torch.stack([zero, cx, sx], -1),
                         torch.stack([zero, -sx, cx], -1)], -2)
    rot_y = torch.stack([torch.stack([cy, zero, -sy], -1), torch.stack([zero, one, zero], -1),
                         torch.stack([sy, zero, cy], -1)], -2)
    rot = rot_y @ rot_x
    r22, r02, r12 = rot[..., 2, 2], rot[..., 0, 2], rot[..., 1, 2]
    proj = torch.stack([torch.stack([r22, zero, -r02], -1), torch.stack([zero, r22, -r12], -1),
                        torch.stack([zero, zero, one], -1)], -2)
    return proj @ rot


def _projective(m: torch.Tensor, x: torch.Tensor, y: torch.Tensor):
    """``(x, y) -> m (x, y, 1)`` dehomogenised; ``m (*, 1, 3, 3)``, ``x, y (*, N)``."""
    u = m[..., 0, 0] * x + m[..., 0, 1] * y + m[..., 0, 2]
    v = m[..., 1, 0] * x + m[..., 1, 1] * y + m[..., 1, 2]
    w = m[..., 2, 0] * x + m[..., 2, 1] * y + m[..., 2, 2]
    ok = w != 0
    inv = torch.where(ok, 1 / torch.where(ok, w, torch.ones_like(w)), 1.0)
    return u * inv, v * inv


def _distort(x: torch.Tensor, y: torch.Tensor, distortion: torch.Tensor):
    k = _coeffs(distortion)
    xd, yd = _plain(x, y, k)
    if distortion.shape[-1] == 14:
        xd, yd = _projective(_tilt(k), xd, yd)
    return xd, yd


def distort_points(xy: torch.Tensor, distortion: torch.Tensor) -> torch.Tensor:
    """Apply OpenCV's lens distortion to normalised image coordinates.

    Convention:
        ``xy = (X / Z, Y / Z)`` in the camera frame (x right, y down, z forward);
        ``distortion`` in OpenCV's order ``k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2,
        s3, s4[, tx, ty]]]]`` (tilt angles in radians). The model of
        ``cv2.projectPoints``; see :mod:`torchgeo_cg.cameras.distortion`.

    Args:
        xy: ``(*, N, 2)`` normalised coordinates.
        distortion: ``(*, P)``, ``P`` in ``{4, 5, 8, 12, 14}``.

    Returns:
        ``(*, N, 2)`` distorted normalised coordinates; differentiable in both inputs.

    Raises:
        ShapeError: a shape, or ``P`` not in the list.

    Example:
        >>> distort_points(torch.tensor([[0.5, 0.0]]), torch.tensor([-0.2, 0.0, 0.0, 0.0]))
        tensor([[0.4750, 0.0000]])
    """
    _check_pair(xy, distortion, _LENGTHS)
    dtype = xy.dtype
    work = torch.float64  # see the module's note on precision
    xy, distortion = xy.to(work), distortion.to(work)
    xd, yd = _distort(xy[..., 0], xy[..., 1], distortion)
    return cast_back(torch.stack([xd, yd], -1), dtype)


def _radial_limit(distortion: torch.Tensor) -> torch.Tensor:
    """``r*`` per lens, ``(*, 1)``: the end of the monotone domain of ``r -> r c(r)``.

    ``d(r c)/dr = (N D + 2 s (N' D - N D')) / D^2`` in ``s = r^2``: the first positive
    root of that numerator, or of ``D`` (a pole), whichever comes first.
    """
    with torch.no_grad():
        k = F.pad(distortion.detach().double(), (0, 14 - distortion.shape[-1]))
        k = k.reshape(-1, 14)
        one = torch.ones_like(k[:, 0])
        num = torch.stack([one, k[:, 0], k[:, 1], k[:, 4]], -1)  # N(s), low degree first
        den = torch.stack([one, k[:, 5], k[:, 6], k[:, 7]], -1)
        dnum = torch.stack([k[:, 0], 2 * k[:, 1], 3 * k[:, 4]], -1)
        dden = torch.stack([k[:, 5], 2 * k[:, 6], 3 * k[:, 7]], -1)
        g = _polymul(num, den)
        cross = _polymul(dnum, den) - _polymul(num, dden)[:, :6]
        g[:, 1:] = g[:, 1:] + 2 * cross
        both = torch.cat([g, F.pad(den, (0, 3))], 0)  # (2B, 7): one search for both
        roots = first_root(both, None)
        s = torch.minimum(roots[: k.shape[0]], roots[k.shape[0]:])
        r = torch.sqrt(s)
    return r.reshape(distortion.shape[:-1] + (1,)).to(distortion.dtype)


def _polymul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Product of polynomials (coefficients low degree first, batched over rows)."""
    out = a.new_zeros(a.shape[0], a.shape[1] + b.shape[1] - 1)
    for i in range(a.shape[1]):
        out[:, i: i + b.shape[1]] += a[:, i, None] * b
    return out


def _radial_map(r: torch.Tensor, k: list[torch.Tensor]):
    """``r -> r c(r)`` and its slope."""
    c, dc = _rational(r * r, k)
    return r * c, c + 2 * r * r * dc


def _solve_radial(rd: torch.Tensor, k: list[torch.Tensor], limit: torch.Tensor,
                  rtol: float = 0.0):
    """Radius ``r`` with ``r c(r) = rd`` inside ``[0, r*)``; ``(r, inside)``.

    ``rtol``: the relative precision wanted (0: rounding level)."""
    radial = [k[0], k[1], k[4], k[5], k[6], k[7]]

    def as_k(ks):
        return [ks[0], ks[1], None, None, ks[2], ks[3], ks[4], ks[5]]

    # one bracket per lens (and batch item): a radius whose image passes every target
    if rd.shape[-1]:
        need = rd.nan_to_num(0.0, 0.0, 0.0).amax(-1, keepdim=True)
    else:
        need = rd.new_zeros(rd.shape[:-1] + (1,))
    hi = upper_bracket(need, lambda r, ks: _radial_map(r, as_k(ks)), limit, radial)
    inside = rd < _radial_map(hi, k)[0]
    r, done = solve_monotone(rd, lambda r, ks: _radial_map(r, as_k(ks)), hi, radial, ~inside,
                             rtol=rtol)
    return r, inside & done


def _plain_residual(xy: torch.Tensor, target: torch.Tensor, distortion: torch.Tensor):
    xd, yd = _plain(xy[..., 0], xy[..., 1], _coeffs(distortion))
    return torch.stack([xd, yd], -1) - target


#: Points per block of the solve: a block's arrays stay in cache, so the solver's few
#: dozen elementwise passes run at compute speed, not memory speed.
_BLOCK = 1 << 15


def _undistort_block(xd, yd, k, limit, tangential: bool, max_iterations: int):
    rd = torch.sqrt(xd * xd + yd * yd)
    # with tangential terms the radius is only the 2D Newton's start: half the digits do
    rtol = torch.finfo(rd.dtype).eps ** 0.5 if tangential else 0.0
    r, valid = _solve_radial(rd, k, limit, rtol)
    ratio = torch.where(rd > 0, r / torch.where(rd > 0, rd, torch.ones_like(rd)), 1.0)
    x, y = xd * ratio, yd * ratio
    if tangential:
        x, y, done, det = newton_2d(x, y, xd, yd, lambda a, b, ks: _plain(a, b, ks, True),
                                    k, ~valid, max_iterations)
        inside = (torch.sqrt(x * x + y * y) < limit) & (det > 0)
        valid = done & inside
    return x, y, valid


def _undistort(xd: torch.Tensor, yd: torch.Tensor, distortion: torch.Tensor,
               max_iterations: int):
    """The preimage without gradients: ``(x, y, valid)``, all ``(*, N)``.

    Large inputs are solved in blocks of the point axis (a loop over blocks, not points).
    """
    k = _coeffs(distortion)
    if distortion.shape[-1] == 14:
        xd, yd = _projective(torch.linalg.inv(_tilt(k)), xd, yd)
    limit = _radial_limit(distortion)
    extra = distortion[..., 2:4]
    if distortion.shape[-1] >= 12:
        extra = torch.cat([extra, distortion[..., 8:12]], -1)
    tangential = bool((extra != 0).any())
    xd, yd = torch.broadcast_tensors(xd, yd)
    count = xd.shape[-1]
    step = max(1, _BLOCK // max(1, math.prod(xd.shape[:-1])))
    if count <= step:
        return _undistort_block(xd, yd, k, limit, tangential, max_iterations)
    parts = [_undistort_block(xd[..., i: i + step], yd[..., i: i + step], k, limit,
                              tangential, max_iterations) for i in range(0, count, step)]
    return tuple(torch.cat(p, -1) for p in zip(*parts))


def undistort_points(xy: torch.Tensor, distortion: torch.Tensor,
                     max_iterations: int = 100) -> UndistortResult:
    """The exact inverse of :func:`distort_points`, with where it exists.

    Convention:
        As :func:`distort_points`. The tilt is undone exactly (a homography); the radius
        is found inside the monotone domain ``[0, r*)`` of ``r -> r c(r)`` by Newton
        safeguarded with bisection; the tangential and thin-prism terms by Newton in 2D
        with a trust region, to rounding level (``max_iterations`` is a cap, not a
        count). Gradients by implicit differentiation, in ``xy`` and ``distortion``.

    Args:
        xy: ``(*, N, 2)`` distorted normalised coordinates.
        distortion: ``(*, P)``, ``P`` in ``{4, 5, 8, 12, 14}``.
        max_iterations: cap on each solver's iterations.

    Returns:
        :class:`UndistortResult` ``(points (*, N, 2), valid (*, N))``.

    Example:
        >>> lens = torch.tensor([-0.45, 0.25, 0.0, 0.0], dtype=torch.float64)
        >>> out = undistort_points(torch.tensor([[1.1336, 0.0]], dtype=torch.float64), lens)
        >>> round(float(out.points[0, 0]), 4), bool(out.valid[0])
        (1.2498, True)
        >>> fold = torch.tensor([-0.45, 0.05, 0.0, 0.0], dtype=torch.float64)
        >>> undistort_points(torch.tensor([[0.7, 0.0]], dtype=torch.float64), fold).valid
        tensor([False])
    """
    _check_pair(xy, distortion, _LENGTHS)
    dtype = xy.dtype
    work = torch.float64  # see the module's note on precision
    xy, distortion = xy.to(work), distortion.to(work)
    with torch.no_grad():
        x, y, valid = _undistort(xy[..., 0].detach(), xy[..., 1].detach(),
                                 distortion.detach(), max_iterations)
        bad = xy.isnan().any(-1) | distortion.isnan().any(-1, keepdim=True)
    solution = torch.stack([x, y], -1)
    if xy.requires_grad or distortion.requires_grad:
        k = _coeffs(distortion)
        target_x, target_y = xy[..., 0], xy[..., 1]
        if distortion.shape[-1] == 14:  # differentiable homography back to (x', y')
            target_x, target_y = _projective(torch.linalg.inv(_tilt(k)), target_x, target_y)
        target = torch.stack([target_x, target_y], -1)
        solution = implicit_solution(_plain_residual, valid, solution, target, distortion)
    solution = torch.where(bad[..., None], torch.nan, solution)
    return UndistortResult(cast_back(solution, dtype), valid & ~bad)


# ----------------------------------------------------------------------------- fisheye


def _safe_radius(xy: torch.Tensor) -> torch.Tensor:
    """``|xy|`` over the last axis with a zero (not NaN) gradient at the origin."""
    sq = (xy * xy).sum(-1)
    ok = sq > 0
    return torch.where(ok, torch.sqrt(torch.where(ok, sq, torch.ones_like(sq))), 0.0)


def fisheye_distort_points(xy: torch.Tensor, distortion: torch.Tensor) -> torch.Tensor:
    """Apply the Kannala-Brandt fisheye distortion to normalised image coordinates.

    Convention:
        ``xy = (X / Z, Y / Z)`` (pinhole-normalised, ``Z > 0``), ``theta = atan(|xy|)``,
        ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``, result
        ``xy theta_d / |xy|``: the model of ``cv2.fisheye.projectPoints``.

    Args:
        xy: ``(*, N, 2)`` normalised coordinates.
        distortion: ``(*, 4)`` ``k1, k2, k3, k4``.

    Returns:
        ``(*, N, 2)`` distorted coordinates; differentiable in both inputs.

    Example:
        >>> fisheye_distort_points(torch.tensor([[1.0, 0.0]]), torch.zeros(4))
        tensor([[0.7854, 0.0000]])
    """
    _check_pair(xy, distortion, (4,))
    dtype = xy.dtype
    work = torch.float64  # see the module's note on precision
    xy, distortion = xy.to(work), distortion.to(work)
    r = _safe_radius(xy)
    angle_d = theta_d(torch.atan(r), distortion)[0]
    scale = torch.where(r > 0, angle_d / torch.where(r > 0, r, torch.ones_like(r)), 1.0)
    return cast_back(xy * scale[..., None], dtype)


def fisheye_undistort_points(xy: torch.Tensor, distortion: torch.Tensor) -> UndistortResult:
    """The exact inverse of :func:`fisheye_distort_points`, with where it exists.

    Convention:
        As :func:`fisheye_distort_points`. The result is pinhole-normalised, so it covers
        incidence angles in ``[0, pi/2)`` only (``valid`` is False beyond); the camera's
        ``pixel_rays`` (:func:`torchgeo_cg.cameras.pixel_rays`) covers ``[0, pi)``. The
        angle is found inside the monotone domain of ``theta -> theta_d`` (the first
        root of its derivative, isolated in the Bernstein basis) by Newton safeguarded
        with bisection; gradients by implicit differentiation.

    Args:
        xy: ``(*, N, 2)`` distorted normalised coordinates.
        distortion: ``(*, 4)``.

    Returns:
        :class:`UndistortResult` ``(points (*, N, 2), valid (*, N))``.

    Example:
        >>> out = fisheye_undistort_points(torch.tensor([[0.7854, 0.0]]), torch.zeros(4))
        >>> out.points, out.valid
        (tensor([[1.0000, 0.0000]]), tensor([True]))
    """
    _check_pair(xy, distortion, (4,))
    dtype = xy.dtype
    work = torch.float64  # see the module's note on precision
    xy, distortion = xy.to(work), distortion.to(work)
    rd = _safe_radius(xy)
    theta, valid = fisheye_angle(rd, distortion, math.pi / 2)
    ok = rd > 0
    scale = torch.where(ok, torch.tan(theta) / torch.where(ok, rd, torch.ones_like(rd)), 1.0)
    points = xy * scale[..., None]
    bad = xy.isnan().any(-1) | distortion.isnan().any(-1, keepdim=True)
    points = torch.where(bad[..., None], torch.nan, points)
    return UndistortResult(cast_back(points, dtype), valid & ~bad)
