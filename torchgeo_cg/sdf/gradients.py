"""Gradients and normals of SDFs by autograd, and the Eikonal regularizer.

Convention:
    For a signed distance ``f`` (negative inside) the gradient ``grad f`` points
    outward and is the surface normal on the zero set; an exact SDF has
    ``|grad f| = 1`` almost everywhere, which :func:`eikonal_loss` penalizes
    (Gropp et al. 2020, "Implicit Geometric Regularization", eq. 2).
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from torchgeo_cg.core.check import check_choice, check_float, check_shape
from torchgeo_cg.core.numerics import cast_back, safe_div, safe_norm, working_dtype

__all__ = ["sdf_gradient", "sdf_normal", "eikonal_loss"]


def sdf_gradient(
    sdf_fn: Callable[[torch.Tensor], torch.Tensor],
    points: torch.Tensor,
    create_graph: bool = True,
) -> torch.Tensor:
    """Spatial gradient ``grad f(p)`` of an SDF by autograd, one per point.

    Convention:
        ``sdf_fn`` maps ``(*, N, 3)`` (or ``(*, N, 2)``) to ``(*, N)`` and each output
        depends only on its own point (true of every SDF), so the gradient of the sum
        is the per-point gradient. Works under ``torch.no_grad()`` too.

    Args:
        sdf_fn: callable ``(*, N, D) -> (*, N)``.
        points: ``(*, N, D)`` float.
        create_graph: keep the graph so the result can be differentiated again (needed
            to train with :func:`eikonal_loss`).

    Returns:
        ``(*, N, D)`` gradients.

    Example:
        >>> from torchgeo_cg.sdf.primitives import sphere
        >>> sdf_gradient(sphere, torch.tensor([[3.0, 4.0, 0.0]]))
        tensor([[0.6000, 0.8000, 0.0000]], grad_fn=<...>)
    """
    check_float(points, "points")
    check_shape(points, ["*", "N", "D"], "points")
    with torch.enable_grad():
        p = points if points.requires_grad else points.detach().requires_grad_(True)
        values = sdf_fn(p)
        if not isinstance(values, torch.Tensor) or values.shape != points.shape[:-1]:
            got = tuple(values.shape) if isinstance(values, torch.Tensor) else type(values)
            raise ValueError(f"sdf_fn: expected output shape {tuple(points.shape[:-1])}, "
                             f"got {got}")
        if not values.requires_grad:  # constant field
            return torch.zeros_like(points)
        (grad,) = torch.autograd.grad(values.sum(), p, create_graph=create_graph)
    return grad


def sdf_normal(
    sdf_fn: Callable[[torch.Tensor], torch.Tensor], points: torch.Tensor,
    create_graph: bool = True,
) -> torch.Tensor:
    """Unit outward normals ``grad f / |grad f|`` (zero where the gradient vanishes).

    Convention:
        Outward for an SDF that is negative inside.

    Args:
        sdf_fn: callable ``(*, N, D) -> (*, N)``.
        points: ``(*, N, D)``.
        create_graph: as in :func:`sdf_gradient`.

    Returns:
        ``(*, N, D)``.

    Example:
        >>> from torchgeo_cg.sdf.primitives import torus
        >>> sdf_normal(lambda p: torus(p, exact=False), torch.tensor([[0.0, 0.0, 1.0]])).detach()
        tensor([[0., 0., 1.]])
    """
    g = sdf_gradient(sdf_fn, points, create_graph)
    return safe_div(g, safe_norm(g, keepdim=True))  # overflow-safe; zero where g = 0


def eikonal_loss(gradients: torch.Tensor, reduction: str = "mean") -> torch.Tensor:
    """Eikonal penalty ``(|grad f| - 1)^2`` that pushes a learned field towards a distance.

    Convention:
        Finite gradient everywhere, also where ``grad f = 0`` (safe norm); the norm is
        overflow-safe. Zero points give ``0`` for ``"mean"`` and ``"sum"`` (a penalty
        over nothing) and an empty ``(*, 0)`` for ``"none"``, never NaN.
        float16/bfloat16 are computed in float32 and returned in their dtype.

    Args:
        gradients: ``(*, N, D)``, typically ``sdf_gradient(model, points)``.
        reduction: ``"mean"`` (a scalar), ``"sum"`` or ``"none"`` (``(*, N)``).

    Returns:
        A scalar, or ``(*, N)`` with ``reduction="none"``.

    Example:
        >>> eikonal_loss(torch.tensor([[1.0, 0.0, 0.0], [0.0, 3.0, 4.0]]), reduction="none")
        tensor([ 0., 16.])
    """
    check_float(gradients, "gradients")
    check_shape(gradients, ["*", "N", "D"], "gradients")
    check_choice(reduction, ("mean", "sum", "none"), "reduction")
    work = gradients.to(working_dtype(gradients.dtype))
    per_point = (safe_norm(work) - 1.0) ** 2
    if reduction == "mean":
        out = per_point.sum() / max(per_point.numel(), 1)
    elif reduction == "sum":
        out = per_point.sum()
    else:
        out = per_point
    return cast_back(out, gradients.dtype)
