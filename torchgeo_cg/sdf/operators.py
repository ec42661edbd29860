"""Operators on signed distances: CSG, smooth blends, products and rigid/uniform transforms.

Convention:
    - CSG operators act on *values*: tensors ``(*, N)`` of signed distances, negative
      inside, all broadcast together. Transforms act on *functions*: they take an SDF
      callable ``points (*, N, D) -> (*, N)`` and return another such callable.
    - ``union`` (min) and ``intersection`` (max) return the exact distance outside /
      inside respectively and a lower bound elsewhere (the usual CSG caveat);
      ``difference(a, b) = max(a, -b)`` likewise. They are differentiable almost
      everywhere (the gradient follows the selected operand).
    - ``translate`` and ``rotate`` keep distances exact; ``scale`` keeps them exact for
      a uniform factor (``s * f(p / s)``); non-uniform scaling is not offered because
      it does not preserve distances.
    - Rotations are column-vector ``world_from_local`` matrices (``p_world = R @
      p_local``), as everywhere in torchgeo_cg.
    - dtypes: the values combined by a CSG operator share one dtype and device (else
      ``TypeError`` naming both). Parameters (``k``, offsets, rotations, factors)
      follow the rule of :mod:`torchgeo_cg.sdf`: numbers, numpy values and lists take
      the dtype and device of the values or points they act on, at each call; a
      tensor keeps its dtype and must match them (``TypeError`` naming both; float16,
      bfloat16 and float32 meet), so a float64 ``rotate`` never computes in float32.
      float16/bfloat16 blends are computed in float32 and returned in the input dtype
      (min/max/negation are exact in any dtype).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn

from torchgeo_cg.core.check import check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import as_tensor_like, check_module_dtype, check_same_dtype
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.sdf._params import shape_parameter

__all__ = [
    "union",
    "intersection",
    "difference",
    "smooth_union",
    "smooth_intersection",
    "product",
    "translate",
    "rotate",
    "scale",
    "Union",
    "Intersection",
    "Difference",
    "SmoothUnion",
    "SmoothIntersection",
    "Product",
    "Translate",
    "Rotate",
    "Scale",
]

_SDF = Callable[[torch.Tensor], torch.Tensor]


def _values(*values: torch.Tensor) -> None:
    """Check that the fields are float tensors whose shapes broadcast (names ``sdf[i]``)."""
    for i, v in enumerate(values):
        check_float(v, f"sdf[{i}]")
    check_broadcastable({f"sdf[{i}]": v.shape for i, v in enumerate(values)})
    check_same_dtype({f"sdf[{i}]": v for i, v in enumerate(values)})


def union(a: torch.Tensor, b: torch.Tensor, *more: torch.Tensor) -> torch.Tensor:
    """Union of shapes: the elementwise minimum of their signed distances.

    Convention:
        Negative inside. Exact outside the union, a lower bound of the distance inside.

    Args:
        a, b: ``(*, N)`` signed distances (broadcastable).
        *more: further ``(*, N)`` signed distances.

    Returns:
        ``(*, N)``.

    Example:
        >>> union(torch.tensor([1.0, -2.0]), torch.tensor([0.5, 3.0]))
        tensor([ 0.5000, -2.0000])
    """
    _values(a, b, *more)
    out = torch.minimum(a, b)
    for m in more:
        out = torch.minimum(out, m)
    return out


def intersection(a: torch.Tensor, b: torch.Tensor, *more: torch.Tensor) -> torch.Tensor:
    """Intersection of shapes: the elementwise maximum of their signed distances.

    Convention:
        Negative inside. Exact inside the intersection, a lower bound outside.

    Args:
        a, b: ``(*, N)`` signed distances.
        *more: further ``(*, N)`` signed distances.

    Returns:
        ``(*, N)``.

    Example:
        >>> intersection(torch.tensor([1.0, -2.0]), torch.tensor([0.5, -3.0]))
        tensor([ 1., -2.])
    """
    _values(a, b, *more)
    out = torch.maximum(a, b)
    for m in more:
        out = torch.maximum(out, m)
    return out


def difference(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``a`` minus ``b``: ``max(a, -b)``.

    Convention:
        Negative inside ``a`` and outside ``b``; a bound, exact where ``a`` dominates.

    Args:
        a, b: ``(*, N)`` signed distances.

    Returns:
        ``(*, N)``.

    Example:
        >>> difference(torch.tensor([-1.0, -1.0]), torch.tensor([-0.5, 2.0]))
        tensor([ 0.5000, -1.0000])
    """
    _values(a, b)
    return torch.maximum(a, -b)


