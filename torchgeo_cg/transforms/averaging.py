"""Averages of rotations: the weighted chordal L2 mean on SO(3)."""

from __future__ import annotations

import torch

from torchgeo_cg.core.check import check_broadcastable, check_float, check_shape
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.transforms._correspondences import pow2_normalize
from torchgeo_cg.transforms._horn import horn_solve
from torchgeo_cg.transforms._so3 import matrix_from_quat

__all__ = ["rotation_mean"]


def rotation_mean(rotations: torch.Tensor, weights: torch.Tensor | None = None) -> torch.Tensor:
    """The weighted chordal L2 mean ``argmin_R Σ w_i ‖R - R_i‖_F²`` over SO(3), batched.

    The minimizer is the rotation nearest (Frobenius) to ``M = Σ w_i R_i``,
    found as the top eigenvector of Horn's 4x4 matrix of ``Mᵀ`` (the same as
    ``U diag(1, 1, det UVᵀ) Vᵀ`` from the SVD of ``M``). Its gradient is exact
    and finite also when ``M``'s singular values repeat (e.g. all ``R_i`` equal).

    Convention:
        Weights are relative (any positive scale gives the same mean); zero
        weights drop a rotation; an all-zero set counts every rotation. Where
        the mean is not unique (e.g. two half-turns about orthogonal axes) a
        finite rotation is returned.

    Args:
        rotations: ``(*, M, 3, 3)`` rotation matrices, ``M >= 1``.
        weights: optional ``(*, M)`` non-negative weights.

    Returns:
        ``(*, 3, 3)`` mean rotations.

    Example:
        >>> from torchgeo_cg.transforms.rotations import so3_exp
        >>> r = so3_exp(torch.tensor([[0.0, 0.0, 0.1], [0.0, 0.0, 0.3]], dtype=torch.float64))
        >>> torch.allclose(rotation_mean(r), so3_exp(torch.tensor([0.0, 0.0, 0.2],
        ...                                                       dtype=torch.float64)))
        True
    """
    sizes = check_shape(rotations, ["*", "M", "3", "3"], "rotations")
    check_float(rotations, "rotations")
    r = rotations.to(working_dtype(rotations.dtype))
    if weights is None:
        w = torch.ones_like(r[..., 0, 0])
    else:
        check_shape(weights, ["*", "M"], "weights", sizes={"M": sizes["M"]})
        check_float(weights, "weights")
        check_broadcastable({"rotations": rotations.shape[:-3], "weights": weights.shape[:-1]})
        w = pow2_normalize(weights.to(r.dtype), -1)
        w = torch.where(w.sum(-1, keepdim=True) == 0, torch.ones_like(w), w)
    total = (r * w[..., None, None]).sum(-3)  # (*, 3, 3)
    sol = horn_solve(total.mT, allow_reflection=False)
    return cast_back(matrix_from_quat(sol.quaternion), rotations.dtype)
