"""THE grid convention of torchgeo_cg: where a sample of a regular grid sits in the world.

Every module that puts values on a regular grid (SDF sampling, zero-level sets,
marching cubes, marching squares) uses this one convention::

                z (axis 2, index k)
                ^
                |   y (axis 1, index j)
                |  /
                | /
     origin --> o-------> x (axis 0, index i)

     volume[i, j, k]  is the value at  origin + spacing * (i, j, k)
                                      = (x0 + sx*i, y0 + sy*j, z0 + sz*k)

     bounds = ((x0, y0, z0), (x1, y1, z1)),  resolution = (X, Y, Z)
     spacing = (bounds[1] - bounds[0]) / (resolution - 1)      # both ends are samples
     volume.shape == (X, Y, Z)  or (B, X, Y, Z) for a batch of B shapes

Convention:
    - ``indexing="ij"``: array axis 0 is x, axis 1 is y, axis 2 is z (as
      ``torch.meshgrid(xs, ys, zs, indexing="ij")``). Index ``(i, j, k)`` maps to the
      world point ``origin + spacing * (i, j, k)``; ``origin`` is the first corner of
      ``bounds`` and the last sample sits exactly on the second corner (``linspace``).
    - ``origin`` and ``spacing`` are ``(3,)`` tensors of the volume's dtype and device;
      functions also accept numpy arrays and lists (cast to the points' or volume's
      dtype). ``spacing`` must be positive (``ValueError`` naming it); NaN in the
      points, origin or spacing gives NaN out.
    - A crossing of the level ``iso`` on the grid edge between samples ``f1`` and
      ``f2`` sits at the fraction :func:`edge_fraction` of the edge (marching squares
      and marching cubes share it).

It lives in :mod:`torchgeo_cg.core` because curves, mesh and sdf all use it, and
none of them may import another for it. Sampling functions onto the grid and reading
it back (``sample_grid``, ``grid_interpolate``) are in :mod:`torchgeo_cg.sdf.grid`.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.core.coerce import as_tensor_like

__all__ = ["Volume", "index_to_world", "world_to_index", "check_spacing", "edge_fraction"]


class Volume(NamedTuple):
    """A sampled grid: ``values[..., i, j, k]`` lives at ``origin + spacing * (i, j, k)``.

    Attributes:
        values: ``(X, Y, Z)`` or ``(B, X, Y, Z)`` samples.
        origin: ``(3,)`` world position of index ``(0, 0, 0)``.
        spacing: ``(3,)`` distance between neighbouring samples along x, y, z.
    """

    values: torch.Tensor
    origin: torch.Tensor
    spacing: torch.Tensor


def check_spacing(spacing, like: torch.Tensor | None, name: str = "spacing") -> torch.Tensor:
    """``spacing`` as a ``(3,)`` tensor like ``like`` (cast), checked positive.

    Raises:
        ShapeError: not 3 values.
        ValueError: a value is zero or negative (NaN passes: NaN in, NaN out).

    Example:
        >>> check_spacing([0.5, 1.0, 0.0], torch.zeros(3))
        Traceback (most recent call last):
        ...
        ValueError: spacing: expected positive grid spacings, got [0.5, 1.0, 0.0]
    """
    spacing = as_tensor_like(spacing, like, name, cast=True)
    check_shape(spacing, ["3"], name)
    if bool((spacing <= 0).any()):
        raise ValueError(f"{name}: expected positive grid spacings, got {spacing.tolist()}")
    return spacing


def index_to_world(
    indices: torch.Tensor, origin: torch.Tensor, spacing: torch.Tensor
) -> torch.Tensor:
    """Grid index ``(i, j, k)`` (integer or fractional) to world ``origin + spacing * ijk``.

    Convention:
        ``"ij"`` grid convention of this module.

    Args:
        indices: ``(*, 3)`` integer or float indices.
        origin: ``(3,)``.
        spacing: ``(3,)``.

    Returns:
        ``(*, 3)`` world points, dtype of ``origin``.

    Example:
        >>> index_to_world(torch.tensor([[1, 2, 3]]), torch.zeros(3), torch.tensor([0.5, 1.0, 2.0]))
        tensor([[0.5000, 2.0000, 6.0000]])
    """
    check_shape(indices, ["*", "3"], "indices")
    origin = as_tensor_like(origin, None, "origin")
    check_shape(origin, ["3"], "origin")
    spacing = check_spacing(spacing, origin)
    return origin + spacing * indices.to(dtype=origin.dtype, device=origin.device)


def world_to_index(
    points: torch.Tensor, origin: torch.Tensor, spacing: torch.Tensor
) -> torch.Tensor:
    """World points to fractional grid indices ``(p - origin) / spacing`` (inverse of above).

    Convention:
        ``"ij"`` grid convention; round the result to get the nearest sample.

    Args:
        points: ``(*, 3)`` float.
        origin: ``(3,)``, cast to the points' dtype.
        spacing: ``(3,)``, positive (else ``ValueError``), cast to the points' dtype.

    Returns:
        ``(*, 3)`` fractional indices.

    Example:
        >>> spacing = torch.tensor([0.5, 1.0, 2.0])
        >>> world_to_index(torch.tensor([[0.5, 2.0, 6.0]]), torch.zeros(3), spacing)
        tensor([[1., 2., 3.]])
    """
    check_float(points, "points")
    check_shape(points, ["*", "3"], "points")
    origin = as_tensor_like(origin, points, "origin", cast=True)
    check_shape(origin, ["3"], "origin")
    spacing = check_spacing(spacing, points)
    return (points - origin) / spacing


class _EdgeFraction(torch.autograd.Function):
    """``t = clamp((iso - f1) / (f2 - f1), delta, 1 - delta)`` with scale-free gradients
    (see :func:`edge_fraction`)."""

    generate_vmap_rule = True  # with setup_context: works under vmap / jacrev / grad

    @staticmethod
    def _fraction(f1, f2, iso):
        """``(t, den)``: the unclamped fraction and its denominator (1 where ``f1 == f2``)."""
        den = f2 - f1
        den = torch.where(den == 0, torch.ones_like(den), den)
        return (iso - f1) / den, den

    @staticmethod
    def forward(f1, f2, iso, delta: float):
        t, _ = _EdgeFraction._fraction(f1, f2, iso)
        return t.clamp(delta, 1.0 - delta)

    @staticmethod
    def setup_context(ctx, inputs, output) -> None:
        f1, f2, iso, delta = inputs
        ctx.save_for_backward(*_EdgeFraction._fraction(f1, f2, iso))
        ctx.delta = delta

    @staticmethod
    def backward(ctx, grad):
        t, den = ctx.saved_tensors
        free = (t > ctx.delta) & (t < 1.0 - ctx.delta)
        g = torch.where(free, grad, torch.zeros_like(grad)) / den
        return g * (t - 1.0), -g * t, g, None


def edge_fraction(
    f1: torch.Tensor, f2: torch.Tensor, iso: torch.Tensor, delta: float
) -> torch.Tensor:
    """Where ``iso`` crosses a grid edge: ``clamp((iso - f1) / (f2 - f1), delta, 1 - delta)``.

    The derivatives are written with one division each, ``dt/df1 = (t - 1) / den``,
    ``dt/df2 = -t / den``, ``dt/diso = 1 / den`` (``den = f2 - f1``), so they stay finite
    at any field scale (autograd's ``-num / den**2`` underflows to 0 and gives inf);
    where the clamp is active the gradient is zero. ``den == 0`` (never for a crossing
    edge of finite samples) divides by one instead. Works under ``vmap``/``jacrev``.

    Convention:
        ``t = 0`` at the sample ``f1``, ``t = 1`` at ``f2``; the crossing is at
        ``p1 + t (p2 - p1)``. ``delta`` (e.g. ``sqrt(finfo(dtype).eps)``) keeps it off
        the samples, so a sample equal to ``iso`` never makes two vertices coincide.

    Args:
        f1, f2: ``(*)`` samples at the two ends of each edge.
        iso: ``(*)`` the level.
        delta: the clamp margin, in ``[0, 0.5)``.

    Returns:
        ``(*)`` fractions in ``[delta, 1 - delta]``.

    Example:
        >>> edge_fraction(torch.tensor([-1.0, 0.0]), torch.tensor([3.0, 2.0]),
        ...               torch.tensor([0.0, 0.0]), 1e-3)
        tensor([0.2500, 0.0010])
    """
    if not records_graph(f1, f2, iso):  # the same operations, without the Function's context
        return _EdgeFraction.forward(f1, f2, iso, delta)
    return _EdgeFraction.apply(f1, f2, iso, delta)
