"""The update step of :func:`~torchgeo_cg.points.icp` for point-to-plane: the linearised
solve, batched over pairs, in float64. (Point-to-point steps are the closed forms
:func:`~torchgeo_cg.transforms.find_euclidean` / :func:`~torchgeo_cg.transforms.find_similarity`.)

Convention:
    - Column vectors, ``p' = M @ p`` with homogeneous ``(B, 4, 4)`` matrices.
    - Correspondences come as ``src (B, N, 3)``, ``dst (B, N, 3)`` and weights
      ``w (B, N) >= 0``; zero weight ignores a row. A pair whose weights sum to zero
      gets a zero step (the identity).
    - Every step is scale-free: no threshold has a unit (the damping of the
      point-to-plane normal equations is relative to their trace).
"""

from __future__ import annotations

import torch

from torchgeo_cg.transforms.rotations import axis_angle_to_matrix

__all__ = ["point_to_plane_step", "apply_transform", "dot3", "weighted_sum"]


def apply_transform(matrix_b44: torch.Tensor, points_bn3: torch.Tensor) -> torch.Tensor:
    """``M @ p`` for homogeneous ``(B, 4, 4)`` and points ``(B, N, 3)``.

    Example:
        >>> m = torch.eye(4)[None].clone()
        >>> m[0, :3, 3] = torch.tensor([1.0, 2.0, 3.0])
        >>> apply_transform(m, torch.zeros(1, 1, 3))
        tensor([[[1., 2., 3.]]])
    """
    return points_bn3 @ matrix_b44[:, :3, :3].transpose(1, 2) + matrix_b44[:, None, :3, 3]


def dot3(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``(..., 3) . (..., 3) -> (...)``, by components (a reduction over a last dimension
    of 3 is several times slower on the CPU).

    Example:
        >>> dot3(torch.tensor([1.0, 2.0, 3.0]), torch.tensor([4.0, 5.0, 6.0]))
        tensor(32.)
    """
    a0, a1, a2 = a.unbind(-1)
    b0, b1, b2 = b.unbind(-1)
    return a0 * b0 + a1 * b1 + a2 * b2


def weighted_sum(w_bn: torch.Tensor, x_bnk: torch.Tensor) -> torch.Tensor:
    """``sum_n w[b, n] x[b, n]`` ``(B, K)`` as one batched product.

    Example:
        >>> weighted_sum(torch.tensor([[1.0, 2.0]]), torch.tensor([[[1.0, 0.0], [0.0, 1.0]]]))
        tensor([[1., 2.]])
    """
    return (w_bn[:, None, :] @ x_bnk)[:, 0]


def point_to_plane_step(p: torch.Tensor, q: torch.Tensor, n: torch.Tensor, w: torch.Tensor,
                        similarity: bool = False, residual: torch.Tensor | None = None
                        ) -> torch.Tensor:
    """One Gauss-Newton step ``(B, 4, 4)`` of ``sum_i w_i ((M p_i - q_i) . n_i)^2``.

    The increment is linearised about the weighted centroid ``c`` of ``p``:
    ``p -> c + exp(sigma) R(omega) (p - c) + v`` (``sigma = 0`` unless ``similarity``),
    with the rotation columns divided by the RMS radius so the normal equations are
    unitless. They are damped by ``1e-12 x trace`` (relative), so a pair with an
    unconstrained direction (a planar target) gets the minimum-norm-like step there.
    ``residual`` ``(B, N)``, when known, is ``(p - q) . n``.

    Example:
        >>> g = torch.Generator().manual_seed(0)
        >>> q = torch.randn(1, 50, 3, generator=g, dtype=torch.float64)
        >>> n = torch.nn.functional.normalize(torch.randn(1, 50, 3, generator=g,
        ...                                               dtype=torch.float64), dim=-1)
        >>> m = point_to_plane_step(q + 1e-3, q, n, torch.ones(1, 50, dtype=torch.float64))
        >>> torch.allclose(m[0, :3, 3], torch.full((3,), -1e-3, dtype=torch.float64))
        True
    """
    total_b = w.sum(-1)
    total_b = torch.where(total_b > 0, total_b, torch.ones_like(total_b))
    c_b3 = weighted_sum(w, p) / total_b[:, None]
    pc = p - c_b3[:, None]
    radius2 = (w * dot3(pc, pc)).sum(-1) / total_b
    rho_b = torch.where(radius2 > 0, radius2, torch.ones_like(radius2)).sqrt()
    u0, u1, u2 = (pc / rho_b[:, None, None]).unbind(-1)
    n0, n1, n2 = n.unbind(-1)
    cols = [u1 * n2 - u2 * n1, u2 * n0 - u0 * n2, u0 * n1 - u1 * n0, n0, n1, n2]  # u x n, n
    if similarity:
        cols.append(u0 * n0 + u1 * n1 + u2 * n2)
    jac_bnk = torch.stack(cols, -1)
    wjac_bkn = (jac_bnk * w[..., None]).transpose(1, 2)
    a_bkk = wjac_bkn @ jac_bnk
    if residual is None:
        residual = dot3(p - q, n)
    rhs_bk = -(wjac_bkn @ residual[..., None])[..., 0]
    trace_b = a_bkk.diagonal(dim1=-2, dim2=-1).sum(-1)
    ok_b = trace_b > 0
    eye_k = torch.eye(a_bkk.shape[-1], dtype=p.dtype, device=p.device)
    damp_b = torch.where(ok_b, 1e-12 * trace_b, torch.ones_like(trace_b))
    x_bk = torch.linalg.solve(a_bkk + damp_b[:, None, None] * eye_k, rhs_bk[..., None])[..., 0]
    x_bk = torch.where(ok_b[:, None], x_bk, torch.zeros_like(x_bk))
    rot = axis_angle_to_matrix(x_bk[:, :3] / rho_b[:, None])
    if similarity:
        rot = rot * x_bk[:, 6].exp()[:, None, None]
    out = torch.eye(4, dtype=p.dtype, device=p.device).repeat(p.shape[0], 1, 1)
    out[:, :3, :3] = rot
    out[:, :3, 3] = c_b3 + x_bk[:, 3:6] - (rot @ c_b3[..., None])[..., 0]
    return out
