"""Tensor-product patches: Bezier, B-spline and NURBS surfaces, partial derivatives, normals.

``S(u, v) = sum_ij N_i(u) M_j(v) P_ij`` (NURBS: ``sum N M w P / sum N M w``) with the
basis of :func:`~torchgeo_cg.curves.bspline_basis` in each direction (a Bezier patch
of degree ``(m, n)`` is the B-spline patch of clamped knots with one span).

Convention:
    - ``control_grid`` is ``(*, m + 1, n + 1, D)``: axis ``-3`` runs along ``u``, axis
      ``-2`` along ``v``, the last holds coordinates. NURBS ``weights`` are
      ``(*, m + 1, n + 1)``, positive.
    - ``u`` and ``v`` are paired parameters ``(*, N)`` (or ``(N,)``, shared), not a grid:
      point ``k`` is ``S(u_k, v_k)``. :func:`~torchgeo_cg.surfaces.surface_mesh` makes a
      grid. Bezier patches are defined on ``[0, 1]^2``; B-spline and NURBS patches on
      ``[u_p, u_{m+1}] x [v_q, v_{n+1}]`` of their knots (``None``: clamped uniform on
      ``[0, 1]``), with right-continuous spans and extrapolation outside, as curves.
    - ``degree`` is an int (both directions) or a pair ``(p, q)``; ``knots_u``/``knots_v``
      are full vectors ``(m + p + 2,)`` / ``(n + q + 2,)`` or per patch ``(*, K)``.
    - Derivatives come from the ``*_derivatives`` siblings, one form for the three kinds:
      :class:`SurfaceDerivatives` ``(points, du, dv, normals)``.
    - Normals are ``du x dv / |du x dv|`` (3D only; ``None`` otherwise), so the
      orientation follows the parameter axes: ``u`` to the right, ``v`` up, normal
      toward the viewer. Where ``du`` or ``dv`` vanishes (to rounding: below the
      rounding bound of the sum that computes it), as on a degenerate edge such as a
      sphere's pole, the normal is the limit from inside the domain: ``du ~ (v - v_e)
      duv`` near an edge ``v = v_e``, so it is ``sign * duv x dv`` (and ``sign * du x
      duv`` for a degenerate ``dv``), ``sign = +1`` at the low end of the domain and
      ``-1`` at the high end. Where that vanishes too (a collapsed corner), the normal
      is zero.
    - Differentiable with respect to the grid, weights, ``u``, ``v`` and knots. dtypes
      are promoted; float16/bfloat16 rejected. A patch scaled by ``s`` has points and
      derivatives times ``s``, the same normals.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import ShapeError, check_broadcastable, check_float, check_shape
from torchgeo_cg.core.numerics import safe_div, safe_norm
from torchgeo_cg.curves.knots import (
    check_bspline_knots,
    find_spans,
    local_basis_list,
    uniform_knots,
)
from torchgeo_cg.curves.nurbs import check_weights
from torchgeo_cg.surfaces._degree import check_surface_degree

__all__ = [
    "SurfaceDerivatives",
    "bezier_surface",
    "bezier_surface_derivatives",
    "bspline_surface",
    "bspline_surface_derivatives",
    "nurbs_surface",
    "nurbs_surface_derivatives",
]


class SurfaceDerivatives(NamedTuple):
    """Points, first partial derivatives and unit normals of a patch.

    Attributes:
        points: ``(*, N, D)``.
        du: ``(*, N, D)`` ``dS/du``.
        dv: ``(*, N, D)`` ``dS/dv``.
        normals: ``(*, N, 3)`` unit normals for ``D = 3``, else ``None``.

    Example:
        >>> grid = torch.tensor([[[0.0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 0]]])
        >>> bezier_surface_derivatives(grid, torch.tensor([0.5]), torch.tensor([0.5])).normals
        tensor([[0., 0., 1.]])
    """

    points: torch.Tensor
    du: torch.Tensor
    dv: torch.Tensor
    normals: torch.Tensor | None


def _check_grid(control_grid: torch.Tensor, p: int, q: int) -> tuple[int, int]:
    check_float(control_grid, "control_grid", low_precision=False)
    sizes = check_shape(control_grid, ["*", "M", "N", "D"], "control_grid")
    if sizes["M"] < p + 1 or sizes["N"] < q + 1:
        raise ShapeError(f"control_grid: degree ({p}, {q}) needs at least ({p + 1}, {q + 1}) "
                         f"control points, got shape {tuple(control_grid.shape)}")
    return sizes["M"], sizes["N"]


def _params(u, v, grid):
    for name, x in (("u", u), ("v", v)):
        check_float(x, name, low_precision=False)
        check_shape(x, ["*", "N"], name)
    if u.shape[-1] != v.shape[-1]:
        raise ShapeError(f"v: expected as many parameters as u ({u.shape[-1]}), got shape "
                         f"{tuple(v.shape)}")
    check_broadcastable({"control_grid": grid.shape[:-3], "u": u.shape[:-1], "v": v.shape[:-1]})


def _knots(knots, count, degree, name, like):
    if knots is None:
        return uniform_knots(count, degree, dtype=like.dtype, device=like.device)
    check_bspline_knots(knots, count, degree, name)
    return knots.to(like.dtype)


#: parameters per chunk of a patch evaluation (its intermediates stay in cache)
_CHUNK = 8192


def _tensor_product(grid, u, v, knots_u, knots_v, p, q, derivatives: bool):
    """``S_ab`` for ``(a, b)`` in ``(0,0), (1,0), (0,1), (1,1)`` (only ``(0,0)`` if not
    ``derivatives``), and the same sums with absolute basis values on ``|P|``.

    The points are processed in chunks (one pass where autograd records); within one, the
    ``(p + 1)(q + 1)`` local control points are gathered one at a time from coordinate
    planes, so every operation runs contiguously along the parameters.
    """
    rows, cols, e = grid.shape[-3:]
    batch = torch.broadcast_shapes(grid.shape[:-3], u.shape[:-1], v.shape[:-1],
                                   knots_u.shape[:-1], knots_v.shape[:-1])
    n = u.shape[-1]
    planes = grid.movedim(-1, 0)  # (e, *, M, N)
    if derivatives:  # one more plane: |P|_1, for the rounding bounds
        planes = torch.cat([planes, grid.detach().abs().sum(-1)[None]])
    planes = planes.movedim(0, -1).expand(*batch, rows, cols, planes.shape[0])
    planes = planes.movedim(-1, 0).flatten(-2)  # (E, *, M N)
    knots_u = knots_u.expand(*batch, knots_u.shape[-1])
    knots_v = knots_v.expand(*batch, knots_v.shape[-1])
    u, v = u.expand(*batch, n), v.expand(*batch, n)
    record = records_graph(grid, u, v, knots_u, knots_v)
    step = n if record else max(1, _CHUNK // max(1, batch.numel()))
    keys = [(0, 0), (1, 0), (0, 1), (1, 1)] if derivatives else [(0, 0)]
    out = {}
    for c in range(0, n, step):  # loop over chunks of parameters
        part = _patch_chunk(planes, knots_u, knots_v, u[..., c:c + step], v[..., c:c + step],
                            p, q, cols, e, derivatives)
        if record:
            out = part
            break
        if not out:
            out = {key: x.new_empty(*x.shape[:-1], n) for key, x in part.items()}
        for key, x in part.items():
            out[key][..., c:c + step] = x
    out = {key: (x.movedim(0, -1) if key in keys else x) for key, x in out.items()}
    ends_u = (knots_u[..., p:p + 1], knots_u[..., rows:rows + 1])
    ends_v = (knots_v[..., q:q + 1], knots_v[..., cols:cols + 1])
    out["sign_u"] = _end_sign(u, *ends_u)
    out["sign_v"] = _end_sign(v, *ends_v)
    return out


def _patch_chunk(planes, knots_u, knots_v, u, v, p, q, cols, e, derivatives):
    """:func:`_tensor_product` on one chunk: ``(e, *, n)`` sums and ``(*, n)`` bounds."""
    order = 1 if derivatives else 0
    su = find_spans(knots_u, u, p)
    sv = find_spans(knots_v, v, q)
    bu = local_basis_list(knots_u, u, su, p, order)  # [order][i] (*, n)
    bv = local_basis_list(knots_v, v, sv, q, order)
    base = (su - p) * cols + (sv - q)  # flat index of the local corner
    inplace = not records_graph(planes, u, v, knots_u, knots_v)
    sums: dict = {}
    for i in range(p + 1):  # loop over the p + 1 local rows
        along = [None] * (order + 1)
        size_v = [None] * (order + 1)
        for j in range(q + 1):  # loop over the q + 1 local control points of a row
            index = base + (i * cols + j) if i or j else base
            point = planes.gather(-1, index.expand(planes.shape[0], *index.shape))
            for b in range(order + 1):
                along[b] = _accumulate(along[b], point[:e], bv[b][j], inplace)
                if derivatives:
                    size_v[b] = _accumulate(size_v[b], point[e], bv[b][j].abs(), True)
        for a in range(order + 1):
            for b in range(order + 1):
                sums[a, b] = _accumulate(sums.get((a, b)), along[b], bu[a][i], inplace)
        if derivatives:
            sums["bound_u"] = _accumulate(sums.get("bound_u"), size_v[0], bu[1][i].abs(), True)
            sums["bound_v"] = _accumulate(sums.get("bound_v"), size_v[1], bu[0][i].abs(), True)
    return sums


def _accumulate(total, x, weight, inplace: bool):
    """``total + x * weight`` (``x * weight`` when ``total`` is None), in place if allowed."""
    if total is None:
        return x * weight
    return total.addcmul_(x, weight) if inplace else torch.addcmul(total, x, weight)


def _end_sign(x, low, high):
    """``-1`` at (or past) the high end of the domain, else ``+1``."""
    return torch.where(x >= high, -1.0, 1.0).to(x.dtype) if x.numel() else x


def _surface_normals(du: torch.Tensor, dv: torch.Tensor, duv: torch.Tensor,
                    degenerate_u: torch.Tensor, degenerate_v: torch.Tensor,
                    sign_u: torch.Tensor, sign_v: torch.Tensor) -> torch.Tensor:
    """Unit normals ``(*, N, 3)`` with the degenerate-edge rule of the module docstring.

    Args:
        du, dv, duv: ``(*, N, 3)`` first and mixed partial derivatives.
        degenerate_u, degenerate_v: ``(*, N)`` bool, ``du`` / ``dv`` zero to rounding.
        sign_u, sign_v: ``(*, N)`` ``+1`` at the low end of the domain, ``-1`` at the high.

    Example:
        >>> du = torch.tensor([[0.0, 0.0, 0.0]])  # a pole: du vanishes
        >>> dv, duv = torch.tensor([[0.0, 1.0, 0.0]]), torch.tensor([[1.0, 0.0, 0.0]])
        >>> no = torch.tensor([False])
        >>> _surface_normals(du, dv, duv, torch.tensor([True]), no, torch.ones(1), torch.ones(1))
        tensor([[0., 0., 1.]])
    """
    du = torch.where(degenerate_u[..., None], 0.0, du)
    dv = torch.where(degenerate_v[..., None], 0.0, dv)
    cross = torch.linalg.cross(du, dv)
    limit = (sign_v[..., None] * torch.linalg.cross(duv, dv)
             + sign_u[..., None] * torch.linalg.cross(du, duv))
    use = (degenerate_u | degenerate_v)[..., None]
    cross = torch.where(use, limit, cross)
    return safe_div(cross, safe_norm(cross, dim=-1, keepdim=True))


def _derivatives(parts, rational: bool, p: int, q: int) -> SurfaceDerivatives:
    if rational:
        h = parts
        w = h[0, 0][..., -1:]
        s = safe_div(h[0, 0][..., :-1], w)
        du = safe_div(h[1, 0][..., :-1] - h[1, 0][..., -1:] * s, w)
        dv = safe_div(h[0, 1][..., :-1] - h[0, 1][..., -1:] * s, w)
        duv = safe_div(h[1, 1][..., :-1] - h[1, 1][..., -1:] * s - h[1, 0][..., -1:] * dv
                       - h[0, 1][..., -1:] * du, w)
        scale_w = w[..., 0].detach().abs()
        bound_u = safe_div(h["bound_u"] + h[1, 0][..., -1].detach().abs()
                           * s.detach().abs().sum(-1), scale_w)
        bound_v = safe_div(h["bound_v"] + h[0, 1][..., -1].detach().abs()
                           * s.detach().abs().sum(-1), scale_w)
    else:
        s, du, dv, duv = parts[0, 0], parts[1, 0], parts[0, 1], parts[1, 1]
        bound_u, bound_v = parts["bound_u"], parts["bound_v"]
    normals = None
    if s.shape[-1] == 3:
        eps = torch.finfo(s.dtype).eps * 8 * (p + q + 2)
        degenerate_u = du.detach().abs().sum(-1) <= eps * bound_u
        degenerate_v = dv.detach().abs().sum(-1) <= eps * bound_v
        normals = _surface_normals(du, dv, duv, degenerate_u, degenerate_v, parts["sign_u"],
                                  parts["sign_v"])
    return SurfaceDerivatives(s, du, dv, normals)


def _prepare(control_grid, u, v, degree, knots_u, knots_v, weights=None):
    p, q = check_surface_degree(degree)
    rows, cols = _check_grid(control_grid, p, q)
    _params(u, v, control_grid)
    dtype = torch.promote_types(torch.promote_types(control_grid.dtype, u.dtype), v.dtype)
    for name, k in (("knots_u", knots_u), ("knots_v", knots_v)):
        if k is not None:
            check_float(k, name, low_precision=False)
            dtype = torch.promote_types(dtype, k.dtype)
    grid = control_grid.to(dtype)
    if weights is not None:
        check_float(weights, "weights", low_precision=False)
        check_shape(weights, ["*", rows, cols], "weights")
        check_weights(weights.flatten(-2), grid.flatten(-3, -2))
        weights = weights.to(dtype)
        check_broadcastable({"control_grid": grid.shape[:-3], "weights": weights.shape[:-2],
                             "u": u.shape[:-1], "v": v.shape[:-1]})
        batch = torch.broadcast_shapes(grid.shape[:-3], weights.shape[:-2])
        grid = grid.expand(*batch, *grid.shape[-3:])
        weights = weights.expand(*batch, rows, cols)[..., None]
        grid = torch.cat([grid * weights, weights], -1)  # homogeneous (*, M, N, D + 1)
    ku = _knots(knots_u, rows, p, "knots_u", grid)
    kv = _knots(knots_v, cols, q, "knots_v", grid)
    return grid, u.to(dtype), v.to(dtype), ku, kv, p, q


def _empty(grid, u, v, rational):
    if u.numel() and v.numel() and grid.numel():
        return None
    batch = torch.broadcast_shapes(grid.shape[:-3], u.shape[:-1], v.shape[:-1])
    d = grid.shape[-1] - (1 if rational else 0)
    return grid.new_zeros(*batch, u.shape[-1], d)


def _evaluate(control_grid, u, v, degree, knots_u, knots_v, weights, derivatives):
    grid, u, v, ku, kv, p, q = _prepare(control_grid, u, v, degree, knots_u, knots_v, weights)
    rational = weights is not None
    empty = _empty(grid, u, v, rational)
    if empty is not None:
        if not derivatives:
            return empty
        return SurfaceDerivatives(empty, empty, empty, empty if empty.shape[-1] == 3 else None)
    parts = _tensor_product(grid, u, v, ku, kv, p, q, derivatives)
    if derivatives:
        return _derivatives(parts, rational, p, q)
    s = parts[0, 0]
    return safe_div(s[..., :-1], s[..., -1:]) if rational else s


def _bezier_degree(control_grid):
    check_float(control_grid, "control_grid", low_precision=False)
    check_shape(control_grid, ["*", "M", "N", "D"], "control_grid")
    m, n = control_grid.shape[-3] - 1, control_grid.shape[-2] - 1
    if m < 0 or n < 0:
        raise ShapeError(f"control_grid: expected at least one control point per direction, "
                         f"got shape {tuple(control_grid.shape)}")
    return m, n


def bezier_surface(control_grid: torch.Tensor, u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Evaluate tensor-product Bezier patches of degree ``(m, n)`` at paired ``(u, v)``.

    Convention:
        See the module docstring; the domain is ``[0, 1]^2``, values outside
        extrapolate the polynomial.

    Args:
        control_grid: ``(*, m + 1, n + 1, D)``.
        u: ``(N,)`` or ``(*, N)``.
        v: ``(N,)`` or ``(*, N)``.

    Returns:
        ``(*, N, D)`` points.

    Example:
        >>> grid = torch.tensor([[[0.0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 1]]])
        >>> bezier_surface(grid, torch.tensor([0.5, 1.0]), torch.tensor([0.5, 1.0]))
        tensor([[0.5000, 0.5000, 0.2500],
                [1.0000, 1.0000, 1.0000]])
    """
    return _evaluate(control_grid, u, v, _bezier_degree(control_grid), None, None, None, False)


