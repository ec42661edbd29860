"""The Kannala-Brandt angle map ``theta -> theta_d``, and its exact inverse on the
monotone domain."""

from __future__ import annotations

import torch

from torchgeo_cg.cameras._implicit import implicit_solution
from torchgeo_cg.cameras._roots import first_root
from torchgeo_cg.cameras._solve import solve_monotone


def angle_map(theta: torch.Tensor, k1, k2, k3, k4):
    """``theta_d(theta)`` and its slope, the coefficients broadcast against ``theta``."""
    t2 = theta * theta
    value = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    slope = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
    return value, slope


def theta_d(theta: torch.Tensor, k: torch.Tensor):
    """Kannala-Brandt ``theta_d(theta)`` and its slope; ``k (*, 4)`` meets ``theta (*, N)``."""
    return angle_map(theta, *(k[..., i, None] for i in range(4)))


def fisheye_limit(distortion: torch.Tensor, cap: float) -> torch.Tensor:
    """``theta*`` per lens, ``(*, 1)``: the first root of ``theta_d'`` in ``(0, cap)``, or
    ``cap``."""
    with torch.no_grad():
        k = distortion.detach().double().reshape(-1, 4)
        one = torch.ones_like(k[:, 0])
        slope = torch.stack([one, 3 * k[:, 0], 5 * k[:, 1], 7 * k[:, 2], 9 * k[:, 3]], -1)
        theta = torch.sqrt(first_root(slope, cap * cap)).clamp_max(cap)
    return theta.reshape(distortion.shape[:-1] + (1,)).to(distortion.dtype)


def _angle_residual(theta: torch.Tensor, rd: torch.Tensor, distortion: torch.Tensor):
    return theta_d(theta[..., 0], distortion)[0][..., None] - rd[..., None]


def fisheye_angle(rd: torch.Tensor, distortion: torch.Tensor, cap: float):
    """The incidence angle ``theta`` with ``theta_d(theta) = rd`` in ``[0, min(theta*, cap))``.

    ``rd (*, N)`` (differentiable), ``distortion (*, 4)``; returns ``(theta, valid)``
    with the implicit gradient in both.
    """
    with torch.no_grad():
        limit = fisheye_limit(distortion, cap)
        rd_d, k_d = rd.detach(), distortion.detach()
        top = theta_d(limit, k_d)[0]
        inside = rd_d < top
        ks = [k_d[..., i, None] for i in range(4)]
        theta, done = solve_monotone(rd_d, lambda t, p: angle_map(t, *p), limit, ks, ~inside)
        valid = done & inside
    theta = implicit_solution(_angle_residual, valid, theta[..., None], rd, distortion)
    return theta[..., 0], valid
