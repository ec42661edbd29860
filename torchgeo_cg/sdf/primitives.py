"""Signed distance primitives: pure functions on points, then thin ``nn.Module`` s.

Convention:
    - A signed distance function (SDF) maps points ``(*, N, D)`` to ``(*, N)``;
      it is **negative inside**, zero on the surface and positive outside.
    - Points are ``(x, y, z)`` (or ``(x, y)`` in 2D) in world units, last axis.
    - Shape parameters broadcast against the leading batch dimensions ``(*)``:
      a scalar parameter may be a number or a ``(*)`` tensor, a vector parameter
      (center, half size, normal, end point) a ``(D,)`` or ``(*, D)`` tensor. So one
      call evaluates B shapes at once with ``points (B, N, 3)`` and ``radius (B,)``.
    - "Exact" means the value is the true Euclidean distance to the surface
      (``|grad f| = 1`` almost everywhere). :func:`gyroid` and ``torus(exact=False)``
      (the algebraic torus ``(sqrt(x²+y²) - R)² + z² - r²``) are *not* exact distances.
    - Every function is differentiable in the points and the parameters, with finite
      gradients everywhere: norms are the overflow-safe
      :func:`~torchgeo_cg.core.numerics.hypot`, exact at every scale (no threshold),
      with a zero gradient at the zero vector (no inf, no NaN). A value is finite
      wherever the true distance is, over the whole range of the dtype
      (``|p| = 2e19`` in float32 included).
    - Parameters follow the rule of :mod:`torchgeo_cg.sdf`: numbers, numpy values and
      lists take the dtype and device of ``points``; a tensor parameter must have the
      points' dtype and device (``TypeError`` naming both otherwise; float16, bfloat16
      and float32 meet). float16/bfloat16 points are computed in float32 and the
      result is returned in their dtype. NaN in any input gives NaN out.
    - :func:`sphere`, :func:`box`, :func:`capsule` and :func:`plane` work in 2D and 3D;
      :func:`circle`, :func:`rectangle` and :func:`annulus` are the named 2D counterparts.
"""

from __future__ import annotations

import torch
from torch import nn

from torchgeo_cg.core.check import ShapeError, check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.core.numerics import cast_back, hypot, safe_div, working_dtype
from torchgeo_cg.sdf._params import shape_parameter

__all__ = [
    "sphere",
    "box",
    "capsule",
    "plane",
    "torus",
    "gyroid",
    "circle",
    "rectangle",
    "annulus",
    "Sphere",
    "Box",
    "Capsule",
    "Plane",
    "Torus",
    "Gyroid",
    "Circle",
    "Rectangle",
    "Annulus",
]

_Number = float | int


def _norm(v: torch.Tensor) -> torch.Tensor:
    """``|v|`` over the last dim (2 or 3 components), overflow-safe, zero gradient at 0."""
    return hypot(*v.unbind(-1))


def _points(points: torch.Tensor, dims: tuple[int, ...] = (2, 3)) -> torch.Tensor:
    """Check ``points`` is a float ``(*, N, D)`` tensor with ``D`` in ``dims``.

    Returns the points in the working dtype (float32 for float16/bfloat16).
    """
    check_float(points, "points")
    check_shape(points, ["*", "N", "D"], "points")
    dim = points.shape[-1]
    if dim not in dims:
        expected = " or ".join(str(d) for d in dims)
        raise ShapeError(f"points: expected shape (*, N, {expected.replace(' or ', '|')}), got "
                         f"{tuple(points.shape)}")
    return points.to(working_dtype(points.dtype))


def _scalar(x: torch.Tensor | _Number, name: str, like: torch.Tensor,
            points: torch.Tensor) -> torch.Tensor:
    """A ``(*)`` parameter as a tensor shaped ``(*, 1)`` to broadcast against ``(*, N)``.

    ``like`` is the points in the working dtype, ``points`` as given (the dtype rule).
    """
    x = shape_parameter(x, name, like, points)
    return x.unsqueeze(-1) if x.dim() > 0 else x


