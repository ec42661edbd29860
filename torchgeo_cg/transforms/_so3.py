"""The numerics of 3D rotations shared by the rotation, estimation and kinematics modules.

Batch-first tensors in their working dtype, no validation: the public wrappers in
:mod:`torchgeo_cg.transforms.rotations` check and cast. Quaternions are
``(w, x, y, z)``. Series near 0 switch at thresholds relative to the dtype's
precision, with the double-``where`` idiom.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.numerics import safe_norm


def hat(omega: torch.Tensor) -> torch.Tensor:
    """The skew matrix (*, 3, 3) of (*, 3) vectors: ``hat(ω) p = ω × p``."""
    x, y, z = omega.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).unflatten(-1, (3, 3))


def series_threshold(dtype: torch.dtype, power: int) -> float:
    """Angle below which a series truncated after its ``θ^power`` term is exact to rounding."""
    return float(torch.finfo(dtype).eps) ** (1.0 / (power + 2))



def sinc(theta: torch.Tensor) -> torch.Tensor:
    """``sin θ / θ`` with its series near 0 (exact limit and gradient at 0)."""
    small = theta.abs() < series_threshold(theta.dtype, 4)
    safe = torch.where(small, torch.ones_like(theta), theta)
    t2 = theta * theta
    return torch.where(small, 1 - t2 / 6 * (1 - t2 / 20), torch.sin(safe) / safe)



def one_minus_cos(theta: torch.Tensor) -> torch.Tensor:
    """``(1 - cos θ) / θ² = ½ (sin(θ/2) / (θ/2))²``, accurate for every θ."""
    return 0.5 * sinc(0.5 * theta).square()



_ATAN_SERIES = [1.0, -1 / 3, 1 / 5, -1 / 7]  # atan(r) / r in r²


def polynomial(t2: torch.Tensor, coefficients: list[float]) -> torch.Tensor:
    out = torch.full_like(t2, coefficients[-1])
    for c in reversed(coefficients[:-1]):
        out = out * t2 + c
    return out



def theta_minus_sin(theta: torch.Tensor) -> torch.Tensor:
    """``(θ - sin θ) / θ³``: its Taylor series (to θ^16, exact in float64) below 1."""
    small = theta.abs() < 1.0
    safe = torch.where(small, torch.ones_like(theta), theta)
    coefficients, fact = [], 6.0  # (-1)^k / (2k + 3)!
    for k in range(8):
        coefficients.append((-1) ** k / fact)
        fact *= (2 * k + 4) * (2 * k + 5)
    series = polynomial(theta * theta, coefficients)
    return torch.where(small, series, (safe - torch.sin(safe)) / (safe * safe * safe))



def exp_map(omega: torch.Tensor) -> torch.Tensor:
    """``I + a [ω]× + b [ω]×²`` entrywise, with ``[ω]×² = ω ωᵀ - θ² I`` (no batched 3x3
    matmul; the diagonal as ``1 - b (y² + z²)`` etc., which also avoids ``θ²`` cancelling)."""
    theta = safe_norm(omega)
    return torch.stack(rodrigues_entries(omega.unbind(-1), sinc(theta), one_minus_cos(theta)),
                       -1).unflatten(-1, (3, 3))


def rodrigues_entries(cols, a: torch.Tensor, b: torch.Tensor) -> list[torch.Tensor]:
    """The 9 row-major entries of ``I + a [ω]× + b [ω]×²`` for ``cols = (x, y, z)``."""
    x, y, z = cols
    ax, ay, az = a * x, a * y, a * z
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    xx, yy, zz = x * x, y * y, z * z
    return [1 - b * (yy + zz), bxy - az, bxz + ay,
            bxy + az, 1 - b * (xx + zz), byz - ax,
            bxz - ay, byz + ax, 1 - b * (xx + yy)]


def rodrigues_entries_lazy(cols) -> list[torch.Tensor]:
    """:func:`exp_map`'s entries without autograd: the same coefficients, with the
    series evaluated only on the rows below their thresholds (no double ``where``)."""
    x, y, z = cols
    theta = (x * x).add_(y * y).add_(z * z).sqrt_()
    limit = series_threshold(theta.dtype, 4)
    a = torch.sin(theta).div_(theta)
    half = 0.5 * theta
    h = torch.sin(half).div_(half)
    small = theta < 2 * limit  # every row where either series applies
    if bool(small.any()):
        ts = theta[small]
        a[small] = torch.where(ts < limit, _sinc_series(ts), a[small])
        hs = 0.5 * ts
        h[small] = torch.where(hs < limit, _sinc_series(hs), h[small])
    return rodrigues_entries(cols, a, h.square_().mul_(0.5))


def _sinc_series(theta: torch.Tensor) -> torch.Tensor:
    t2 = theta * theta
    return 1 - t2 / 6 * (1 - t2 / 20)



def canonical(q: torch.Tensor) -> torch.Tensor:
    """``q`` or ``-q``: ``w > 0``, or at ``w = 0`` the largest ``|x|, |y|, |z|`` positive."""
    w, v = q[..., 0], q[..., 1:]
    pivot = v.gather(-1, v.abs().argmax(-1, keepdim=True))[..., 0]
    flip = (w < 0) | ((w == 0) & (pivot < 0))
    return torch.where(flip[..., None], -q, q)



def shepperd_row(r) -> list[torch.Tensor]:
    """Shepperd (1978) for the 9 row-major entries ``r`` of rotation matrices: the row
    ``4 q_k q`` of ``4 q qᵀ`` whose pivot ``4 q_k²`` is the largest (the first on
    ties). The four pivots sum to 4, so the row has norm >= 2 for a rotation and
    >= 1 for any matrix: no branch divides by a small number."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r
    t0, t1 = 1 + r00 + r11 + r22, 1 + r00 - r11 - r22  # 4 w², 4 x²
    t2, t3 = 1 - r00 + r11 - r22, 1 - r00 - r11 + r22  # 4 y², 4 z²
    a, b, c = r21 - r12, r02 - r20, r10 - r01  # 4 w (x, y, z)
    d, e, f = r01 + r10, r02 + r20, r12 + r21  # 4 (xy, xz, yz)
    k1 = t1 > t0
    m = torch.maximum(t0, t1)
    k2 = t2 > m
    k3 = t3 > torch.maximum(m, t2)
    rows = ((t0, a, b, c), (a, t1, d, e), (b, d, t2, f), (c, e, f, t3))
    return [torch.where(k3, rows[3][j], torch.where(k2, rows[2][j], torch.where(
        k1, rows[1][j], rows[0][j]))) for j in range(4)]


