"""Voxel downsampling: the mean of the points (and features) in each voxel of a grid.

Convention:
    - Open3D's grid (``voxel_down_sample``): its origin is the cloud's minimum minus half
      a voxel, a point's voxel is ``floor((p - origin) / voxel_size)`` per axis.
    - The output of each cloud is sorted by voxel index, x-major (lexicographic in
      ``(i_x, i_y, i_z)``); padded batches: ``points (*, V, D)`` with ``lengths (*,)``
      voxels per cloud, zero rows past them.
    - Means are sums divided by counts in torch: differentiable w.r.t. ``points`` and
      ``features``.
    - Points with a NaN/inf coordinate (and rows past ``lengths``) are ignored; a cloud
      with no finite point gives no voxel.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.points._search import check_lengths, check_positive

__all__ = ["VoxelResult", "voxel_downsample"]


class VoxelResult(NamedTuple):
    """Result of :func:`voxel_downsample`.

    Attributes:
        points: ``(*, V, D)`` voxel means, sorted by voxel index (zero rows past
            ``lengths``).
        features: ``(*, V, F)`` the features' means, or None without features.
        lengths: ``(*,)`` long, the number of voxels of each cloud.
    """

    points: torch.Tensor
    features: torch.Tensor | None
    lengths: torch.Tensor


def _voxel_keys(p_bnd: torch.Tensor, ok_bn: torch.Tensor, voxel_size: float):
    """Integer voxel coordinates ``(B, N, D)`` of the valid points on Open3D's grid."""
    inf = float("inf")
    if p_bnd.shape[1] == 0:
        return p_bnd.new_zeros(p_bnd.shape, dtype=torch.long)
    lo_bd = p_bnd.masked_fill(~ok_bn[..., None], inf).amin(1)
    lo_bd = torch.where(torch.isfinite(lo_bd), lo_bd, torch.zeros_like(lo_bd))
    origin_bd = lo_bd - voxel_size * 0.5
    cell = torch.floor((p_bnd - origin_bd[:, None, :]) / voxel_size)
    return torch.where(ok_bn[..., None], cell, torch.zeros_like(cell)).to(torch.long)


def _linear_keys(cell_bnd: torch.Tensor, ok_bn: torch.Tensor) -> torch.Tensor:
    """One sortable int64 key per valid point (batch item major, then x, y, z), or the
    rank of its row among the unique rows when the grid is too large for one int64."""
    B, N, D = cell_bnd.shape
    b = torch.arange(B, device=cell_bnd.device)[:, None].expand(B, N)
    rows = torch.cat([b[ok_bn][:, None], cell_bnd[ok_bn]], 1)  # (P, 1 + D)
    if rows.shape[0] == 0:
        return rows.new_zeros(0)
    span = rows.amax(0) + 1
    if math.prod(float(s) for s in span.tolist()) < 2.0**62:
        key = rows[:, 0]
        for a in range(1, D + 1):  # loop over coordinates
            key = key * span[a] + rows[:, a]
        return key
    return torch.unique(rows, dim=0, return_inverse=True)[1]


def voxel_downsample(
    points: torch.Tensor,
    voxel_size: float,
    *,
    features: torch.Tensor | None = None,
    lengths: torch.Tensor | None = None,
) -> VoxelResult:
    """The mean of the points (and features) in each occupied voxel, as Open3D's
    ``voxel_down_sample``, sorted by voxel index.

    Convention:
        See the module docstring: Open3D's grid origin (minimum minus half a voxel),
        output sorted x-major, padded batches with ``lengths``, differentiable means.

    Args:
        points: ``(*, N, D)`` floating point.
        voxel_size: the voxel edge, ``> 0``.
        features: ``(*, N, F)`` floating point, averaged like the points (optional).
        lengths: ``(*,)`` integer, valid rows per cloud (default ``N``).

    Returns:
        :class:`VoxelResult` ``(points (*, V, D), features (*, V, F) | None, lengths)``.

    Raises:
        ShapeError: bad shapes (names the argument).
        ValueError: ``voxel_size <= 0``.

    Example:
        >>> p = torch.tensor([[0.0, 0.0], [0.2, 0.0], [1.0, 1.0], [0.0, 1.1]])
        >>> out = voxel_downsample(p, 1.0)
        >>> out.points
        tensor([[0.1000, 0.0000],
                [0.0000, 1.1000],
                [1.0000, 1.0000]])
        >>> out.lengths
        tensor(3)
    """
    check_float(points, "points")
    s = check_shape(points, ["*", "N", "D"], "points")
    voxel_size = check_positive(voxel_size, "voxel_size")
    batch, N, D = s["*"], s["N"], s["D"]
    if features is not None:
        check_float(features, "features")
        check_shape(features, [*batch, N, "F"], "features")
        if features.dtype != points.dtype:
            raise TypeError(f"features: expected dtype {points.dtype} (of points), "
                            f"got {features.dtype}")
    len_ = check_lengths(lengths, batch, N, "lengths", points.device)
    B = math.prod(batch)
    p_bnd = points.reshape(B, N, D)
    with torch.no_grad():
        ok_bn = torch.isfinite(p_bnd).all(-1) & (torch.arange(N, device=points.device)
                                                  < len_.reshape(B, 1))
        key = _linear_keys(_voxel_keys(p_bnd.detach(), ok_bn, voxel_size), ok_bn)
        _, voxel, count = torch.unique(key, sorted=True, return_inverse=True,
                                       return_counts=True)
        item_p = torch.arange(B, device=points.device)[:, None].expand(B, N)[ok_bn]
        per_item = torch.bincount(item_p[torch.cumsum(count, 0) - 1] if count.numel()
                                  else item_p, minlength=B)
        V = int(per_item.max()) if per_item.numel() else 0
        first = torch.cumsum(per_item, 0) - per_item
        slot = voxel - first[item_p] + item_p * V  # row of each point in (B * V)
    out_p = _means(p_bnd[ok_bn], slot, B * V).reshape(*batch, V, D)
    out_f = None
    if features is not None:
        f = features.reshape(B, N, -1)[ok_bn]
        out_f = _means(f, slot, B * V).reshape(*batch, V, f.shape[-1])
    return VoxelResult(out_p, out_f, per_item.reshape(batch))


def _means(values_pc: torch.Tensor, slot_p: torch.Tensor, rows: int) -> torch.Tensor:
    """Per-slot means ``(rows, C)`` of the rows of ``values`` (zero for empty slots)."""
    C = values_pc.shape[-1]
    sums = values_pc.new_zeros(rows, C).index_add(0, slot_p, values_pc)
    counts = values_pc.new_zeros(rows).index_add(0, slot_p, values_pc.new_ones(len(slot_p)))
    return sums / counts.clamp_min(1)[:, None]