def _vector(x: torch.Tensor | None, name: str, like: torch.Tensor, points: torch.Tensor,
            default=0.0) -> torch.Tensor:
    """A ``(D,)`` or ``(*, D)`` parameter shaped ``(*, 1, D)`` to broadcast against points."""
    dim = like.shape[-1]
    if x is None:
        return like.new_full((dim,), float(default))
    x = shape_parameter(x, name, like, points)
    check_shape(x, ["*", dim], name)
    return x if x.dim() == 1 else x.unsqueeze(-2)


def _batches(work: torch.Tensor, scalars: dict[str, torch.Tensor],
             vectors: dict[str, torch.Tensor] | None = None) -> None:
    """Check that the parameters' batch dims broadcast with the points' ``(*)``.

    ``scalars`` are as :func:`_scalar` returns them (``(*, 1)`` or ``()``), ``vectors`` as
    :func:`_vector` does (``(*, 1, D)`` or ``(D,)``).
    """
    batches = {"points": work.shape[:-2]}
    batches.update({n: x.shape[:-1] for n, x in scalars.items()})
    batches.update({n: x.shape[:-2] for n, x in (vectors or {}).items()})
    check_broadcastable(batches)


def sphere(
    points: torch.Tensor, radius: torch.Tensor | _Number = 1.0, center: torch.Tensor | None = None
) -> torch.Tensor:
    """Exact SDF of a sphere (a circle in 2D): ``|p - center| - radius``.

    Convention:
        Negative inside. Works for ``D = 2`` or ``3``; ``center`` defaults to the origin.

    Args:
        points: ``(*, N, D)`` query points.
        radius: number or ``(*)`` tensor.
        center: ``(D,)`` or ``(*, D)``; ``None`` is the origin.

    Returns:
        ``(*, N)`` signed distances.

    Example:
        >>> sphere(torch.tensor([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]), radius=1.0)
        tensor([-1.,  1.])
    """
    work = _points(points)
    r = _scalar(radius, "radius", work, points)
    c = _vector(center, "center", work, points)
    _batches(work, {"radius": r}, {"center": c})
    return cast_back(_norm(work - c) - r, points.dtype)


def circle(
    points: torch.Tensor, radius: torch.Tensor | _Number = 1.0, center: torch.Tensor | None = None
) -> torch.Tensor:
    """Exact 2D SDF of a disk: :func:`sphere` restricted to ``points (*, N, 2)``.

    Convention:
        Negative inside; (x, y) order.

    Args:
        points: ``(*, N, 2)``.
        radius: number or ``(*)``.
        center: ``(2,)`` or ``(*, 2)``; ``None`` is the origin.

    Returns:
        ``(*, N)``.

    Example:
        >>> circle(torch.tensor([[3.0, 4.0]]), radius=2.0)
        tensor([3.])
    """
    _points(points, (2,))
    return sphere(points, radius, center)


def box(
    points: torch.Tensor,
    half_size: torch.Tensor | None = None,
    radius: torch.Tensor | _Number = 0.0,
    center: torch.Tensor | None = None,
) -> torch.Tensor:
    """Exact SDF of an axis-aligned box with rounded edges (2D: a rectangle).

    ``q = |p - center| - half_size + radius``;
    ``f = |max(q, 0)| + min(max_i q_i, 0) - radius``.

    Convention:
        Negative inside. ``half_size`` is the outer half extent *including* the
        rounding, so ``radius`` only rounds the corners and edges (``0 <= radius <=
        min(half_size)``). Exact inside and outside.

    Args:
        points: ``(*, N, D)``, ``D`` = 2 or 3.
        half_size: ``(D,)`` or ``(*, D)``; ``None`` means all ones (the cube ``[-1, 1]^D``).
        radius: rounding radius, number or ``(*)``.
        center: ``(D,)`` or ``(*, D)``; ``None`` is the origin.

    Returns:
        ``(*, N)``.

    Example:
        >>> box(torch.tensor([[0.0, 0.0, 0.0], [2.0, 2.0, 1.0]]), torch.tensor([1.0, 1.0, 1.0]))
        tensor([-1.0000,  1.4142])
    """
    work = _points(points)
    b = _vector(half_size, "half_size", work, points, default=1.0)
    r = _scalar(radius, "radius", work, points)
    c = _vector(center, "center", work, points)
    _batches(work, {"radius": r}, {"half_size": b, "center": c})
    q = (work - c).abs() - b + r.unsqueeze(-1)
    outside = _norm(q.clamp_min(0.0))
    inside = q.amax(dim=-1).clamp_max(0.0)
    return cast_back(outside + inside - r, points.dtype)


