"""The hit on a chosen face, in torch (differentiable) and refined in double-double.

The search decides *which* face each ray hits; this module computes *where*, in torch,
closed-form in that face's corners (Moeller and Trumbore 1997):

    ``s = o - v0``, ``p = d x e2``, ``q = s x e1``, ``den = e1 . p``,
    ``t = (e2 . q) / den``, ``b1 = (s . p) / den``, ``b2 = (d . q) / den``,

with ``e1 = v1 - v0``, ``e2 = v2 - v0``, so ``t``, the barycentric coordinates, the
points and the normals are differentiable w.r.t. the corners, the origins and the
directions (piecewise in the choice of face, like :func:`torchgeo_cg.sdf.mesh_sdf`).

Near-grazing rays make ``den`` a difference of nearly equal products, and plain float64
loses digits there; the value of ``t`` of such rays (:func:`plane_t` estimates the
condition) is therefore refined with the plane equation
``t = ((v0 - o) . n) / (d . n)``, ``n = e1 x e2``, in double-double arithmetic from the
exact float64 inputs (:mod:`~torchgeo_cg.rays._exact`): the correction is added detached,
so the value is the correctly computed one and the gradient stays the closed form's.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.numerics import safe_norm
from torchgeo_cg.rays._exact import dd_cross3, dd_div_to_float, dd_dot3, two_sum

__all__: list[str] = []


def refine_t(tri_n33: torch.Tensor, o_n3: torch.Tensor, d_n3: torch.Tensor) -> torch.Tensor:
    """``t`` of the rays ``o + t d`` on the planes of ``tri``, to float64's last bit.

    All inputs are float64 (scaled into ``[-1, 1]``); the differences ``v - o`` and
    ``v1 - v0`` are kept exact as double-doubles.

    Example:
        >>> tri = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=torch.float64)
        >>> refine_t(tri, torch.tensor([[0.1, 0.2, 0.3]], dtype=torch.float64),
        ...          torch.tensor([[0.0, 0.0, -0.1]], dtype=torch.float64))
        tensor([3.], dtype=torch.float64)
    """
    v0, v1, v2 = tri_n33.unbind(-2)
    e1 = [two_sum(v1[:, i], -v0[:, i]) for i in range(3)]
    e2 = [two_sum(v2[:, i], -v0[:, i]) for i in range(3)]
    w = [two_sum(v0[:, i], -o_n3[:, i]) for i in range(3)]
    n = dd_cross3(e1, e2)
    zero = torch.zeros_like(o_n3[:, 0])
    num = dd_dot3(w, n)
    den = dd_dot3([(d_n3[:, i], zero) for i in range(3)], n)
    safe = torch.where(den[0] == 0, 1.0, den[0])
    return dd_div_to_float(num[0], num[1], safe, den[1])


def plane_t(tri_n33: torch.Tensor, o_n3: torch.Tensor, d_n3: torch.Tensor) -> torch.Tensor:
    """``t`` on the planes of ``tri`` in plain float64, refined in double-double where its
    condition could cost more than a few ulps.

    The plain value ``((v0 - o) . n) / (d . n)`` has a relative error of about
    ``cond * eps`` with ``cond = sum|d_i n_i| / |d . n| + sum|w_i n_i| / |w . n| +
    2 |e1| |e2| / |n|`` (cancellation in each dot product, rounding of ``n``); rays
    with ``cond > 16`` (near-grazing, thin faces) get :func:`refine_t`.

    Example:
        >>> tri = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=torch.float64)
        >>> plane_t(tri, torch.tensor([[0.1, 0.2, 0.3]], dtype=torch.float64),
        ...         torch.tensor([[0.0, 0.0, -0.1]], dtype=torch.float64))
        tensor([3.], dtype=torch.float64)
    """
    v0, v1, v2 = tri_n33.unbind(-2)
    e1, e2, w = v1 - v0, v2 - v0, v0 - o_n3
    n = _cross(e1, e2)
    num, den = _dot(w, n), _dot(d_n3, n)
    t = num / torch.where(den == 0, 1.0, den)
    na = n.abs()
    cond = ((d_n3.abs() * na).sum(-1) / den.abs() + (w.abs() * na).sum(-1) / num.abs()
            + 2 * e1.norm(dim=-1) * e2.norm(dim=-1) / n.norm(dim=-1))
    bad = (~(cond <= 16)).nonzero().squeeze(1)  # NaN (0 / 0) included
    if bad.numel():
        t = t.index_put((bad,), refine_t(tri_n33[bad], o_n3[bad], d_n3[bad]))
    return t


def _cross(a, b):
    return torch.linalg.cross(a, b, dim=-1)


def _dot(a, b):
    return (a * b).sum(-1)


def hit_geometry(tri: torch.Tensor, o: torch.Tensor, d: torch.Tensor, hit: torch.Tensor,
                 t_exact: torch.Tensor):
    """Differentiable ``(t, b1, b2, normals)`` of rays ``(o, d) (..., 3)`` on the faces
    ``tri (..., 3, 3)`` where ``hit``; ``t`` carries the value ``t_exact`` (detached
    correction). Elsewhere the values are harmless zeros (no NaN forward or backward).

    Example:
        >>> tri = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
        >>> t, b1, b2, n = hit_geometry(tri, torch.tensor([[0.25, 0.5, 1.0]]),
        ...                             torch.tensor([[0.0, 0.0, -1.0]]),
        ...                             torch.tensor([True]), torch.tensor([1.0]))
        >>> t, b1, b2, n
        (tensor([1.]), tensor([0.2500]), tensor([0.5000]), tensor([[0., 0., 1.]]))
    """
    v0, v1, v2 = tri.unbind(-2)
    e1, e2, s = v1 - v0, v2 - v0, o - v0
    p = _cross(d, e2)
    q = _cross(s, e1)
    den = _dot(e1, p)
    ok = hit & (den != 0)
    safe = torch.where(ok, den, 1.0)
    t = torch.where(ok, _dot(e2, q) / safe, 0.0)
    b1 = torch.where(ok, _dot(s, p) / safe, 0.0)
    b2 = torch.where(ok, _dot(d, q) / safe, 0.0)
    t = t + (torch.where(ok, t_exact, 0.0) - t).detach()
    n = _cross(e1, e2)
    length = safe_norm(n, dim=-1, keepdim=True)
    n = torch.where(ok[..., None], n / torch.where(length > 0, length, 1.0), 0.0)
    return t, b1, b2, n
