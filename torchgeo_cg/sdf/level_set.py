"""The report's zero-level-set extraction: grid samples within a tolerance of zero.

Report section 1.4 samples the algebraic torus ``(sqrt(x²+y²) - R)² + z² - r²`` on a 500^3
grid and keeps the samples with ``|f| < 1e-4`` (``numpy.isclose`` + ``where``), Figure 5.

Why a fixed tolerance is a poor surface: a sample is kept when it falls inside the
band ``|f| < tol``, whose width is about ``2 tol / |grad f|``. A surface crossing a
grid cell is caught only if some sample lands inside that band, so

- with grid spacing ``h`` much larger than ``2 tol / |grad f|`` (the report: ``h ~ 0.01``
  against a band ~2e-4 wide) only a small, resolution-dependent fraction of the
  surface is found, in moire-like stripes where the surface happens to line up with
  the lattice; coarser grids lose the surface entirely;
- with ``tol`` much larger than ``h |grad f|`` the "surface" becomes a thick shell;
- ``|grad f|`` varies with position for non-distance functions, so a single ``tol``
  gives a band whose width changes over the surface;
- the result is an unordered point set with no connectivity or normals.

A tolerance of about ``h |grad f| / 2`` keeps roughly one sample layer, but marching
cubes (``torchgeo_cg.mesh``) is the right tool: it interpolates the crossing on every
cell edge and returns a connected, watertight mesh. The gallery figure
``sdf_level_set_tolerance.png`` shows both effects.
"""

from __future__ import annotations

import numbers
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape
from torchgeo_cg.core.coerce import as_tensor_like
from torchgeo_cg.core.grid import Volume, check_spacing

__all__ = ["LevelSetPoints", "zero_level_set"]


class LevelSetPoints(NamedTuple):
    """Grid samples within tolerance of the zero level set, packed over the batch.

    Attributes:
        points: ``(M, 3)`` world positions ``origin + spacing * (i, j, k)``.
        indices: ``(M, 3)`` long grid indices ``(i, j, k)``.
        batch: ``(M,)`` long index of the shape each point belongs to (all 0 unbatched).
        counts: ``(B,)`` number of points per shape (``(1,)`` unbatched).
    """

    points: torch.Tensor
    indices: torch.Tensor
    batch: torch.Tensor
    counts: torch.Tensor


def zero_level_set(
    volume: Volume | torch.Tensor,
    origin: torch.Tensor | None = None,
    spacing: torch.Tensor | None = None,
    tol: float = 1e-4,
) -> LevelSetPoints:
    """The report's surface extraction: every sample with ``|f| < tol``, as world points.

    See the module docstring for why a fixed tolerance is a poor surface; use marching
    cubes for a mesh.

    Convention:
        Grid convention of :mod:`torchgeo_cg.core.grid` (``"ij"``; index ``(i, j, k)`` at
        ``origin + spacing * (i, j, k)``). Points come in C order of ``(b, i, j, k)``.
        Not differentiable (a selection).

    Args:
        volume: a :class:`~torchgeo_cg.core.grid.Volume`, or values ``(X, Y, Z)`` /
            ``(B, X, Y, Z)`` with ``origin`` and ``spacing``.
        origin: ``(3,)``; taken from the Volume when omitted.
        spacing: ``(3,)``, positive; taken from the Volume when omitted.
        tol: the tolerance (the report uses ``1e-4``), in the units of the values;
            must be positive.

    Raises:
        ValueError: ``spacing`` or ``tol`` not positive, or a NaN sample in the volume
            (as :func:`~torchgeo_cg.mesh.marching_cubes` does).

    Returns:
        :class:`LevelSetPoints` ``(points (M, 3), indices (M, 3), batch (M,), counts (B,))``.

    Example:
        >>> from torchgeo_cg.sdf.grid import sample_grid
        >>> vol = sample_grid(lambda p: p[:, 0] - 0.5, 3, (0.0, 1.0))  # the plane x = 0.5
        >>> zero_level_set(vol).points
        tensor([[0.5000, 0.0000, 0.0000],
                [0.5000, 0.0000, 0.5000],
                [0.5000, 0.0000, 1.0000],
                [0.5000, 0.5000, 0.0000],
                [0.5000, 0.5000, 0.5000],
                [0.5000, 0.5000, 1.0000],
                [0.5000, 1.0000, 0.0000],
                [0.5000, 1.0000, 0.5000],
                [0.5000, 1.0000, 1.0000]])
    """
    if isinstance(volume, Volume):
        values = volume.values
        origin = volume.origin if origin is None else origin
        spacing = volume.spacing if spacing is None else spacing
    else:
        values = volume
    if origin is None or spacing is None:
        raise TypeError("zero_level_set: origin and spacing are required with a plain tensor")
    check_float(values, "volume")
    origin = as_tensor_like(origin, values, "origin", cast=True)
    check_shape(origin, ["3"], "origin")
    spacing = check_spacing(spacing, values)
    if values.dim() not in (3, 4):
        raise ShapeError(f"volume: expected shape (X, Y, Z) or (B, X, Y, Z), got "
                         f"{tuple(values.shape)}")
    if isinstance(tol, bool) or not isinstance(tol, numbers.Real) or not tol > 0:
        raise ValueError(f"tol: expected a positive tolerance, got {tol}")
    batched = values if values.dim() == 4 else values[None]
    nan = int(torch.isnan(values.detach()).sum())
    if nan:  # a NaN sample is neither near the surface nor away from it
        raise ValueError(f"volume: expected no NaN samples (NaN is neither within tol of 0 "
                         f"nor away from it), got {nan} of {values.numel()}")
    hits = torch.nonzero(batched.abs() < tol)  # (M, 4): b, i, j, k
    batch, indices = hits[:, 0], hits[:, 1:]
    points = origin.to(values) + spacing.to(values) * indices.to(values.dtype)
    counts = torch.bincount(batch, minlength=batched.shape[0])
    return LevelSetPoints(points, indices, batch, counts)
