"""Validation, batching and exact power-of-two scaling of a ray-mesh query.

Every query is flattened to ``B`` meshes ``(B, V, 3)`` sharing ``T`` triangles and
``(B, R, 3)`` rays; the float64 copy the search decides on is scaled exactly: the
positions of item ``b`` by the power of two ``s_b`` above its vertices' magnitude (so
the corners lie in ``[-1, 1]``), each direction by the power of two above its own
magnitude. Scaling by a power of two rounds nothing, so the decisions (which face, and
the signs that make the test watertight) are those of the unscaled problem, at any
input scale, and the products of the test neither overflow nor underflow.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.check import (
    check_broadcastable,
    check_float,
    check_shape,
)
from torchgeo_cg.core.coerce import check_same_dtype
from torchgeo_cg.core.numerics import power_of_two_scale
from torchgeo_cg.mesh.faces import check_mesh

__all__: list[str] = []


class RayProblem(NamedTuple):
    """A validated, flattened ray-mesh query (see the module docstring)."""

    verts: torch.Tensor  # (B, V, 3) input dtype (differentiable)
    origins: torch.Tensor  # (B, R, 3) input dtype
    directions: torch.Tensor  # (B, R, 3) input dtype
    tris: torch.Tensor  # (T, 3) long
    lead: tuple  # shape of the result (*, R)
    scale: torch.Tensor  # (B, 1, 1) float64 power of two of the positions
    dscale: torch.Tensor  # (B, R, 1) float64 power of two of each direction
    valid: torch.Tensor  # (B, R) finite origin and direction, direction nonzero
    bad: torch.Tensor  # (B, R) NaN or inf in the ray (t is NaN there)


def check_limits(t_min: float, t_max: float) -> None:
    """Raise ``ValueError`` unless ``t_min`` is finite and ``t_min <= t_max`` (not NaN).

    Example:
        >>> check_limits(0.0, math.inf)
        >>> check_limits(1.0, 0.5)
        Traceback (most recent call last):
        ...
        ValueError: t_min, t_max: expected a finite t_min <= t_max, got 1.0 and 0.5
    """
    lo, hi = float(t_min), float(t_max)
    if not (math.isfinite(lo) and lo <= hi):
        raise ValueError(f"t_min, t_max: expected a finite t_min <= t_max, got {t_min!r} "
                         f"and {t_max!r}")


def check_rays(origins: torch.Tensor, directions: torch.Tensor) -> tuple[int, ...]:
    """Validate a ray bundle; return the broadcast shape ``(*, R)`` of its rays.

    Example:
        >>> check_rays(torch.zeros(1, 3), torch.ones(5, 3))
        (5,)
    """
    check_float(origins, "origins")
    check_float(directions, "directions")
    check_shape(origins, ["*", "3"], "origins")
    check_shape(directions, ["*", "3"], "directions")
    check_same_dtype({"origins": origins, "directions": directions})
    return check_broadcastable({"origins": origins.shape[:-1],
                                "directions": directions.shape[:-1]})


def prepare(verts: torch.Tensor, faces, origins: torch.Tensor, directions: torch.Tensor
            ) -> RayProblem:
    """Validate and flatten a query (``ShapeError``/``TypeError`` naming the argument).

    Example:
        >>> p = prepare(torch.eye(3), torch.tensor([[0, 1, 2]]), torch.zeros(4, 2, 3),
        ...             torch.ones(2, 3))
        >>> p.origins.shape, p.lead, p.scale.flatten().tolist()
        (torch.Size([1, 8, 3]), (4, 2), [2.0])
    """
    tris = check_mesh(verts, faces, finite=True)
    rays = check_rays(origins, directions)
    check_same_dtype({"verts": verts, "origins": origins, "directions": directions})
    if verts.dim() > 2 and not rays:  # a batch of meshes needs the ray dim R
        check_shape(origins, ["*", "R", "3"], "origins")
    if verts.dim() == 2:
        B, R, lead = 1, math.prod(rays), rays
    else:
        batch = check_broadcastable({"verts": verts.shape[:-2], "origins": rays[:-1]})
        B, R, lead = math.prod(batch), rays[-1], (*batch, rays[-1])
        verts = verts.expand(*batch, *verts.shape[-2:])
    o = origins.expand(*lead, 3).reshape(B, R, 3)
    d = directions.expand(*lead, 3).reshape(B, R, 3)
    v = verts.reshape(B, verts.shape[-2], 3)
    with torch.no_grad():
        v64 = v.detach().double()
        used = v64[:, tris.unique()] if B else v64
        big = torch.where(torch.isfinite(used), used.abs(), 0.0).amax((1, 2), keepdim=True) \
            if used.numel() else v64.new_ones(B, 1, 1)
        scale = power_of_two_scale(big)
        d64 = d.detach().double()
        dscale = power_of_two_scale(d64.abs().amax(-1, keepdim=True))
        finite = torch.isfinite(o).all(-1) & torch.isfinite(d).all(-1)
        valid = finite & (d != 0).any(-1)
    return RayProblem(v, o, d, tris, lead, scale, dscale, valid, ~finite)
