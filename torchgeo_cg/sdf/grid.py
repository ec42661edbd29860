"""Sampling SDFs on THE grid of :mod:`torchgeo_cg.core.grid` and reading them back.

The convention (``indexing="ij"``, sample ``(i, j, k)`` at ``origin + spacing * (i, j, k)``,
``spacing = (bounds[1] - bounds[0]) / (resolution - 1)``) and :class:`Volume` are in
:mod:`torchgeo_cg.core.grid`, shared with marching squares and marching cubes; this module
puts functions onto that grid (:func:`sample_grid`, :func:`grid_points`) and reads values
back (:func:`grid_interpolate`).

Convention:
    - ``indexing="ij"``: array axis 0 is x, axis 1 is y, axis 2 is z; ``origin`` is the
      first corner of ``bounds`` and the last sample sits exactly on the second corner.
    - SDF values are negative inside.
    - :func:`grid_interpolate` is trilinear and uses ``grid_sample(...,
      align_corners=True)`` so grid sample ``i`` sits exactly at ``origin + spacing*i``;
      points outside the bounds are clamped to the border value.
    - ``origin`` and ``spacing`` are ``(3,)`` tensors of the volume's dtype and device;
      functions also accept numpy arrays and lists (cast to the points' or volume's
      dtype). ``spacing`` must be positive (``ValueError`` naming it); NaN in the
      points, origin or spacing gives NaN out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
import torch.nn.functional as F
from tqdm.auto import tqdm

from torchgeo_cg.core.check import ShapeError, check_choice, check_float, check_shape
from torchgeo_cg.core.coerce import as_tensor_like
from torchgeo_cg.core.grid import Volume, check_spacing
from torchgeo_cg.core.numerics import cast_back, working_dtype

__all__ = ["grid_spacing", "grid_points", "sample_grid", "grid_interpolate"]


def _resolution(resolution: int | Sequence[int]) -> tuple[int, int, int]:
    if isinstance(resolution, torch.Tensor):
        resolution = resolution.tolist()
    res = (resolution,) * 3 if isinstance(resolution, int) else tuple(resolution)
    if len(res) != 3 or not all(isinstance(r, int) and not isinstance(r, bool) for r in res):
        raise TypeError(f"resolution: expected an int or 3 ints, got {resolution!r}")
    if min(res) < 2:
        raise ValueError(f"resolution: expected at least 2 samples per axis, got {res}")
    return res  # type: ignore[return-value]


def _parse_bounds(bounds, device=None, dtype=None) -> torch.Tensor:
    """``bounds`` as a checked ``(2, 3)`` float tensor ``((x0, y0, z0), (x1, y1, z1))``.

    Accepts ``(lo, hi)`` shared by the axes or a ``(2, 3)`` tensor/sequence.

    Raises:
        ShapeError: not ``(2,)`` or ``(2, 3)``.
        ValueError: not finite, or ``lo >= hi`` on an axis.

    Example:
        >>> _parse_bounds((-1.0, 2.0))
        tensor([[-1., -1., -1.],
                [ 2.,  2.,  2.]])
    """
    if isinstance(bounds, torch.Tensor):
        b = bounds.to(device=device or bounds.device, dtype=dtype or bounds.dtype)
    else:
        b = torch.as_tensor(bounds, dtype=dtype or torch.get_default_dtype(), device=device)
    check_float(b, "bounds")
    if b.dim() == 1 and b.shape[0] == 2:  # (lo, hi) shared by all axes
        b = b[:, None].expand(2, 3)
    check_shape(b, [2, 3], "bounds")
    if bool(~torch.isfinite(b).all()) or bool((b[1] <= b[0]).any()):
        raise ValueError(f"bounds: expected finite bounds with lo < hi per axis, got {b.tolist()}")
    return b


def grid_spacing(
    resolution: int | Sequence[int], bounds=(-1.0, 1.0), device=None, dtype=None
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(origin, spacing)`` of the grid with ``resolution`` samples spanning ``bounds``.

    Convention:
        See the module docstring: ``spacing = (hi - lo) / (resolution - 1)``.

    Args:
        resolution: ``int`` or ``(X, Y, Z)``, each at least 2.
        bounds: ``(lo, hi)`` numbers shared by the axes, or ``((x0, y0, z0), (x1, y1, z1))``
            (a ``(2, 3)`` tensor or nested sequence).
        device, dtype: of the result (default: of ``bounds`` if a tensor, else the default).

    Returns:
        ``origin (3,)`` and ``spacing (3,)``.

    Example:
        >>> grid_spacing(5, (-1.0, 1.0))
        (tensor([-1., -1., -1.]), tensor([0.5000, 0.5000, 0.5000]))
    """
    res = _resolution(resolution)
    b = _parse_bounds(bounds, device, dtype)
    return b[0].clone(), (b[1] - b[0]) / b.new_tensor([r - 1 for r in res])


