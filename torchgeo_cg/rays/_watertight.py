"""The watertight ray-triangle test (Woop, Benthin and Wald 2013), float64, exact signs.

Woop, Benthin, Wald, "Watertight Ray/Triangle Intersection", JCGT 2(1), 2013. The ray
becomes the z axis of a sheared frame: with ``kz`` the axis of the largest ``|d|``
(``kx, ky`` the next two, swapped when ``d[kz] < 0`` so the winding is kept),
``S = (d[kx] / d[kz], d[ky] / d[kz], 1 / d[kz])``, every corner ``A`` relative to the
origin maps to ``(A[kx] - Sx A[kz], A[ky] - Sy A[kz])``, computed per corner, so a
corner shared by several faces gets the very same 2D coordinates in each. The edge
functions are the 2D cross products

    ``U = Cx By - Cy Bx``, ``V = Ax Cy - Ay Cx``, ``W = Bx Ay - By Ax``,

and the ray meets the triangle where they share one sign. Shared edges get values of
opposite sign bit for bit, so no ray falls between two faces; here their signs are
also *exact* (:func:`~torchgeo_cg.rays._exact.cross_sign`), so the signs around a vertex
are those of one planar configuration, and none falls through a vertex either.

Ties (an edge function exactly 0) follow one symbolic perturbation (Edelsbrunner and
Muecke's simulation of simplicity): the ray is moved to ``(eps, eps**2)`` in the sheared
plane, ``eps -> 0+``, which gives ``U`` the sign of ``Cy - By``, else of ``Bx - Cx``
(and so on cyclically). Where faces meet at a crossing point exactly one of them is hit;
a ray that only touches the surface there hits 0 or 2 of them. A triangle that is a
segment seen along the ray (zero projected area) is never hit.

The hit parameter is ``t = (U Az + V Bz + W Cz) / (U + V + W)`` with ``z = Sz A[kz]``.
"""

from __future__ import annotations

import torch

from torchgeo_cg.rays._exact import cross_sign

__all__: list[str] = []


def ray_shear(directions_n3: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(perm (n, 3) long [kx, ky, kz], shear (n, 3) [Sx, Sy, Sz])`` of every ray.

    Example:
        >>> perm, s = ray_shear(torch.tensor([[0.0, 0.0, -2.0]], dtype=torch.float64))
        >>> perm, s
        (tensor([[1, 0, 2]]), tensor([[-0.0000, -0.0000, -0.5000]], dtype=torch.float64))
    """
    kz = directions_n3.abs().argmax(-1)
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    dz = directions_n3.gather(-1, kz[:, None]).squeeze(-1)
    neg = dz < 0
    kx, ky = torch.where(neg, ky, kx), torch.where(neg, kx, ky)
    perm = torch.stack([kx, ky, kz], -1)
    dp = directions_n3.gather(-1, perm)
    safe = torch.where(dz == 0, 1.0, dz)
    shear = torch.stack([dp[:, 0] / safe, dp[:, 1] / safe, 1.0 / safe], -1)
    return perm, shear


def _tie_sign(px, py, qx, qy):
    """Sign of the edge function ``Q x P`` (2D) after the symbolic perturbation:
    ``sign(Qy - Py)``, else ``sign(Px - Qx)``."""
    first = torch.sign(qy - py)
    return torch.where(first != 0, first, torch.sign(px - qx))


def watertight_test(tri_n33: torch.Tensor, origins_n3: torch.Tensor, perm_n3: torch.Tensor,
                    shear_n3: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(hit (n,) bool, t (n,))`` of ``n`` ray-triangle pairs (float64, scaled data).

    ``t`` is in units of the (scaled) direction and is only meaningful where ``hit``;
    the caller checks its range.

    Example:
        >>> tri = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=torch.float64)
        >>> o = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
        >>> perm, s = ray_shear(torch.tensor([[0.0, 0.0, -1.0]], dtype=torch.float64))
        >>> watertight_test(tri, o, perm, s)  # the vertex (0, 0, 0): hit, at t = 1
        (tensor([True]), tensor([1.], dtype=torch.float64))
    """
    rel = (tri_n33 - origins_n3[:, None, :]).gather(-1, perm_n3[:, None, :].expand(-1, 3, 3))
    sx, sy, sz = shear_n3.unbind(-1)
    x = rel[..., 0] - sx[:, None] * rel[..., 2]  # (n, 3): corners A, B, C
    y = rel[..., 1] - sy[:, None] * rel[..., 2]
    z = sz[:, None] * rel[..., 2]
    ax, bx, cx = x.unbind(-1)
    ay, by, cy = y.unbind(-1)
    u, su = cross_sign(cx, by, cy, bx)
    v, sv = cross_sign(ax, cy, ay, cx)
    w, sw = cross_sign(bx, ay, by, ax)
    su = torch.where(su == 0, _tie_sign(bx, by, cx, cy), su)
    sv = torch.where(sv == 0, _tie_sign(cx, cy, ax, ay), sv)
    sw = torch.where(sw == 0, _tie_sign(ax, ay, bx, by), sw)
    hit = (su == sv) & (sv == sw) & (su != 0)
    det = u + v + w
    t = (u * z[:, 0] + v * z[:, 1] + w * z[:, 2]) / torch.where(det == 0, 1.0, det)
    hit = hit & (det != 0) & torch.isfinite(t)
    return hit, t