def rectangle(
    points: torch.Tensor,
    half_size: torch.Tensor | None = None,
    radius: torch.Tensor | _Number = 0.0,
    center: torch.Tensor | None = None,
) -> torch.Tensor:
    """Exact 2D SDF of a (rounded) rectangle: :func:`box` for ``points (*, N, 2)``.

    Convention:
        Negative inside; ``half_size`` is the outer half extent ``(hx, hy)``.

    Args:
        points: ``(*, N, 2)``.
        half_size: ``(2,)`` or ``(*, 2)``; ``None`` means ``(1, 1)``.
        radius: corner radius, number or ``(*)``.
        center: ``(2,)`` or ``(*, 2)``.

    Returns:
        ``(*, N)``.

    Example:
        >>> rectangle(torch.tensor([[0.0, 0.0], [3.0, 0.0]]), torch.tensor([2.0, 1.0]))
        tensor([-1.,  1.])
    """
    _points(points, (2,))
    return box(points, half_size, radius, center)


def capsule(
    points: torch.Tensor,
    start: torch.Tensor | None = None,
    end: torch.Tensor | None = None,
    radius: torch.Tensor | _Number = 0.5,
) -> torch.Tensor:
    """Exact SDF of a capsule: points within ``radius`` of the segment ``start -> end``.

    Convention:
        Negative inside; 2D (a stadium) or 3D. ``start`` defaults to the origin and
        ``end`` to ``(0, ..., 0, 1)`` (the last axis). A zero-length segment is a sphere.

    Args:
        points: ``(*, N, D)``.
        start: ``(D,)`` or ``(*, D)``.
        end: ``(D,)`` or ``(*, D)``.
        radius: number or ``(*)``.

    Returns:
        ``(*, N)``.

    Example:
        >>> capsule(torch.tensor([[1.0, 0.0, 0.5], [0.0, 0.0, 3.0]]), radius=0.5)
        tensor([0.5000, 1.5000])
    """
    work = _points(points)
    dim = work.shape[-1]
    a = _vector(start, "start", work, points)
    if end is None:
        end = work.new_zeros(dim)
        end[-1] = 1.0
    b = _vector(end, "end", work, points)
    r = _scalar(radius, "radius", work, points)
    _batches(work, {"radius": r}, {"start": a, "end": b})
    pa, ba = work - a, b - a
    # t = (pa . ba) / |ba|^2 as (pa . u) / |ba| with u = ba / |ba|: no |ba|^2 to overflow
    length = _norm(ba).unsqueeze(-1)
    unit = safe_div(ba, length)  # zero for a zero-length segment (a sphere)
    t = safe_div((pa * unit).sum(-1, keepdim=True), length).clamp(0.0, 1.0)
    return cast_back(_norm(pa - t * ba) - r, points.dtype)