def grid_points(
    resolution: int | Sequence[int],
    bounds=(-1.0, 1.0),
    indexing: str = "ij",
    device=None,
    dtype=None,
) -> torch.Tensor:
    """World coordinates of every grid sample, ``(X, Y, Z, 3)`` (``"ij"``).

    Convention:
        ``grid_points(...)[i, j, k] == origin + spacing * (i, j, k)`` with ``indexing="ij"``
        (the torchgeo_cg convention). ``indexing="xy"`` swaps the first two axes, as
        ``torch.meshgrid`` does, giving ``(Y, X, Z, 3)``; it exists for interop only.

    Args:
        resolution: ``int`` or ``(X, Y, Z)``, each at least 2.
        bounds: ``(lo, hi)`` or ``((x0, y0, z0), (x1, y1, z1))``.
        indexing: ``"ij"`` (default) or ``"xy"``.
        device, dtype: of the result.

    Returns:
        ``(X, Y, Z, 3)`` points (``(Y, X, Z, 3)`` for ``"xy"``).

    Example:
        >>> g = grid_points((2, 3, 2), ((0.0, 0.0, 0.0), (1.0, 2.0, 1.0)))
        >>> g.shape, g[1, 2, 0]
        (torch.Size([2, 3, 2, 3]), tensor([1., 2., 0.]))
    """
    check_choice(indexing, ("ij", "xy"), "indexing")
    res = _resolution(resolution)
    b = _parse_bounds(bounds, device, dtype)
    axes = [torch.linspace(float(b[0, a]), float(b[1, a]), res[a], device=b.device, dtype=b.dtype)
            for a in range(3)]
    return torch.stack(torch.meshgrid(*axes, indexing=indexing), dim=-1)