def bezier_surface_derivatives(control_grid: torch.Tensor, u: torch.Tensor,
                               v: torch.Tensor) -> SurfaceDerivatives:
    """Points, ``dS/du``, ``dS/dv`` and unit normals of Bezier patches (see :func:`bezier_surface`).

    Returns:
        :class:`SurfaceDerivatives` ``(points, du, dv (*, N, D), normals (*, N, 3) | None)``.

    Example:
        >>> grid = torch.tensor([[[0.0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 1]]])
        >>> d = bezier_surface_derivatives(grid, torch.tensor([0.0]), torch.tensor([0.0]))
        >>> d.du, d.dv, d.normals
        (tensor([[1., 0., 0.]]), tensor([[0., 1., 0.]]), tensor([[0., 0., 1.]]))
    """
    return _evaluate(control_grid, u, v, _bezier_degree(control_grid), None, None, None, True)


def bspline_surface(control_grid: torch.Tensor, u: torch.Tensor, v: torch.Tensor, degree,
                    knots_u: torch.Tensor | None = None,
                    knots_v: torch.Tensor | None = None) -> torch.Tensor:
    """Evaluate tensor-product B-spline patches at paired ``(u, v)``.

    Convention:
        See the module docstring (knots, spans and extrapolation as
        :func:`~torchgeo_cg.curves.bspline`).

    Args:
        control_grid: ``(*, m + 1, n + 1, D)``.
        u, v: ``(N,)`` or ``(*, N)``.
        degree: ``p`` or ``(p, q)``.
        knots_u: ``(m + p + 2,)`` or ``(*, m + p + 2)``; ``None``: clamped uniform.
        knots_v: ``(n + q + 2,)`` or ``(*, n + q + 2)``; ``None``: clamped uniform.

    Returns:
        ``(*, N, D)`` points.

    Example:
        >>> grid = torch.stack(torch.meshgrid(torch.arange(4.0), torch.arange(3.0),
        ...                                   indexing="ij"), -1)  # the plane (i, j)
        >>> bspline_surface(grid, torch.tensor([0.5]), torch.tensor([0.5]), (2, 1))
        tensor([[1.5000, 1.0000]])
    """
    return _evaluate(control_grid, u, v, degree, knots_u, knots_v, None, False)