def plane(
    points: torch.Tensor, normal: torch.Tensor | None = None, offset: torch.Tensor | _Number = 0.0
) -> torch.Tensor:
    """Exact SDF of the half-space ``n . p <= offset`` with ``n = normal / |normal|``.

    Convention:
        ``f = n . p - offset``: negative on the side opposite to ``normal`` (inside),
        positive on the side ``normal`` points to. ``normal`` defaults to the last axis
        (``+z`` in 3D, ``+y`` in 2D) and is normalized (a zero normal is an error).

    Args:
        points: ``(*, N, D)``.
        normal: ``(D,)`` or ``(*, D)``, any nonzero length.
        offset: signed distance of the plane from the origin along ``n``: number or ``(*)``.

    Returns:
        ``(*, N)``.

    Example:
        >>> plane(torch.tensor([[0.0, 0.0, 3.0]]), torch.tensor([0.0, 0.0, 2.0]), offset=1.0)
        tensor([2.])
    """
    work = _points(points)
    dim = work.shape[-1]
    if normal is None:
        normal = work.new_zeros(dim)
        normal[-1] = 1.0
    n = _vector(normal, "normal", work, points)
    d = _scalar(offset, "offset", work, points)
    _batches(work, {"offset": d}, {"normal": n})
    length = _norm(n).unsqueeze(-1)
    if bool((length == 0).any()):
        raise ValueError("normal: expected a nonzero vector, got a zero normal")
    return cast_back((work * (n / length)).sum(-1) - d, points.dtype)


def torus(
    points: torch.Tensor,
    major_radius: torch.Tensor | _Number = 1.0,
    minor_radius: torch.Tensor | _Number = 0.25,
    exact: bool = True,
) -> torch.Tensor:
    """SDF of a torus around the z axis (exact, or the algebraic torus of the course report).

    With ``s = sqrt((sqrt(x^2 + y^2) - R)^2 + z^2)`` the distance to the tube's core
    circle: ``exact=True`` gives ``s - r`` (the true distance), ``exact=False`` the
    report's algebraic ``f = (sqrt(x^2 + y^2) - R)^2 + z^2 - r^2 = s^2 - r^2``, which has
    the same zero set and sign but ``|grad f| = 2 s`` (``2 r`` on the surface).

    Convention:
        Negative inside; centered at the origin, the core circle lies in the xy plane.

    Args:
        points: ``(*, N, 3)``.
        major_radius: ``R``, center of torus to center of tube; number or ``(*)``.
        minor_radius: ``r``, tube radius; number or ``(*)``.
        exact: Euclidean distance (default) or the report's algebraic function.

    Returns:
        ``(*, N)``.

    Example:
        >>> p = torch.tensor([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
        >>> torus(p, 1.0, 0.25), torus(p, 1.0, 0.25, exact=False)
        (tensor([-0.2500,  0.7500]), tensor([-0.0625,  0.9375]))
    """
    work = _points(points, (3,))
    big = _scalar(major_radius, "major_radius", work, points)
    small = _scalar(minor_radius, "minor_radius", work, points)
    _batches(work, {"major_radius": big, "minor_radius": small})
    x, y, z = work.unbind(-1)
    rho = hypot(x, y) - big
    s = hypot(rho, z)
    if exact:
        return cast_back(s - small, points.dtype)
    return cast_back((s - small) * (s + small), points.dtype)  # s^2 - r^2, no overflow


def annulus(
    points: torch.Tensor,
    major_radius: torch.Tensor | _Number = 1.0,
    minor_radius: torch.Tensor | _Number = 0.25,
) -> torch.Tensor:
    """Exact 2D SDF of a ring, the torus' cross-section: ``| |p| - R | - r``.

    Convention:
        Negative inside the ring of half width ``r`` around the circle of radius ``R``
        centred at the origin; (x, y) order.

    Args:
        points: ``(*, N, 2)``.
        major_radius: ``R``, number or ``(*)``.
        minor_radius: ``r``, number or ``(*)``.

    Returns:
        ``(*, N)``.

    Example:
        >>> annulus(torch.tensor([[1.0, 0.0], [0.0, 0.0]]), 1.0, 0.25)
        tensor([-0.2500,  0.7500])
    """
    work = _points(points, (2,))
    big = _scalar(major_radius, "major_radius", work, points)
    small = _scalar(minor_radius, "minor_radius", work, points)
    _batches(work, {"major_radius": big, "minor_radius": small})
    return cast_back((_norm(work) - big).abs() - small, points.dtype)


