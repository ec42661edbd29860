"""Thin ``nn.Module`` wrappers around :mod:`torchgeo_cg.transforms.homogeneous`.

Each module's ``forward`` is one call to the pure function with the same
defaults; its tensors are parameters (learnable) or buffers, so ``.to()`` moves
them.
"""

from __future__ import annotations

import torch
from torch import nn

from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.core.coerce import as_tensor_like
from torchgeo_cg.transforms.homogeneous import compose_trs, transform_points

__all__ = ["TRSTransform", "HomogeneousTransform"]


def _register(module: nn.Module, name: str, value: torch.Tensor, learnable: bool) -> None:
    if learnable:
        setattr(module, name, nn.Parameter(value))
    else:
        module.register_buffer(name, value, persistent=True)


class TRSTransform(nn.Module):
    """A (learnable) compound transform ``T·S·R`` applied to points.

    Convention:
        Column vectors, ``p' = T(offset)·S(scale)·R(angle)·p``; angle in degrees
        unless ``degrees=False``, counter-clockwise. Same as
        :func:`~torchgeo_cg.transforms.compose_trs` with ``row_vectors=False``.

    Args:
        offset: ``(*, 2)`` translation.
        angle: ``(*)`` rotation, a tensor of ``offset``'s dtype and device or a number.
        scale: ``(*)`` uniform or ``(*, 2)`` per-axis scale, like ``angle``.
        degrees: unit of ``angle``.
        learnable: make offset, angle and scale ``nn.Parameter`` (else buffers).

    Example:
        >>> m = TRSTransform(torch.tensor([2.0, 10.0]), torch.tensor(90.0), torch.tensor(0.5))
        >>> m(torch.tensor([[2.0, 0.0]])).detach()
        tensor([[ 2., 11.]])
    """

    def __init__(
        self,
        offset: torch.Tensor,
        angle: torch.Tensor | float,
        scale: torch.Tensor | float,
        degrees: bool = True,
        learnable: bool = True,
    ) -> None:
        super().__init__()
        check_shape(offset, ["*", "2"], "offset")
        check_float(offset, "offset")
        angle = as_tensor_like(angle, offset, "angle", like_name="offset")
        scale = as_tensor_like(scale, offset, "scale", like_name="offset")
        for name, value in (("offset", offset), ("angle", angle), ("scale", scale)):
            _register(self, name, value.detach().clone(), learnable)
        self.degrees = degrees

    def matrix(self) -> torch.Tensor:
        """``(*, 3, 3)`` the current ``T·S·R`` matrix."""
        return compose_trs(self.offset, self.angle, self.scale, degrees=self.degrees)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """``(*, N, 2)`` points -> ``(*, N, 2)`` transformed points."""
        return transform_points(self.matrix(), points)


class HomogeneousTransform(nn.Module):
    """A fixed or learnable ``(*, 3, 3)`` matrix applied with :func:`transform_points`.

    Convention:
        Column vectors, ``p' = M @ [x, y, 1]`` then the perspective divide (``w``
        numerically zero divides by a bound relative to ``M``'s bottom row). The
        matrix is a parameter when ``learnable`` (entries trained freely, no
        normalization of ``M[2, 2]``), else a buffer; ``.to()`` moves it either way.

    Args:
        matrix: ``(*, 3, 3)`` float, copied.
        learnable: register it as a ``nn.Parameter``.
        eps: the divide's guard, as in :func:`transform_points` (``None``: relative).

    Example:
        >>> m = HomogeneousTransform(torch.eye(3) * 2)
        >>> m(torch.tensor([[1.0, 2.0]])).detach()
        tensor([[1., 2.]])
    """

    def __init__(self, matrix: torch.Tensor, learnable: bool = False,
                 eps: float | None = None) -> None:
        super().__init__()
        check_shape(matrix, ["*", "3", "3"], "matrix")
        check_float(matrix, "matrix")
        _register(self, "matrix", matrix.detach().clone(), learnable)
        self.eps = eps

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """``(*, N, 2)`` points -> ``(*, N, 2)`` transformed points."""
        return transform_points(self.matrix, points, eps=self.eps)