def bspline_surface_derivatives(control_grid: torch.Tensor, u: torch.Tensor, v: torch.Tensor,
                                degree, knots_u: torch.Tensor | None = None,
                                knots_v: torch.Tensor | None = None) -> SurfaceDerivatives:
    """Points, partial derivatives and normals of B-spline patches (see :func:`bspline_surface`).

    Returns:
        :class:`SurfaceDerivatives` ``(points, du, dv (*, N, D), normals (*, N, 3) | None)``.

    Example:
        >>> grid = torch.stack(torch.meshgrid(torch.arange(4.0), torch.arange(3.0),
        ...                                   indexing="ij"), -1)
        >>> d = bspline_surface_derivatives(grid, torch.tensor([0.5]), torch.tensor([0.5]), 1)
        >>> d.du, d.dv, d.normals
        (tensor([[3., 0.]]), tensor([[0., 2.]]), None)
    """
    return _evaluate(control_grid, u, v, degree, knots_u, knots_v, None, True)


def nurbs_surface(control_grid: torch.Tensor, weights: torch.Tensor, u: torch.Tensor,
                  v: torch.Tensor, degree, knots_u: torch.Tensor | None = None,
                  knots_v: torch.Tensor | None = None) -> torch.Tensor:
    """Evaluate NURBS patches at paired ``(u, v)``.

    Convention:
        See the module docstring; ``weights (*, m + 1, n + 1)`` positive.

    Args:
        control_grid: ``(*, m + 1, n + 1, D)``.
        weights: ``(*, m + 1, n + 1)``.
        u, v: ``(N,)`` or ``(*, N)``.
        degree: ``p`` or ``(p, q)``.
        knots_u, knots_v: as :func:`bspline_surface`.

    Returns:
        ``(*, N, D)`` points.

    Example:
        >>> arc = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # quarter circle in u
        >>> grid = torch.stack([torch.cat([arc, torch.zeros(3, 1)], -1),
        ...                     torch.cat([arc, torch.ones(3, 1)], -1)], 1)  # (3, 2, 3)
        >>> w = torch.tensor([1.0, 0.5 ** 0.5, 1.0])[:, None].expand(3, 2)
        >>> p = nurbs_surface(grid, w, torch.tensor([0.3, 0.6]), torch.tensor([0.0, 0.5]), (2, 1))
        >>> p[..., :2].norm(dim=-1), p[..., 2]  # on the unit cylinder
        (tensor([1.0000, 1.0000]), tensor([0.0000, 0.5000]))
    """
    return _evaluate(control_grid, u, v, degree, knots_u, knots_v, weights, False)