def gyroid(
    points: torch.Tensor, scale: torch.Tensor | _Number = 1.0,
    thickness: torch.Tensor | _Number = 0.1,
) -> torch.Tensor:
    """Approximate SDF of a gyroid sheet (a triply periodic minimal surface).

    ``g(q) = sin(qx) cos(qy) + sin(qy) cos(qz) + sin(qz) cos(qx)`` with ``q = scale * p``;
    ``f = |g(q)| / scale - thickness / 2``.

    Convention:
        Negative inside a sheet of (approximate) thickness ``thickness`` around the
        surface ``g = 0``; period ``2 pi / scale`` along each axis. *Not* exact:
        ``|grad f|`` varies (it is at most ``sqrt(6)``), so ``f`` only approximates a
        distance; use it for shapes, not for losses that assume ``|grad f| = 1``.

    Args:
        points: ``(*, N, 3)``.
        scale: spatial frequency, number or ``(*)``; positive (else ``ValueError``).
        thickness: sheet thickness, number or ``(*)``.

    Returns:
        ``(*, N)``.

    Example:
        >>> gyroid(torch.tensor([[0.0, 0.0, 0.0], [1.5708, 0.0, 0.0]]), 1.0, 0.1)
        tensor([-0.0500,  0.9500])
    """
    work = _points(points, (3,))
    s = _scalar(scale, "scale", work, points)
    t = _scalar(thickness, "thickness", work, points)
    _batches(work, {"scale": s, "thickness": t})
    if bool((s <= 0).any()):  # NaN passes (NaN in, NaN out)
        raise ValueError(f"scale: expected a positive spatial frequency, got {s.min().item()}")
    q = work * s.unsqueeze(-1)
    x, y, z = q.unbind(-1)
    g = torch.sin(x) * torch.cos(y) + torch.sin(y) * torch.cos(z) + torch.sin(z) * torch.cos(x)
    return cast_back(g.abs() / s - 0.5 * t, points.dtype)


# --------------------------------------------------------------------------- modules


def _param(value, dtype=None, device=None) -> nn.Parameter:
    return nn.Parameter(torch.as_tensor(value, dtype=dtype or torch.get_default_dtype(),
                                        device=device).clone())


class Sphere(nn.Module):
    """:func:`sphere` with learnable ``radius ()`` and ``center (D,)``; same defaults.

    Example:
        >>> Sphere(radius=2.0)(torch.zeros(1, 3))
        tensor([-2.], grad_fn=<SubBackward0>)
    """

    def __init__(self, radius: float = 1.0, center=None, dim: int = 3, device=None, dtype=None):
        super().__init__()
        self.radius = _param(radius, dtype, device)
        self.center = _param([0.0] * dim if center is None else center, dtype, device)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return sphere(points, self.radius, self.center)


class Circle(Sphere):
    """:func:`circle` as a module: a 2D :class:`Sphere` with learnable radius and center.

    Example:
        >>> Circle(radius=1.0)(torch.tensor([[2.0, 0.0]]))
        tensor([1.], grad_fn=<SubBackward0>)
    """

    def __init__(self, radius: float = 1.0, center=None, device=None, dtype=None):
        super().__init__(radius, center, dim=2, device=device, dtype=dtype)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return circle(points, self.radius, self.center)


class Box(nn.Module):
    """:func:`box` with learnable ``half_size (D,)``, ``radius ()`` and ``center (D,)``.

    Example:
        >>> Box()(torch.zeros(1, 3))
        tensor([-1.], grad_fn=<SubBackward0>)
    """

    def __init__(self, half_size=None, radius: float = 0.0, center=None, dim: int = 3,
                 device=None, dtype=None):
        super().__init__()
        self.half_size = _param([1.0] * dim if half_size is None else half_size, dtype, device)
        self.radius = _param(radius, dtype, device)
        self.center = _param([0.0] * dim if center is None else center, dtype, device)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return box(points, self.half_size, self.radius, self.center)