def _check_k(k, a: torch.Tensor, b: torch.Tensor, given: torch.Tensor) -> torch.Tensor:
    k = shape_parameter(k, "k", a, given, "sdf[0]")
    check_broadcastable({"sdf[0]": a.shape, "sdf[1]": b.shape, "k": k.shape})
    if bool((k <= 0).any()):  # NaN passes (NaN in, NaN out)
        raise ValueError(f"k: expected a positive blend radius, got {k.min().item()}")
    return k


def smooth_union(a: torch.Tensor, b: torch.Tensor, k: torch.Tensor | float = 0.1) -> torch.Tensor:
    """Polynomial smooth minimum: a union whose crease is rounded over a width ``k``.

    ``h = clamp(1/2 + (b - a) / (2k), 0, 1)``;  ``f = b (1 - h) + a h - k h (1 - h)``.
    Equals ``min(a, b)`` where ``|a - b| >= k``; it is never above ``min(a, b)``.

    Convention:
        Negative inside; ``k > 0`` in distance units, a number or broadcastable tensor.

    Args:
        a, b: ``(*, N)`` signed distances.
        k: blend width (positive).

    Returns:
        ``(*, N)``.

    Example:
        >>> smooth_union(torch.tensor([0.0, 1.0]), torch.tensor([0.0, -1.0]), k=0.5)
        tensor([-0.1250, -1.0000])
    """
    _values(a, b)
    given, dtype = a, a.dtype
    work = working_dtype(dtype)
    a, b = a.to(work), b.to(work)
    k = _check_k(k, a, b, given)
    h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0)
    return cast_back(b * (1.0 - h) + a * h - k * h * (1.0 - h), dtype)


def smooth_intersection(
    a: torch.Tensor, b: torch.Tensor, k: torch.Tensor | float = 0.1
) -> torch.Tensor:
    """Smooth maximum: ``-smooth_union(-a, -b, k)``, an intersection with a rounded crease.

    Convention:
        Negative inside; ``k > 0``; never below ``max(a, b)``.

    Args:
        a, b: ``(*, N)`` signed distances.
        k: blend width (positive).

    Returns:
        ``(*, N)``.

    Example:
        >>> smooth_intersection(torch.tensor([0.0, 1.0]), torch.tensor([0.0, -1.0]), k=0.5)
        tensor([0.1250, 1.0000])
    """
    return -smooth_union(-a, -b, k)


def product(a: torch.Tensor, b: torch.Tensor, *more: torch.Tensor) -> torch.Tensor:
    """The report's merge of implicit functions by multiplication: ``a * b * ...``.

    The zero set of the product is the union of the zero sets, so it draws every
    surface at once. The sign is negative where an odd number of fields are negative:
    for disjoint shapes that is their union, for overlapping shapes the overlap flips
    to "outside". The value is not a distance.

    Convention:
        Inputs negative inside; output is an implicit function, not an SDF.

    Args:
        a, b: ``(*, N)`` implicit values.
        *more: further ``(*, N)`` implicit values.

    Returns:
        ``(*, N)``.

    Example:
        >>> product(torch.tensor([-1.0, 2.0]), torch.tensor([3.0, 0.5]))
        tensor([-3.,  1.])
    """
    _values(a, b, *more)
    work = working_dtype(a.dtype)
    out = a.to(work) * b.to(work)
    for m in more:
        out = out * m.to(work)
    return cast_back(out, a.dtype)


