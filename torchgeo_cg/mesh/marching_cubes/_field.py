"""The grid and the field of :func:`~torchgeo_cg.mesh.marching_cubes.sparse_marching_cubes`.

The grid follows THE grid convention (``volume[i, j, k]`` at ``origin + spacing * (i, j,
k)``, the last sample on the upper bound): the sample coordinates are the entries of
one ``linspace`` per axis, exactly as ``sample_grid`` makes them, so a sample evaluated
here is bit for bit the sample of the dense grid. The field is evaluated in chunks of
at most ``max_points_per_call`` points; under ``distributed=True`` each evaluation's
points are split into one equal share per rank, each share evaluated in chunks, and the
shares gathered, so every rank holds every value and the values equal the
single-process ones byte for byte (for a field that gives the same value for a point
in any chunk).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import torch
import torch.distributed as dist

from torchgeo_cg.core.check import ShapeError

__all__ = ["Grid", "make_grid", "FieldEvaluator", "check_positive_int", "check_lipschitz"]


class Grid(NamedTuple):
    """The sampled grid: ``axes`` three ``linspace`` tensors, ``origin (3,)``,
    ``spacing (3,)``, ``sizes (X, Y, Z)`` samples, ``strides (3,)`` long of the flat
    sample index ``i * Y * Z + j * Z + k``, ``extent`` the largest ``|coordinate|``."""

    axes: tuple[torch.Tensor, torch.Tensor, torch.Tensor]
    origin: torch.Tensor
    spacing: torch.Tensor
    sizes: tuple[int, int, int]
    strides: torch.Tensor
    extent: float

    def points(self, ijk: torch.Tensor) -> torch.Tensor:
        """``(N, 3)`` world points of the integer indices ``ijk (N, 3)``."""
        return torch.stack([torch.index_select(a, 0, ijk[:, n]) for n, a in enumerate(self.axes)],
                           dim=1)

    def unflatten(self, flat: torch.Tensor) -> torch.Tensor:
        """``(N, 3)`` indices of the flat sample indices ``flat (N,)``."""
        X, Y, Z = self.sizes
        return torch.stack([flat // (Y * Z), (flat // Z) % Y, flat % Z], dim=1)


def _resolution(resolution) -> tuple[int, int, int]:
    if isinstance(resolution, torch.Tensor):
        resolution = resolution.tolist()
    if isinstance(resolution, int):
        res = (resolution,) * 3
    elif isinstance(resolution, (list, tuple)):
        res = tuple(resolution)
    else:
        raise TypeError(f"resolution: expected an int or 3 ints, got {resolution!r}")
    if len(res) != 3 or not all(isinstance(r, int) and not isinstance(r, bool) for r in res):
        raise TypeError(f"resolution: expected an int or 3 ints, got {resolution!r}")
    if min(res) < 2:
        raise ValueError(f"resolution: expected at least 2 samples per axis, got {res}")
    return res  # type: ignore[return-value]


def _bounds(bounds) -> torch.Tensor:
    """``bounds`` as a ``(2, 3)`` float tensor (dtype and device of a tensor ``bounds``)."""
    if isinstance(bounds, torch.Tensor):
        b = bounds.detach()
    else:
        try:
            b = torch.as_tensor(bounds, dtype=torch.get_default_dtype())
        except (TypeError, ValueError) as err:
            raise TypeError(f"bounds: expected (lo, hi) or ((x0, y0, z0), (x1, y1, z1)), "
                            f"got {bounds!r}") from err
    if not b.is_floating_point():
        raise TypeError(f"bounds: expected a float tensor or numbers, got {b.dtype}")
    if b.dtype in (torch.float16, torch.bfloat16):
        raise TypeError(f"bounds: {b.dtype} is not supported (the grid's coordinates are made "
                        f"in the dtype of bounds): use float32 or float64")
    if b.dim() == 1 and b.shape[0] == 2:
        b = b[:, None].expand(2, 3)
    if tuple(b.shape) != (2, 3):
        raise ShapeError(f"bounds: expected shape (2,) or (2, 3), got {tuple(b.shape)}")
    if not bool(torch.isfinite(b).all()) or bool((b[1] <= b[0]).any()):
        raise ValueError(f"bounds: expected finite bounds with lo < hi on every axis, "
                         f"got {b.tolist()}")
    return b


def make_grid(bounds, resolution) -> Grid:
    """The :class:`Grid` of ``resolution`` samples spanning ``bounds``.

    Example:
        >>> g = make_grid((-1.0, 1.0), 3)
        >>> g.spacing, g.points(torch.tensor([[0, 1, 2]]))
        (tensor([1., 1., 1.]), tensor([[-1.,  0.,  1.]]))
    """
    res = _resolution(resolution)
    b = _bounds(bounds)
    axes = tuple(torch.linspace(float(b[0, a]), float(b[1, a]), res[a], device=b.device,
                                dtype=b.dtype) for a in range(3))
    spacing = (b[1] - b[0]) / b.new_tensor([r - 1 for r in res])
    X, Y, Z = res
    strides = torch.tensor([Y * Z, Z, 1], device=b.device)
    return Grid(axes, b[0].clone(), spacing, res, strides, float(b.abs().max()))  # type: ignore


class FieldEvaluator:
    """Evaluates ``field`` on points, checked, in chunks (sharded over ranks when asked).

    Args:
        field: callable ``(N, 3) -> (N,)`` or ``(N, 1)``.
        chunk: points per call.
        distributed: split the points into equal shares over the ranks of the default
            process group.
    """

    def __init__(self, field: Callable, chunk: int, distributed: bool) -> None:
        self.field, self.chunk = field, chunk
        self.world = dist.get_world_size() if distributed else 1
        self.rank = dist.get_rank() if distributed else 0
        self.calls = 0  # points evaluated by this rank (for reporting)

    def _call(self, pts: torch.Tensor) -> torch.Tensor:
        out = self.field(pts)
        n = pts.shape[0]
        if not isinstance(out, torch.Tensor):
            raise TypeError(f"field: expected a tensor output, got {type(out).__name__}")
        if tuple(out.shape) not in ((n,), (n, 1)):
            raise ShapeError(f"field: expected output ({n},) or ({n}, 1) for points "
                             f"({n}, 3), got {tuple(out.shape)}")
        if out.dtype != pts.dtype:
            raise TypeError(f"field: expected output of dtype {pts.dtype} (the points' dtype, "
                            f"from bounds), got {out.dtype}")
        if out.device != pts.device:
            raise ValueError(f"field: expected output on {pts.device} (the points' device, "
                             f"from bounds), got {out.device}")
        out = out.reshape(n)
        if bool(torch.isnan(out.detach()).any()):
            raise ValueError(f"field: returned NaN at {int(torch.isnan(out.detach()).sum())} of "
                             f"{n} points (a NaN sample is neither inside nor outside)")
        self.calls += n
        return out

    def __call__(self, grid: Grid, ijk: torch.Tensor) -> torch.Tensor:
        """``(N,)`` detached values at the grid indices ``ijk (N, 3)`` (or world points
        ``(N, 3)`` float, evaluated as given)."""
        n = ijk.shape[0]
        as_points = ijk.is_floating_point()
        make = (lambda s: ijk[s]) if as_points else (lambda s: grid.points(ijk[s]))
        with torch.no_grad():
            if self.world == 1:
                parts = [self._call(make(slice(s, s + self.chunk)))
                         for s in range(0, n, self.chunk)]
                return torch.cat(parts) if parts else grid.origin.new_zeros(0)
            return self._sharded(make, n, grid)

    def _sharded(self, make, n: int, grid: Grid) -> torch.Tensor:
        """Rank ``r`` evaluates the ``r``-th of ``world`` equal shares of the ``n`` points
        (in chunks); every rank gets every value."""
        share = math.ceil(n / self.world)
        lo, hi = min(n, self.rank * share), min(n, (self.rank + 1) * share)
        mine = grid.origin.new_zeros(share)
        for s in range(lo, hi, self.chunk):  # loop over chunks
            e = min(hi, s + self.chunk)
            mine[s - lo:e - lo] = self._call(make(slice(s, e)))
        gathered = [torch.empty_like(mine) for _ in range(self.world)]
        dist.all_gather(gathered, mine)
        return torch.cat(gathered)[:n]  # share r holds points r * share ...

    def with_grad(self, grid: Grid, ijk: torch.Tensor) -> torch.Tensor:
        """``(N,)`` values at ``ijk`` with autograd (on this rank, in chunks)."""
        parts = [self._call(grid.points(ijk[s:s + self.chunk]))
                 for s in range(0, ijk.shape[0], self.chunk)]
        return torch.cat(parts) if parts else grid.origin.new_zeros(0)


def check_positive_int(value, name: str, low: int = 1) -> int:
    """``value`` as an int ``>= low`` (``TypeError``/``ValueError`` naming ``name``)."""
    if not isinstance(value, int) or isinstance(value, bool):
        raise TypeError(f"{name}: expected an int, got {type(value).__name__}")
    if value < low:
        raise ValueError(f"{name}: expected an int >= {low}, got {value}")
    return value


def check_lipschitz(value) -> float | None:
    """``None`` or a finite positive number."""
    if value is None:
        return None
    if isinstance(value, torch.Tensor):
        value = float(value)
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        raise TypeError(f"lipschitz: expected a number or None, got {type(value).__name__}")
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"lipschitz: expected a finite positive number or None, got {value}")
    return float(value)