def lead_sign(x: torch.Tensor, y: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """-1 where the first of ``x, y, z`` of largest magnitude is negative, else 1."""
    ax, ay, az = x.abs(), y.abs(), z.abs()
    lead = torch.where((ax >= ay) & (ax >= az), x, torch.where(ay >= az, y, z))
    return torch.where(lead < 0, -1.0, 1.0).to(x.dtype)


def quat_entries(r, lazy: bool = False) -> list[torch.Tensor]:
    """The unit quaternion of :func:`shepperd_row`, signed to ``w >= 0``. ``lazy``
    also applies the tie rule of :func:`canonical` (at ``w = 0``) to the rows that
    need it; otherwise the caller applies :func:`canonical`."""
    row = shepperd_row(r)
    w = row[0]
    inv = torch.rsqrt(w * w + row[1] * row[1] + row[2] * row[2] + row[3] * row[3])
    scale = torch.where(w < 0, -inv, inv)
    if lazy:
        tie = w == 0
        if bool(tie.any()):
            scale[tie] *= lead_sign(*(c[tie] for c in row[1:]))
    return [c * scale for c in row]


def quat_from_matrix(m: torch.Tensor) -> torch.Tensor:
    """Unit quaternions (*, 4), canonical, of (*, 3, 3) matrices (:func:`shepperd_row`)."""
    return canonical(torch.stack(quat_entries(m.flatten(-2).unbind(-1)), -1))


def rotvec_entries(r) -> list[torch.Tensor]:
    """Rotation vectors from the 9 entries of rotation matrices, without autograd:
    :func:`shepperd_row` unnormalized (the angle ``2 atan2(|v|, |w|)`` and the axis
    ``v / |v|`` are scale-free), with :func:`rotvec_from_quat`'s series and sign rule
    evaluated only on the rows that need them."""
    c0, c1, c2, c3 = shepperd_row(r)
    w = c0.abs()
    s2 = c1 * c1 + c2 * c2 + c3 * c3
    s = s2.sqrt()
    factor = torch.atan2(s, w).mul_(2).div_(s)
    factor = torch.where(c0 < 0, -factor, factor)
    small = s2 < (series_threshold(s2.dtype, 6) ** 2) * (w * w)
    if bool(small.any()):
        ws, sign = w[small], torch.where(c0[small] < 0, -1.0, 1.0).to(w.dtype)
        factor[small] = sign * (2 / ws) * polynomial(s2[small] / (ws * ws), _ATAN_SERIES)
    tie = c0 == 0
    if bool(tie.any()):
        factor[tie] = factor[tie].abs() * lead_sign(c1[tie], c2[tie], c3[tie])
    return [factor * c1, factor * c2, factor * c3]


def matrix_from_quat(q: torch.Tensor) -> torch.Tensor:
    return torch.stack(quat_matrix_entries(q.unbind(-1)), -1).unflatten(-1, (3, 3))


def quat_matrix_entries(cols) -> list[torch.Tensor]:
    """The 9 row-major entries of the rotation of quaternions ``(w, x, y, z)``,
    normalized through ``2 / |q|²`` (the zero quaternion gives NaN)."""
    w, x, y, z = cols
    s = 2.0 / (w * w + x * x + y * y + z * z)
    sx, sy, sz = s * x, s * y, s * z
    xx, yy, zz = sx * x, sy * y, sz * z
    xy, xz, yz = sx * y, sx * z, sy * z
    wx, wy, wz = sx * w, sy * w, sz * w
    return [1 - (yy + zz), xy - wz, xz + wy,
            xy + wz, 1 - (xx + zz), yz - wx,
            xz - wy, yz + wx, 1 - (xx + yy)]



def quat_from_rotvec(w: torch.Tensor) -> torch.Tensor:
    theta = safe_norm(w, keepdim=True)
    half = 0.5 * sinc(0.5 * theta)  # sin(θ/2) / θ
    return canonical(torch.cat([torch.cos(0.5 * theta), half * w], -1))



def rotvec_from_quat(q: torch.Tensor) -> torch.Tensor:
    q = canonical(q)
    w, v = q[..., :1], q[..., 1:]
    s2 = (v * v).sum(-1, keepdim=True)
    # θ / |v| = 2 atan2(|v|, w) / |v|; for |v| << w it is (2/w) atan(r)/r, r = |v|/w
    small = s2 < (series_threshold(q.dtype, 6) ** 2) * (w * w)
    w_safe = torch.where(small, w, torch.ones_like(w))
    r2 = torch.where(small, s2 / (w_safe * w_safe), torch.zeros_like(s2))
    series = (2 / w_safe) * polynomial(r2, _ATAN_SERIES)
    s = torch.where(small, torch.ones_like(s2), s2).sqrt()
    direct = 2 * torch.atan2(s, w) / s
    return torch.where(small, series, direct) * v



def qmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], -1)



