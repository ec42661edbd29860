"""The dtype rule of a shape's parameters against the points it is evaluated at.

A shape's parameters (radii, centres, half sizes, normals, offsets, rotation
matrices, scale factors, blend widths) are numbers or tensors, given beside the points
(``sphere(points, radius)``), when a shape is built (``translate``, ``rotate``,
``scale``) or held by a module:

- numbers, numpy values and lists have no dtype of their own: they take the points'
  dtype and device at each call;
- a tensor keeps its dtype: it must have the points' dtype and device, else a
  ``TypeError`` names both. float16, bfloat16 and float32 meet each other (the
  low-precision dtypes are computed in float32).

Nothing is cast silently: a float64 shape never computes in float32 and a float32
pipeline never turns float64, as for the modules (``Sphere().double()(points_f32)``
raises) and for peer tensors.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.coerce import as_tensor_like

__all__ = ["shape_parameter"]

_LOW = {torch.float16, torch.bfloat16, torch.float32}


def shape_parameter(value, name: str, work: torch.Tensor, reference: torch.Tensor,
                    reference_name: str = "points") -> torch.Tensor:
    """``value`` as a tensor of ``work``'s dtype and device, by the rule above.

    Args:
        value: a number, numpy value, list or float tensor.
        name: the parameter's name, in every message.
        work: the points (or values) in their working dtype (float32 for float16).
        reference: the points (or values) as given, for the dtype rule and the message.
        reference_name: their name in the message.

    Returns:
        A tensor of ``work``'s dtype and device (the same object when it already is).

    Raises:
        TypeError: ``value`` is a tensor of another dtype (outside the low-precision
            family) or device than ``reference``, an integer tensor, a bool or not numeric.

    Example:
        >>> points = torch.zeros(2, 3)
        >>> shape_parameter(0.5, "radius", points, points).dtype
        torch.float32
        >>> shape_parameter(torch.ones((), dtype=torch.float64), "radius", points, points)
        Traceback (most recent call last):
        ...
        TypeError: radius is torch.float64 on cpu but points is torch.float32 on cpu; ...
    """
    if isinstance(value, torch.Tensor) and value.is_floating_point():
        dtypes = {value.dtype, reference.dtype}
        if (value.dtype != reference.dtype and not dtypes <= _LOW) or (
                value.device != reference.device):
            raise TypeError(
                f"{name} is {value.dtype} on {value.device} but {reference_name} is "
                f"{reference.dtype} on {reference.device}; convert one with .to() (a "
                "shape's tensor parameters keep their dtype, numbers follow the points)")
        return value.to(work.dtype)
    return as_tensor_like(value, work, name)