def sample_grid(
    sdf_fn: Callable[[torch.Tensor], torch.Tensor],
    resolution: int | Sequence[int],
    bounds=(-1.0, 1.0),
    chunk: int = 1 << 18,
    device=None,
    dtype=None,
    grad: bool = False,
    progress: bool = False,
) -> Volume:
    """Evaluate ``sdf_fn`` on the grid, a few x-slabs at a time, in bounded memory.

    The grid is never materialized: each chunk of whole ``x = const`` slabs (about
    ``chunk`` points) is built from three ``linspace`` axes, evaluated, and written into
    the preallocated output. Peak memory is the output plus a few chunk-sized buffers.

    Convention:
        ``values[..., i, j, k] = sdf_fn(origin + spacing * (i, j, k))``, ``indexing="ij"``
        (:mod:`torchgeo_cg.core.grid`). ``sdf_fn`` gets points ``(M, 3)`` and returns ``(M,)`` for
        one shape or ``(B, M)`` for a batch of shapes.

    Args:
        sdf_fn: callable ``(M, 3) -> (M,)`` or ``(B, M)``.
        resolution: ``int`` or ``(X, Y, Z)``, each at least 2.
        bounds: ``(lo, hi)`` or ``((x0, y0, z0), (x1, y1, z1))``.
        chunk: approximate number of points per evaluation (at least one x-slab).
        device, dtype: of the points passed to ``sdf_fn`` (default: of ``bounds`` if a
            tensor, else the default dtype on the CPU).
        grad: keep the autograd graph (memory then grows with the grid); by default the
            evaluation runs under ``torch.no_grad()``.
        progress: show a tqdm bar over the x-slab chunks (off by default, as in
            ``SolverOptions(progress=...)`` of :func:`~torchgeo_cg.transforms.fit_transform`).

    Returns:
        :class:`Volume` with ``values (X, Y, Z)`` or ``(B, X, Y, Z)``, ``origin (3,)``,
        ``spacing (3,)``.

    Example:
        >>> from torchgeo_cg.sdf.primitives import sphere
        >>> vol = sample_grid(sphere, 3, (-1.0, 1.0))
        >>> vol.values[1, 1], vol.spacing
        (tensor([ 0., -1.,  0.]), tensor([1., 1., 1.]))
    """
    res = _resolution(resolution)
    if not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"chunk: expected a positive int, got {chunk!r}")
    origin, spacing = grid_spacing(res, bounds, device, dtype)
    b = _parse_bounds(bounds, device, dtype)
    xs, ys, zs = (torch.linspace(float(b[0, a]), float(b[1, a]), res[a], device=b.device,
                                 dtype=b.dtype) for a in range(3))
    X, Y, Z = res
    slabs = max(1, chunk // (Y * Z))
    yz = torch.stack(torch.meshgrid(ys, zs, indexing="ij"), dim=-1)  # (Y, Z, 2)
    out: torch.Tensor | None = None
    ctx = torch.enable_grad() if grad else torch.no_grad()
    pieces = []
    starts = tqdm(range(0, X, slabs), disable=not progress, desc="sample_grid", unit="chunk")
    with ctx:
        for i0 in starts:  # loop over chunks of slabs, not over points
            i1 = min(X, i0 + slabs)
            n = i1 - i0
            pts = torch.empty(n, Y, Z, 3, device=b.device, dtype=b.dtype)
            pts[..., 0] = xs[i0:i1, None, None]
            pts[..., 1:] = yz
            vals = sdf_fn(pts.reshape(-1, 3))
            if not isinstance(vals, torch.Tensor) or vals.shape[-1] != n * Y * Z or vals.dim() > 2:
                got = tuple(vals.shape) if isinstance(vals, torch.Tensor) else type(vals).__name__
                raise ShapeError(f"sdf_fn: expected output (M,) or (B, M) with M={n * Y * Z}, "
                                 f"got {got}")
            vals = vals.reshape(*vals.shape[:-1], n, Y, Z)
            if grad:
                pieces.append(vals)
                continue
            if out is None:
                out = vals.new_empty(*vals.shape[:-3], X, Y, Z)
            out[..., i0:i1, :, :] = vals
    if grad:
        out = torch.cat(pieces, dim=-3)
    return Volume(out, origin, spacing)


def grid_interpolate(
    volume: Volume | torch.Tensor,
    points: torch.Tensor,
    origin: torch.Tensor | None = None,
    spacing: torch.Tensor | None = None,
) -> torch.Tensor:
    """Differentiable trilinear lookup of a sampled volume at arbitrary world points.

    Convention:
        The grid convention of this module; ``grid_sample(..., mode="bilinear",
        align_corners=True, padding_mode="border")`` on the volume viewed as ``(B, 1, X,
        Y, Z)``, so sample ``(i, j, k)`` is exactly ``origin + spacing * (i, j, k)`` and
        points outside the bounds (``±inf`` included) read the nearest border value.
        A NaN coordinate, origin or spacing gives NaN. Differentiable with respect to
        both the values and the points. The values are read in the points' dtype
        (float16/bfloat16 points: computed in float32, returned in their dtype).

    Args:
        volume: a :class:`Volume`, or values ``(X, Y, Z)`` / ``(B, X, Y, Z)`` together
            with ``origin`` and ``spacing``.
        points: ``(*, N, 3)`` for an unbatched volume; ``(B, N, 3)`` for a batched one.
        origin: ``(3,)``; required when ``volume`` is a plain tensor.
        spacing: ``(3,)``, positive (else ``ValueError``); required with a plain tensor.

    Returns:
        ``(*, N)`` (or ``(B, N)``) interpolated values.

    Example:
        >>> vol = sample_grid(lambda p: p[:, 0] + 2 * p[:, 2], 3, (0.0, 2.0))
        >>> grid_interpolate(vol, torch.tensor([[0.5, 0.3, 1.5], [1.0, 1.0, 0.25]]))
        tensor([3.5000, 1.5000])
    """
    if isinstance(volume, Volume):
        values, origin, spacing = volume
    else:
        values = volume
        if origin is None or spacing is None:
            raise TypeError("grid_interpolate: origin and spacing are required with a plain "
                            "tensor volume")
    check_float(values, "volume")
    check_float(points, "points")
    check_shape(points, ["*", "N", "3"], "points")
    if values.dim() not in (3, 4):
        raise ShapeError(f"volume: expected shape (X, Y, Z) or (B, X, Y, Z), got "
                         f"{tuple(values.shape)}")
    if values.dim() == 4:
        check_shape(points, [values.shape[0], "N", "3"], "points")
    dtype = points.dtype
    work = points.to(working_dtype(dtype))
    origin = as_tensor_like(origin, work, "origin", cast=True)
    check_shape(origin, ["3"], "origin")
    spacing = check_spacing(spacing, work)
    res = work.new_tensor(values.shape[-3:])
    # world -> [-1, 1] with align_corners=True; grid_sample wants (W, H, D) = (z, y, x) order.
    # Clamping first reads the border value outside the bounds (inf included) and keeps NaN.
    unit = (2.0 * (work - origin) / (spacing * (res - 1)) - 1.0).clamp(-1.0, 1.0)
    undefined = unit.isnan().any(-1)  # (*, N): NaN point, origin or spacing
    batch = values.shape[0] if values.dim() == 4 else 1
    grid = unit.flip(-1).reshape(batch, -1, 1, 1, 3)
    volume_b1 = values.reshape(batch, 1, *values.shape[-3:]).to(work.dtype)
    out = F.grid_sample(volume_b1, grid, mode="bilinear", padding_mode="border",
                        align_corners=True)
    out = out.reshape(undefined.shape)
    return cast_back(torch.where(undefined, out.new_full((), float("nan")), out), dtype)