def _built(value, name: str) -> torch.Tensor:
    """A parameter given when a shape is built, as a tensor for the checks made then.

    Numbers and lists are read in float64 here (shape and sign only); each call
    converts the value as given, so it takes the points' dtype (no float32 rounding).
    """
    if isinstance(value, torch.Tensor):
        return as_tensor_like(value, None, name)
    return as_tensor_like(value, torch.empty((), dtype=torch.float64), name)


def translate(sdf_fn: _SDF, offset: torch.Tensor) -> _SDF:
    """Move a shape by ``offset``: returns ``p -> sdf_fn(p - offset)`` (exact).

    Convention:
        ``offset`` is in world units, ``(D,)`` or ``(*, D)`` broadcasting against the
        points' leading dims (one offset per shape of a batch). A numpy array or list
        takes the points' dtype and device at each call; a tensor must have them
        (the rule of :mod:`torchgeo_cg.sdf`).

    Args:
        sdf_fn: callable ``(*, N, D) -> (*, N)``.
        offset: ``(D,)`` or ``(*, D)``.

    Returns:
        A callable ``(*, N, D) -> (*, N)``.

    Example:
        >>> from torchgeo_cg.sdf.primitives import sphere
        >>> moved = translate(sphere, torch.tensor([2.0, 0.0, 0.0]))
        >>> moved(torch.tensor([[2.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
        tensor([-1.,  1.])
    """
    given = offset
    offset = _built(offset, "offset")
    check_shape(offset, ["*", "D"], "offset")

    def moved(points: torch.Tensor) -> torch.Tensor:
        check_float(points, "points")
        check_shape(points, ["*", "N", offset.shape[-1]], "points")
        check_broadcastable({"points": points.shape[:-2], "offset": offset.shape[:-1]})
        shift = shape_parameter(given, "offset", points, points)
        return sdf_fn(points - (shift if shift.dim() == 1 else shift.unsqueeze(-2)))

    return moved


def rotate(sdf_fn: _SDF, world_from_local: torch.Tensor) -> _SDF:
    """Rotate a shape: returns ``p -> sdf_fn(R^T p)`` for ``R = world_from_local`` (exact).

    Convention:
        Column vectors: the shape's local point ``q`` appears at ``R @ q`` in the world,
        so the world point ``p`` is evaluated at ``q = R^T p``. ``R`` must be a rotation
        (orthonormal, det +1); it is not re-orthonormalized. A tensor ``R`` must have
        the points' dtype and device (``TypeError`` naming both; float16, bfloat16 and
        float32 meet and are computed in float32); a numpy array or list takes them at
        each call (the rule of :mod:`torchgeo_cg.sdf`).

    Args:
        sdf_fn: callable ``(*, N, D) -> (*, N)``.
        world_from_local: ``(D, D)`` or ``(*, D, D)`` rotation matrices.

    Returns:
        A callable ``(*, N, D) -> (*, N)``.

    Example:
        >>> from torchgeo_cg.sdf.primitives import capsule
        >>> R = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # +90° about x
        >>> rotate(capsule, R)(torch.tensor([[0.0, -1.0, 0.0]]))  # the axis now points to -y
        tensor([-0.5000])
    """
    given = world_from_local
    world_from_local = _built(world_from_local, "world_from_local")
    check_shape(world_from_local, ["*", "D", "D"], "world_from_local")

    def rotated(points: torch.Tensor) -> torch.Tensor:
        check_float(points, "points")
        check_shape(points, ["*", "N", world_from_local.shape[-1]], "points")
        check_broadcastable({"points": points.shape[:-2],
                             "world_from_local": world_from_local.shape[:-2]})
        work = points.to(working_dtype(points.dtype))
        rotation = shape_parameter(given, "world_from_local", work, points)
        # row form of q = R^T p: q^T = p^T R
        return cast_back(sdf_fn(work @ rotation), points.dtype)

    return rotated


