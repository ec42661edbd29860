"""Argument handling of :func:`torchgeo_cg.mesh.marching_cubes` (one place for every check).

Numbers, numpy scalars/arrays and tensors are accepted alike; a wrong length raises
:class:`~torchgeo_cg.core.check.ShapeError`, a wrong type ``TypeError``, a bad value
``ValueError``, each naming the argument.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from torchgeo_cg.core.check import ShapeError, check_float
from torchgeo_cg.core.coerce import as_tensor_like
from torchgeo_cg.core.grid import Volume, index_to_world
from torchgeo_cg.mesh.marching_cubes._steps import take

__all__ = ["MarchingArgs", "parse_arguments", "world_map", "DEFAULT_AMBIGUITY"]

#: The default ``ambiguity`` rule of the marching-cubes functions.
DEFAULT_AMBIGUITY = "asymptotic"

_HALF = (torch.float16, torch.bfloat16)


def _per_mesh(value, name: str, batch: int, like: torch.Tensor) -> torch.Tensor:
    """A scalar or ``(B,)`` value -> ``(B,)`` tensor like ``like``."""
    out = as_tensor_like(value, like, name, cast=True)
    if out.ndim > 1 or (out.ndim == 1 and out.shape[0] not in (1, batch)):
        raise ShapeError(f"{name}: expected a number or shape () or ({batch},), "
                         f"got {tuple(out.shape)}")
    return out.reshape(-1).expand(batch)


def _per_mesh_vec(value, name: str, batch: int, like: torch.Tensor) -> torch.Tensor:
    """3 numbers or a ``(3,)`` / ``(B, 3)`` value -> ``(B, 3)`` tensor like ``like``."""
    out = as_tensor_like(value, like, name, cast=True)
    if out.ndim == 1 and out.shape[0] == 3:
        return out.unsqueeze(0).expand(batch, 3)
    if out.ndim == 2 and out.shape[1] == 3 and out.shape[0] in (1, batch):
        return out.expand(batch, 3)
    raise ShapeError(f"{name}: expected 3 numbers, shape (3,) or ({batch}, 3), "
                     f"got {tuple(out.shape)}")


class MarchingArgs(NamedTuple):
    """Validated arguments: ``vol (B, X, Y, Z)`` contiguous, per-mesh ``iso (B,)``,
    ``origin (B, 3)``, ``spacing (B, 3)``, ``tau (B,)`` or None, ``mask (B, X, Y, Z)`` or
    None, ``work`` (the dtype positions are computed in), ``shared_frame`` (origin and
    spacing shared by the batch, so :func:`~torchgeo_cg.core.grid.index_to_world` applies)."""

    vol: torch.Tensor
    iso: torch.Tensor
    origin: torch.Tensor
    spacing: torch.Tensor
    tau: torch.Tensor | None
    mask: torch.Tensor | None
    work: torch.dtype
    shared_frame: bool


def _frame(volume, origin, spacing):
    """Split a :class:`Volume` (or a tensor) into values, origin, spacing."""
    if isinstance(volume, Volume):
        for name, value in (("origin", origin), ("spacing", spacing)):
            if value is not None:
                raise TypeError(f"{name}: given with a Volume, which carries its own {name}")
        return volume.values, volume.origin, volume.spacing
    if not isinstance(volume, torch.Tensor):
        raise TypeError(f"volume: expected a float tensor or a Volume, got "
                        f"{type(volume).__name__}")
    origin = (0.0, 0.0, 0.0) if origin is None else origin
    spacing = (1.0, 1.0, 1.0) if spacing is None else spacing
    return volume, origin, spacing


def _mask(mask, vol: torch.Tensor) -> torch.Tensor | None:
    if mask is None:
        return None
    if isinstance(mask, np.ndarray):
        mask = torch.from_numpy(mask)
    if not isinstance(mask, torch.Tensor) or mask.dtype != torch.bool:
        got = mask.dtype if isinstance(mask, torch.Tensor) else type(mask).__name__
        raise TypeError(f"mask: expected a bool tensor, got {got}")
    B, X, Y, Z = vol.shape
    if tuple(mask.shape) not in ((X, Y, Z), (B, X, Y, Z)):
        raise ShapeError(f"mask: expected shape ({X}, {Y}, {Z}) or ({B}, {X}, {Y}, {Z}), "
                         f"got {tuple(mask.shape)}")
    return mask.to(vol.device).expand(B, X, Y, Z).contiguous()


def parse_arguments(volume, iso, origin, spacing, temperature, mask) -> MarchingArgs:
    """Validate :func:`marching_cubes`'s arguments (see its docstring for the rules).

    Example:
        >>> args = parse_arguments(torch.zeros(2, 2, 2), 0, None, np.array([1, 2, 3]), None, None)
        >>> args.vol.shape, args.spacing
        (torch.Size([1, 2, 2, 2]), tensor([[1., 2., 3.]]))
    """
    values, origin, spacing = _frame(volume, origin, spacing)
    check_float(values, "volume")
    if values.ndim not in (3, 4) or min(values.shape[-3:]) < 2:
        raise ShapeError(f"volume: expected shape (X, Y, Z) or (B, X, Y, Z) with X, Y, Z >= 2, "
                         f"got {tuple(values.shape)}")
    vol = (values if values.ndim == 4 else values.unsqueeze(0)).contiguous()
    B = vol.shape[0]
    work = torch.float32 if vol.dtype in _HALF else vol.dtype
    like = vol.new_empty((), dtype=work)
    iso_b = _per_mesh(iso, "iso", B, like)
    origin_b = _per_mesh_vec(origin, "origin", B, like)
    spacing_b = _per_mesh_vec(spacing, "spacing", B, like)
    bad = ~torch.isfinite(spacing_b.detach()) | (spacing_b.detach() <= 0)
    if bool(bad.any()):
        raise ValueError(f"spacing: expected finite positive values, got "
                         f"{spacing_b.detach().tolist()}")
    _check_no_nan(vol, iso_b)
    tau_b = None
    if temperature is not None:
        tau_b = _per_mesh(temperature, "temperature", B, like)
        if bool((~(tau_b.detach() > 0)).any()):
            raise ValueError(f"temperature: expected > 0, got {tau_b.detach().tolist()}")
    shared = _is_shared(origin) and _is_shared(spacing)
    return MarchingArgs(vol, iso_b, origin_b, spacing_b, tau_b, _mask(mask, vol), work, shared)


def _check_no_nan(vol: torch.Tensor, iso_b: torch.Tensor) -> None:
    """Raise ``ValueError`` for a NaN sample (neither inside nor outside) or a NaN ``iso``.

    One sum over the volume (cheap: a tenth of a millisecond per 2M samples) is NaN
    whenever a sample is; only then (or for opposite infinities) are the samples counted.
    """
    total = vol.detach().sum() + iso_b.detach().sum()  # one sync in the usual case
    if not bool(torch.isnan(total)):
        return
    if bool(torch.isnan(iso_b.detach()).any()):
        raise ValueError(f"iso: expected a number, got {iso_b.detach().tolist()}")
    if vol.numel():
        bad = int(torch.isnan(vol.detach()).sum())
        if bad:
            raise ValueError(f"volume: expected no NaN samples (NaN is neither inside nor "
                             f"outside), got {bad} of {vol.numel()}")


def _is_shared(value) -> bool:
    """Whether an origin/spacing value is one ``(3,)`` frame for the whole batch."""
    shape = value.shape if isinstance(value, (torch.Tensor, np.ndarray)) else np.shape(value)
    return len(shape) == 1


def world_map(args):
    """Index -> world ``f(index_pos, b_v)``: the grid module's :func:`index_to_world` for
    one shared frame, per-volume frames gathered by ``b_v`` otherwise."""
    if args.shared_frame:
        origin, spacing = args.origin[0], args.spacing[0]
        return lambda index_pos, b_v: index_to_world(index_pos, origin, spacing)
    return lambda index_pos, b_v: (
        (args.origin[:1] if b_v is None else take(args.origin, b_v))
        + (args.spacing[:1] if b_v is None else take(args.spacing, b_v)) * index_pos)