def left_jacobian(omega: torch.Tensor) -> torch.Tensor:
    theta = safe_norm(omega)
    k = hat(omega)
    eye = torch.eye(3, dtype=omega.dtype, device=omega.device)
    b, c = one_minus_cos(theta), theta_minus_sin(theta)
    return eye + b[..., None, None] * k + c[..., None, None] * (k @ k)



def left_jacobian_inverse(omega: torch.Tensor) -> torch.Tensor:
    theta = safe_norm(omega)
    k = hat(omega)
    eye = torch.eye(3, dtype=omega.dtype, device=omega.device)
    # (1/θ²)(1 - (θ/2) cot(θ/2)) = (1/θ²)(1 - A / (2B)) with A = sinc θ, B = (1-cos θ)/θ²
    small = theta < 0.5
    safe = torch.where(small, torch.ones_like(theta), theta)
    direct = (1 - sinc(safe) / (2 * one_minus_cos(safe))) / (safe * safe)
    # series of (1 - (x/2) cot(x/2)) / x² = 1/12 + x²/720 + x⁴/30240 + x⁶/1209600 + ...
    series = polynomial(theta * theta, [1 / 12, 1 / 720, 1 / 30240, 1 / 1209600, 1 / 47900160,
                                   691 / 1307674368000 / 1.0, 1 / 74724249600])
    d = torch.where(small, series, direct)
    return eye - 0.5 * k + d[..., None, None] * (k @ k)
