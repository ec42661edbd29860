"""Joints of 3D articulated chains: revolute and prismatic (report section 2.3, in 3D).

A joint maps joint values ``q (*)`` to the ``(*, 4, 4)`` ``parent_from_child``
matrices of the link it moves. Joints are nodes of a
:class:`~torchgeo_cg.transforms.SceneGraph`; a graph of them evaluates the forward
kinematics of a whole chain (or tree) for ``T`` joint configurations at once, one
batched matmul per tree level, differentiable in the joint values.

Convention:
    - Column vectors, ``p_parent = parent_from_child @ p_child``.
    - ``origin`` is the joint frame in the parent's frame at ``q = 0`` (URDF's
      ``<joint><origin>``): a ``(3,)`` offset (axes parallel to the parent's) or a
      ``(4, 4)`` rigid matrix. The joint moves the child relative to the joint frame:
      ``parent_from_child(q) = origin @ motion(q)``.
    - ``axis`` is a direction in the joint frame (normalised at construction; a zero
      axis is a ValueError).
    - Revolute: ``q`` in **radians**, counter-clockwise (right-handed) about ``axis``.
      Prismatic: ``q`` in length units along ``axis``.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.core.coerce import as_tensor_like, check_module_dtype
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.transforms._so3 import hat

__all__ = ["Revolute", "Prismatic"]


def _unit_axis(axis, name: str) -> torch.Tensor:
    axis = as_tensor_like(axis, None, name)
    check_shape(axis, ["3"], name)
    check_float(axis, name)
    norm = torch.linalg.vector_norm(axis.double())
    if not bool(norm > 0):  # NaN axes stay NaN below; only the zero axis has no direction
        if not bool(norm.isnan()):
            raise ValueError(f"{name}: expected a non-zero direction, got {axis.tolist()}")
    return (axis.double() / norm).to(axis.dtype)


def _origin_matrix(origin, like: torch.Tensor) -> torch.Tensor:
    if origin is None:
        return torch.eye(4, dtype=like.dtype, device=like.device)
    origin = as_tensor_like(origin, like, "origin", like_name="axis")
    if origin.shape == (3,):
        out = torch.eye(4, dtype=origin.dtype, device=origin.device)
        out[:3, 3] = origin
        return out
    check_shape(origin, ["4", "4"], "origin")
    return origin.clone()


def _homogeneous(linear: torch.Tensor, offset: torch.Tensor) -> torch.Tensor:
    """``[[linear, offset], [0, 0, 0, 1]]`` of ``(*, 3, 3)`` and ``(*, 3)``, out of place."""
    top = torch.cat([linear, offset[..., None]], -1)  # (*, 3, 4)
    bottom = torch.zeros_like(top[..., :1, :])
    bottom = torch.cat([bottom[..., :3], torch.ones_like(bottom[..., 3:])], -1)  # (*, 1, 4)
    return torch.cat([top, bottom], -2)


class _Joint(nn.Module):
    def __init__(self, axis, origin=None) -> None:
        super().__init__()
        if isinstance(origin, torch.Tensor) and not isinstance(axis, torch.Tensor):
            axis = as_tensor_like(axis, origin, "axis")  # a list axis takes origin's dtype
        unit = _unit_axis(axis, "axis")
        self.register_buffer("axis", unit, persistent=True)
        self.register_buffer("origin", _origin_matrix(origin, unit), persistent=True)

    def _motion(self, q: torch.Tensor, axis: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def forward(self, q: torch.Tensor) -> torch.Tensor:
        """``(*)`` joint values -> ``(*, 4, 4)`` ``parent_from_child``."""
        check_module_dtype(self, q, "q")
        check_float(q, "q")
        qw = q.to(working_dtype(q.dtype))
        axis, origin = self.axis.to(qw), self.origin.to(qw)
        local = origin @ self._motion(qw, axis)
        # a NaN joint value gives a NaN matrix, also in the entries the motion leaves fixed
        local = torch.where(qw.isnan()[..., None, None], math.nan, local)
        return cast_back(local, q.dtype)


class Revolute(_Joint):
    """A revolute (hinge) joint: rotation by ``q`` radians about ``axis``.

    ``parent_from_child(q) = origin @ [[R(axis, q), 0], [0, 1]]`` with Rodrigues'
    ``R = I + sin q K + 2 sin²(q/2) K²``, ``K = hat(axis)`` (exact for every ``q``, no
    series needed since the axis is a unit vector).

    Convention:
        See the module docstring: column vectors, ``q`` in radians, right-handed about
        the unit ``axis`` given in the joint frame; ``origin`` is the joint frame in the
        parent's frame, a ``(3,)`` offset or a ``(4, 4)`` matrix. The result follows
        ``q``'s dtype, which must be the joint's (``.to(dtype)``); float16/bfloat16 are
        computed in float32 and cast back.

    Args:
        axis: ``(3,)`` rotation axis (any non-zero length).
        origin: ``None`` (the identity), a ``(3,)`` offset or a ``(4, 4)`` matrix;
            tensors ``axis`` and ``origin`` share one dtype (a list takes the other's).

    Example:
        >>> joint = Revolute([0.0, 0.0, 1.0], origin=[1.0, 0.0, 0.0])
        >>> joint(torch.tensor([math.pi / 2]))[0].round(decimals=4) + 0.0
        tensor([[ 0., -1.,  0.,  1.],
                [ 1.,  0.,  0.,  0.],
                [ 0.,  0.,  1.,  0.],
                [ 0.,  0.,  0.,  1.]])
    """

    def _motion(self, q: torch.Tensor, axis: torch.Tensor) -> torch.Tensor:
        k = hat(axis)  # (3, 3)
        s, h = torch.sin(q)[..., None, None], torch.sin(0.5 * q)[..., None, None]
        eye = torch.eye(3, dtype=q.dtype, device=q.device)
        rot = eye + s * k + 2 * h * h * (k @ k)  # (*, 3, 3)
        return _homogeneous(rot, torch.zeros_like(rot[..., 0]))


class Prismatic(_Joint):
    """A prismatic (sliding) joint: translation by ``q`` along ``axis``.

    ``parent_from_child(q) = origin @ [[I, q·axis], [0, 1]]``.

    Convention:
        See the module docstring: column vectors, ``q`` in length units along the unit
        ``axis`` given in the joint frame; ``origin`` is the joint frame in the parent's
        frame, a ``(3,)`` offset or a ``(4, 4)`` matrix. The result follows ``q``'s
        dtype, which must be the joint's (``.to(dtype)``); float16/bfloat16 are computed
        in float32 and cast back.

    Args:
        axis: ``(3,)`` sliding direction (any non-zero length).
        origin: ``None`` (the identity), a ``(3,)`` offset or a ``(4, 4)`` matrix;
            tensors ``axis`` and ``origin`` share one dtype (a list takes the other's).

    Example:
        >>> joint = Prismatic([0.0, 2.0, 0.0], origin=[0.0, 0.0, 1.0])
        >>> joint(torch.tensor([0.0, 0.5]))[:, :3, 3]
        tensor([[0.0000, 0.0000, 1.0000],
                [0.0000, 0.5000, 1.0000]])
    """

    def _motion(self, q: torch.Tensor, axis: torch.Tensor) -> torch.Tensor:
        eye = torch.eye(3, dtype=q.dtype, device=q.device).expand(*q.shape, 3, 3)
        return _homogeneous(eye, q[..., None] * axis)