class Rectangle(Box):
    """:func:`rectangle` as a module: a 2D :class:`Box`.

    Example:
        >>> Rectangle()(torch.tensor([[3.0, 0.0]]))
        tensor([2.], grad_fn=<SubBackward0>)
    """

    def __init__(self, half_size=None, radius: float = 0.0, center=None, device=None, dtype=None):
        super().__init__(half_size, radius, center, dim=2, device=device, dtype=dtype)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return rectangle(points, self.half_size, self.radius, self.center)


class Capsule(nn.Module):
    """:func:`capsule` with learnable ``start (D,)``, ``end (D,)`` and ``radius ()``.

    Example:
        >>> Capsule()(torch.tensor([[0.0, 0.0, 2.0]]))
        tensor([0.5000], grad_fn=<SubBackward0>)
    """

    def __init__(self, start=None, end=None, radius: float = 0.5, dim: int = 3,
                 device=None, dtype=None):
        super().__init__()
        axis = [0.0] * (dim - 1) + [1.0]
        self.start = _param([0.0] * dim if start is None else start, dtype, device)
        self.end = _param(axis if end is None else end, dtype, device)
        self.radius = _param(radius, dtype, device)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return capsule(points, self.start, self.end, self.radius)


class Plane(nn.Module):
    """:func:`plane` with learnable ``normal (D,)`` and ``offset ()``.

    Example:
        >>> Plane()(torch.tensor([[0.0, 0.0, -2.0]]))
        tensor([-2.], grad_fn=<SubBackward0>)
    """

    def __init__(self, normal=None, offset: float = 0.0, dim: int = 3, device=None, dtype=None):
        super().__init__()
        axis = [0.0] * (dim - 1) + [1.0]
        self.normal = _param(axis if normal is None else normal, dtype, device)
        self.offset = _param(offset, dtype, device)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return plane(points, self.normal, self.offset)


class Torus(nn.Module):
    """:func:`torus` with learnable ``major_radius ()`` and ``minor_radius ()``.

    Example:
        >>> Torus()(torch.tensor([[1.0, 0.0, 0.0]]))
        tensor([-0.2500], grad_fn=<SubBackward0>)
    """

    def __init__(self, major_radius: float = 1.0, minor_radius: float = 0.25, exact: bool = True,
                 device=None, dtype=None):
        super().__init__()
        self.major_radius = _param(major_radius, dtype, device)
        self.minor_radius = _param(minor_radius, dtype, device)
        self.exact = exact

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return torus(points, self.major_radius, self.minor_radius, self.exact)


class Annulus(nn.Module):
    """:func:`annulus` with learnable ``major_radius ()`` and ``minor_radius ()``.

    Example:
        >>> Annulus()(torch.tensor([[1.0, 0.0]]))
        tensor([-0.2500], grad_fn=<SubBackward0>)
    """

    def __init__(self, major_radius: float = 1.0, minor_radius: float = 0.25,
                 device=None, dtype=None):
        super().__init__()
        self.major_radius = _param(major_radius, dtype, device)
        self.minor_radius = _param(minor_radius, dtype, device)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return annulus(points, self.major_radius, self.minor_radius)


class Gyroid(nn.Module):
    """:func:`gyroid` with learnable ``scale ()`` and ``thickness ()``.

    Example:
        >>> Gyroid()(torch.zeros(1, 3))
        tensor([-0.0500], grad_fn=<SubBackward0>)
    """

    def __init__(self, scale: float = 1.0, thickness: float = 0.1, device=None, dtype=None):
        super().__init__()
        self.scale = _param(scale, dtype, device)
        self.thickness = _param(thickness, dtype, device)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, points, "points")
        return gyroid(points, self.scale, self.thickness)