def scale(sdf_fn: _SDF, factor: torch.Tensor | float) -> _SDF:
    """Uniformly scale a shape about the origin: ``p -> s * sdf_fn(p / s)`` (exact).

    Convention:
        ``factor`` is a positive number or ``(*)`` tensor (one per shape of a batch);
        a tensor must have the points' dtype and device, a number takes them (the rule
        of :mod:`torchgeo_cg.sdf`).

    Args:
        sdf_fn: callable ``(*, N, D) -> (*, N)``.
        factor: positive scale factor.

    Returns:
        A callable ``(*, N, D) -> (*, N)``.

    Example:
        >>> from torchgeo_cg.sdf.primitives import sphere
        >>> scale(sphere, 3.0)(torch.tensor([[5.0, 0.0, 0.0]]))
        tensor([2.])
    """
    given = factor
    factor = _built(factor, "factor")
    if bool((factor <= 0).any()):  # NaN passes (NaN in, NaN out)
        raise ValueError(f"factor: expected a positive scale factor, got {factor.min().item()}")

    def scaled(points: torch.Tensor) -> torch.Tensor:
        check_float(points, "points")
        check_shape(points, ["*", "N", "D"], "points")
        check_broadcastable({"points": points.shape[:-2], "factor": factor.shape})
        s = shape_parameter(given, "factor", points, points)
        return s.unsqueeze(-1) * sdf_fn(points / s.unsqueeze(-1).unsqueeze(-1))

    return scaled


# --------------------------------------------------------------------------- modules


class Union(nn.Module):
    """:func:`union` of child SDF modules.

    Example:
        >>> from torchgeo_cg.sdf.primitives import Sphere
        >>> Union(Sphere(1.0), Sphere(1.0, center=[3.0, 0.0, 0.0]))(torch.tensor([[3.0, 0, 0]]))
        tensor([-1.], grad_fn=<MinimumBackward0>)
    """

    def __init__(self, *children: nn.Module):
        super().__init__()
        if len(children) < 2:
            raise ValueError(f"Union: expected at least 2 shapes, got {len(children)}")
        self.shapes = nn.ModuleList(children)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return union(*(s(points) for s in self.shapes))


class Intersection(Union):
    """:func:`intersection` of child SDF modules.

    Example:
        >>> from torchgeo_cg.sdf.primitives import Sphere
        >>> Intersection(Sphere(1.0), Sphere(1.0, [1.0, 0, 0]))(torch.tensor([[0.5, 0, 0]]))
        tensor([-0.5000], grad_fn=<MaximumBackward0>)
    """

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return intersection(*(s(points) for s in self.shapes))


class Difference(nn.Module):
    """:func:`difference` of two SDF modules, ``a`` minus ``b``.

    Example:
        >>> from torchgeo_cg.sdf.primitives import Sphere
        >>> Difference(Sphere(1.0), Sphere(0.5))(torch.zeros(1, 3))
        tensor([0.5000], grad_fn=<MaximumBackward0>)
    """

    def __init__(self, a: nn.Module, b: nn.Module):
        super().__init__()
        self.a, self.b = a, b

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return difference(self.a(points), self.b(points))


def _per_shape(k: torch.Tensor) -> torch.Tensor:
    """A module's ``(*)`` width, one per shape, against ``(*, N)`` values."""
    return k.unsqueeze(-1) if k.dim() > 0 else k