def nurbs_surface_derivatives(control_grid: torch.Tensor, weights: torch.Tensor,
                              u: torch.Tensor, v: torch.Tensor, degree,
                              knots_u: torch.Tensor | None = None,
                              knots_v: torch.Tensor | None = None) -> SurfaceDerivatives:
    """Points, exact rational partial derivatives and normals of NURBS patches.

    Convention:
        As :func:`nurbs_surface`; ``S_u = (A_u - w_u S) / w`` (quotient rule, Piegl &
        Tiller eq. 4.20).

    Returns:
        :class:`SurfaceDerivatives` ``(points, du, dv (*, N, D), normals (*, N, 3) | None)``.

    Example:
        >>> arc = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        >>> grid = torch.stack([torch.cat([arc, torch.zeros(3, 1)], -1),
        ...                     torch.cat([arc, torch.ones(3, 1)], -1)], 1)
        >>> w = torch.tensor([1.0, 0.5 ** 0.5, 1.0])[:, None].expand(3, 2)
        >>> d = nurbs_surface_derivatives(grid, w, torch.tensor([0.0]), torch.tensor([0.5]), (2, 1))
        >>> d.normals  # du x dv points out of the cylinder at (1, 0)
        tensor([[1., 0., 0.]])
    """
    return _evaluate(control_grid, u, v, degree, knots_u, knots_v, weights, True)
