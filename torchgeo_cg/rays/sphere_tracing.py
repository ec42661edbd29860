"""Sphere tracing of signed distance fields, batched, with implicit-function gradients.

The march (``torchgeo_cg.rays._march``) runs without a graph: Lipschitz steps (or
over-relaxed steps with sign-change bracketing when no bound is known), then a
safeguarded secant refinement of the root. One differentiable evaluation at the root
then gives the gradients by the implicit function theorem: with ``f(o + t d; theta) = 0``,

    ``dt = -(df/dtheta dtheta + grad f . (do + t dd)) / (grad f . d)``,

implemented as ``t = t* - (f(o + t* d) - f*) / (grad f . d)`` with ``t*``, ``f*`` and the
denominator detached: the value is ``t*`` and autograd produces exactly the formula, for
the field's parameters, the origins and the directions, with memory independent of the
number of steps.
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.numerics import cast_back, safe_norm, working_dtype
from torchgeo_cg.rays._march import bracket, march, refine
from torchgeo_cg.rays._prepare import check_rays
from torchgeo_cg.rays.mesh_intersect import RayHits

__all__ = ["sphere_trace"]


def _check_options(sdf, lipschitz, t_max, max_steps, tol) -> None:
    if not callable(sdf):
        raise TypeError(f"sdf: expected a callable (N, 3) -> (N,), got {type(sdf).__name__}")
    if lipschitz is not None and not (isinstance(lipschitz, (int, float))
                                      and math.isfinite(lipschitz) and lipschitz > 0):
        raise ValueError(f"lipschitz: expected a positive finite bound or None, got {lipschitz!r}")
    if not (isinstance(t_max, (int, float)) and math.isfinite(t_max) and t_max > 0):
        raise ValueError(f"t_max: expected a positive finite ray length, got {t_max!r}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
        raise ValueError(f"max_steps: expected a positive int, got {max_steps!r}")
    if not (isinstance(tol, (int, float)) and 0 < tol < 1):
        raise ValueError(f"tol: expected a relative tolerance in (0, 1), got {tol!r}")


def _field(sdf):
    """``sdf`` with its output checked: ``(N,)`` or ``(N, 1)``, else a ShapeError."""
    def call(p: torch.Tensor) -> torch.Tensor:
        out = sdf(p)
        if not isinstance(out, torch.Tensor) or out.numel() != p.shape[0] or (
                out.dim() > 1 and out.shape[0] != p.shape[0]):
            got = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
            raise ShapeError(f"sdf: expected values of shape ({p.shape[0]},) for points "
                             f"({p.shape[0]}, 3), got {got}")
        return out.reshape(-1)
    return call


def _other_leaves(out: torch.Tensor, leaf: torch.Tensor) -> bool:
    """Whether ``out``'s graph reaches a tensor requiring grad other than ``leaf`` (the
    field's parameters): a walk over the graph's nodes, not over the data."""
    seen, stack = set(), [out.grad_fn]
    while stack:
        node = stack.pop()
        if node is None or node in seen:
            continue
        seen.add(node)
        var = getattr(node, "variable", None)
        if var is not None and var is not leaf:
            return True
        stack.extend(fn for fn, _ in node.next_functions)
    return False


def _differentiable(field, o, d, t_star, hit):
    """``(t, normals)`` at the hits by the implicit function theorem (see the module)."""
    t0 = torch.where(hit, t_star, 0.0).detach()
    rows = hit.nonzero().squeeze(1)
    t_out = torch.where(hit, t_star, 0.0).to(o.dtype)
    normals = o.new_zeros(o.shape)
    if rows.numel() == 0:
        return t_out + 0 * (o.sum() + d.sum()), normals
    orow, drow, trow = o[rows], d[rows], t0[rows]
    with torch.enable_grad():
        p = orow + trow[:, None] * drow
        leaf = None
        if not p.requires_grad:
            p = leaf = p.detach().requires_grad_(True)
        f = field(p).to(o.dtype)
    # the caller's grad mode decides (f itself always records, through p)
    need = records_graph(f) and (leaf is None or _other_leaves(f, leaf))
    with torch.enable_grad():
        (g,) = torch.autograd.grad(f.sum(), p, create_graph=need)
    den = (g * drow).sum(-1).detach()
    ok = den != 0
    corr = torch.where(ok, (f - f.detach()) / torch.where(ok, den, 1.0), 0.0)
    t_hit = trow - corr
    if need:  # the normals move with the hit: grad f at o + t d, t differentiable
        with torch.enable_grad():
            p2 = orow + t_hit[:, None] * drow
            (g,) = torch.autograd.grad(field(p2).to(o.dtype).sum(), p2, create_graph=True)
    length = safe_norm(g, dim=-1, keepdim=True)
    n_hit = g / torch.where(length > 0, length, 1.0)
    if not need:
        t_hit, n_hit = t_hit.detach(), n_hit.detach()
    t_out = t_out.index_put((rows,), t_hit)
    normals = normals.index_put((rows,), n_hit.to(o.dtype))
    return t_out, normals


def sphere_trace(sdf, origins: torch.Tensor, directions: torch.Tensor, *,
                 lipschitz: float | None = 1.0, t_max: float, max_steps: int = 256,
                 tol: float = 1e-7) -> RayHits:
    """The first root of an SDF along each ray, by sphere tracing, with implicit gradients.

    Convention:
        Rays ``origins + t * directions``, ``t >= 0`` in units of ``|direction|``; the
        first root of ``f`` along the ray from either side (an origin inside, ``f < 0``,
        finds the way out). ``normals`` are ``grad f / |grad f|`` at the hit: outward
        (pointing to ``f > 0``) for an SDF that is negative inside, whichever side the
        ray comes from. ``face`` is ``-1`` and ``bary`` 0.

    Args:
        sdf: a callable ``(N, 3) -> (N,)`` (or ``(N, 1)``): an SDF of
            :mod:`torchgeo_cg.sdf`, a CSG of them, an ``nn.Module``; its parameters get
            gradients.
        origins: ``(*, 3)`` ray origins (broadcast with ``directions``).
        directions: ``(*, 3)`` ray directions, any nonzero length.
        lipschitz: a bound ``L`` on ``|grad f|``: steps ``|f| / L`` never cross the
            surface (1 for an exact SDF; ``torchgeo_cg.mesh.lipschitz_bound`` of a
            network). ``None``: over-relaxed steps ``1.6 |f|`` with sign-change
            bracketing, for fields whose bound is unknown or loose (a thin feature may
            then be stepped over).
        t_max: the largest ``t`` searched (positive, finite).
        max_steps: field evaluations of the march at most.
        tol: relative tolerance: the march ends near the surface where
            ``|f| <= tol * |direction| * t_max``; a root bracketed by a sign change is then
            refined to a few ulps; without a sign change the near point is the hit.

    Returns:
        :class:`~torchgeo_cg.rays.RayHits` with shapes ``(*)`` and ``(*, 3)``.

    Raises:
        ShapeError: ``origins``/``directions`` not ``(*, 3)`` or not broadcastable; ``sdf``
            returns a wrong shape.
        TypeError: non-float or mixed dtypes, ``sdf`` not callable.
        ValueError: a bad ``lipschitz``, ``t_max``, ``max_steps`` or ``tol``.

    Example:
        >>> from torchgeo_cg.sdf import sphere
        >>> o = torch.tensor([[0.0, 0.0, 3.0], [0.0, 2.0, 3.0]], dtype=torch.float64)
        >>> d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]], dtype=torch.float64)
        >>> hits = sphere_trace(lambda p: sphere(p, 1.0), o, d, t_max=10.0)
        >>> hits.hit, hits.t
        (tensor([ True, False]), tensor([2., inf], dtype=torch.float64))
        >>> hits.normals[0]
        tensor([0., 0., 1.], dtype=torch.float64)
    """
    _check_options(sdf, lipschitz, t_max, max_steps, tol)
    lead = check_rays(origins, directions)
    dtype = origins.dtype
    work = working_dtype(dtype)  # float16/bfloat16 are traced in float32
    o = origins.expand(*lead, 3).reshape(-1, 3).to(work)
    d = directions.expand(*lead, 3).reshape(-1, 3).to(work)
    field = _field(sdf)
    finite = torch.isfinite(o).all(-1) & torch.isfinite(d).all(-1)
    valid = finite & (d != 0).any(-1)
    with torch.no_grad():
        od, dd = o.detach(), d.detach()
        t, f, tb, fb, state, side = march(field, od, dd, valid, lipschitz, float(t_max),
                                          max_steps, tol)
        bracket(field, od, dd, t, f, tb, fb, state, side, lipschitz)
        refine(field, od, dd, t, f, tb, fb, state)
        hit = valid & (state > 0) & (t <= t_max) & torch.isfinite(t)
    t, normals = _differentiable(field, o, d, t, hit)
    t = torch.where(hit, t, torch.inf)
    t = torch.where(finite, t, torch.nan)
    points = torch.where(hit[:, None], o + t[:, None] * d, 0.0)
    points = torch.where(finite[:, None], points, torch.nan)
    face = torch.full(hit.shape, -1, dtype=torch.long, device=o.device)
    return RayHits(hit.reshape(lead), cast_back(t, dtype).reshape(lead), face.reshape(lead),
                   origins.new_zeros(*lead, 3), cast_back(points, dtype).reshape(*lead, 3),
                   cast_back(normals, dtype).reshape(*lead, 3))