class SmoothUnion(nn.Module):
    """:func:`smooth_union` of two SDF modules with a learnable width ``k``.

    ``k`` is a number or a ``(*)`` tensor, one width per shape of a batch (as the
    primitives' parameters are).

    Example:
        >>> from torchgeo_cg.sdf.primitives import Sphere
        >>> m = SmoothUnion(Sphere(1.0), Sphere(1.0, [2.0, 0, 0]), k=0.5)
        >>> m(torch.tensor([[1.0, 0.0, 0.0]]))
        tensor([-0.1250], grad_fn=<SubBackward0>)
    """

    def __init__(self, a: nn.Module, b: nn.Module, k: float = 0.1, device=None, dtype=None):
        super().__init__()
        self.a, self.b = a, b
        self.k = nn.Parameter(torch.as_tensor(k, device=device, dtype=dtype or
                                              torch.get_default_dtype()).clone())

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return smooth_union(self.a(points), self.b(points), _per_shape(self.k))


class SmoothIntersection(SmoothUnion):
    """:func:`smooth_intersection` of two SDF modules with a learnable width ``k``.

    Example:
        >>> from torchgeo_cg.sdf.primitives import Sphere
        >>> m = SmoothIntersection(Sphere(1.0), Sphere(1.0, [2.0, 0, 0]), k=0.5)
        >>> m(torch.tensor([[1.0, 0.0, 0.0]]))
        tensor([0.1250], grad_fn=<NegBackward0>)
    """

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return smooth_intersection(self.a(points), self.b(points), _per_shape(self.k))


class Product(Union):
    """:func:`product` of child implicit-function modules.

    Example:
        >>> from torchgeo_cg.sdf.primitives import Sphere
        >>> Product(Sphere(1.0), Sphere(1.0, [3.0, 0, 0]))(torch.zeros(1, 3))
        tensor([-2.], grad_fn=<MulBackward0>)
    """

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return product(*(s(points) for s in self.shapes))


class Translate(nn.Module):
    """:func:`translate` a child SDF module by a learnable ``offset (D,)``.

    Example:
        >>> from torchgeo_cg.sdf.primitives import Sphere
        >>> Translate(Sphere(), [0.0, 0.0, 2.0])(torch.tensor([[0.0, 0.0, 2.0]]))
        tensor([-1.], grad_fn=<SubBackward0>)
    """

    def __init__(self, shape: nn.Module, offset, device=None, dtype=None):
        super().__init__()
        self.shape = shape
        self.offset = nn.Parameter(torch.as_tensor(offset, device=device, dtype=dtype).clone()
                                   .to(dtype or torch.get_default_dtype()))

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return translate(self.shape, self.offset)(points)


class Rotate(nn.Module):
    """:func:`rotate` a child SDF module by a fixed ``world_from_local (D, D)`` buffer.

    Example:
        >>> from torchgeo_cg.sdf.primitives import Capsule
        >>> R = torch.tensor([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
        >>> Rotate(Capsule(), R)(torch.tensor([[1.0, 0.0, 0.0]]))  # the axis is now +x
        tensor([-0.5000], grad_fn=<SubBackward0>)
    """

    def __init__(self, shape: nn.Module, world_from_local: torch.Tensor):
        super().__init__()
        world_from_local = as_tensor_like(world_from_local, None, "world_from_local")
        check_shape(world_from_local, ["*", "D", "D"], "world_from_local")
        self.shape = shape
        self.register_buffer("world_from_local", world_from_local.clone(), persistent=False)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return rotate(self.shape, self.world_from_local)(points)


class Scale(nn.Module):
    """:func:`scale` a child SDF module by a learnable uniform ``factor ()``.

    Example:
        >>> from torchgeo_cg.sdf.primitives import Sphere
        >>> Scale(Sphere(), 2.0)(torch.zeros(1, 3))
        tensor([-2.], grad_fn=<MulBackward0>)
    """

    def __init__(self, shape: nn.Module, factor: float = 1.0, device=None, dtype=None):
        super().__init__()
        self.shape = shape
        self.factor = nn.Parameter(torch.as_tensor(factor, device=device, dtype=dtype or
                                                   torch.get_default_dtype()).clone())

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return scale(self.shape, self.factor)(points)
