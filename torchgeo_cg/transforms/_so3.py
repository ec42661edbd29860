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
    a, b = sinc(theta), one_minus_cos(theta)
    x, y, z = omega.unbind(-1)
    ax, ay, az = a * x, a * y, a * z
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    xx, yy, zz = x * x, y * y, z * z
    rows = [1 - b * (yy + zz), bxy - az, bxz + ay,
            bxy + az, 1 - b * (xx + zz), byz - ax,
            bxz - ay, byz + ax, 1 - b * (xx + yy)]
    return torch.stack(rows, -1).unflatten(-1, (3, 3))



def canonical(q: torch.Tensor) -> torch.Tensor:
    """``q`` or ``-q``: ``w > 0``, or at ``w = 0`` the largest ``|x|, |y|, |z|`` positive."""
    w, v = q[..., 0], q[..., 1:]
    pivot = v.gather(-1, v.abs().argmax(-1, keepdim=True))[..., 0]
    flip = (w < 0) | ((w == 0) & (pivot < 0))
    return torch.where(flip[..., None], -q, q)



def quat_from_matrix(m: torch.Tensor) -> torch.Tensor:
    """Shepperd (1978): the best-conditioned of the four quaternion pivots."""
    r = m.flatten(-2).unbind(-1)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r
    t = torch.stack([1 + r00 + r11 + r22, 1 + r00 - r11 - r22, 1 - r00 + r11 - r22,
                     1 - r00 - r11 + r22], -1)  # (*, 4): 4 w², 4 x², 4 y², 4 z²
    best = t.argmax(-1, keepdim=True)  # >= 1 for a rotation: no division near zero
    chosen = torch.zeros_like(t, dtype=torch.bool).scatter(-1, best, True)
    s = torch.where(chosen, t, torch.ones_like(t)).sqrt()  # unused pivots fed a safe 1
    a, b, c = r21 - r12, r02 - r20, r10 - r01  # 4 w (x, y, z)
    d, e, f = r01 + r10, r02 + r20, r12 + r21  # 4 (xy, xz, yz)
    cand = torch.stack([
        torch.stack([t[..., 0], a, b, c], -1),
        torch.stack([a, t[..., 1], d, e], -1),
        torch.stack([b, d, t[..., 2], f], -1),
        torch.stack([c, e, f, t[..., 3]], -1),
    ], -2) / (2 * s[..., None])  # row k: the quaternion from pivot k (times 2)
    q = cand.gather(-2, best[..., None].expand(*best.shape[:-1], 1, 4))[..., 0, :]
    q = q / safe_norm(q, keepdim=True).clamp_min(torch.finfo(q.dtype).tiny)
    return canonical(q)



def matrix_from_quat(q: torch.Tensor) -> torch.Tensor:
    w, x, y, z = q.unbind(-1)
    two_s = 2.0 / (q * q).sum(-1)  # unit quaternions give 2; others are normalized
    rows = [
        1 - two_s * (y * y + z * z), two_s * (x * y - z * w), two_s * (x * z + y * w),
        two_s * (x * y + z * w), 1 - two_s * (x * x + z * z), two_s * (y * z - x * w),
        two_s * (x * z - y * w), two_s * (y * z + x * w), 1 - two_s * (x * x + y * y),
    ]
    return torch.stack(rows, -1).unflatten(-1, (3, 3))



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
    series = (2 / w_safe) * polynomial(r2, [1.0, -1 / 3, 1 / 5, -1 / 7])
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
