"""Asymptotic decider and interior test of ``marching_cubes(..., ambiguity="asymptotic")``.

Face decision (Nielson and Hamann 1991, the asymptotic decider): on a face whose
corners alternate in sign, the bilinear interpolant has a saddle of value
``(f00 f11 - f01 f10) / (f00 + f11 - f01 - f10)``. With ``g = f - iso`` and the
diagonal ``(a, c)`` inside (``g < 0``), ``(b, d)`` outside, the saddle is inside, so
the inside corners are joined, exactly when ``g_a g_c > g_b g_d``: the sign of
``D = g_r0 g_r2 - g_r1 g_r3`` over the face's ring ``r0..r3``. ``D`` is formed from the
same four samples in the same order by both cells sharing the face, so they decide
identically and the mesh is closed by construction. It has no unit (scaling ``g``
scales ``D`` by a square; each cell's ``g`` is rescaled by a power of two first, so
the products neither underflow nor overflow at any field scale) and no epsilon;
``D == 0`` (saddle exactly at ``iso``) counts as outside, the tie rule of the samples.

Interior decision (the interior test of Marching Cubes 33, Chernyaev 1995, as Lewiner
et al. 2003 implement it): along each axis, the slices of the cell perpendicular to it
are bilinear, with corner values ``a_i(t) = u_i + w_i t`` on the four edges along that
axis. Its determinant ``h(t) = a0 a2 - a1 a3`` is quadratic in ``t``; two patches of
one sign are joined through a slice exactly when some slice is ambiguous with its
saddle of their sign, and ``h`` is extremal at ``t* = -B / (2 A)``, where a join, if any
exists along that axis, is strongest. The slice at ``t*`` therefore tells which
diagonal (and which sign) the interior joins; the tables translate that into the tube
(pair of loops) it makes, if it is a candidate of the configuration.

Decisions are computed in float64 (float32 or half samples are exact in it).
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.core.numerics import power_of_two_scale
from torchgeo_cg.mesh.marching_cubes._steps import idiv, imod, take
from torchgeo_cg.mesh.marching_cubes._tables import (
    MAX_TUBES,
    ConfigurationTables,
    configuration_tensors,
    corner_tables,
    table_tensors,
)

__all__ = ["face_decisions", "interior_decisions", "asymptotic_rows", "cell_rows"]


def face_decisions(g: torch.Tensor, cases: torch.Tensor, tables: ConfigurationTables):
    """Face bits ``(N,)`` long: bit ``f`` set when ambiguous face ``f`` joins its inside corners.

    Args:
        g: ``(N, 8)`` corner values minus ``iso``.
        cases: ``(N,)`` long corner bits.
        tables: :func:`~torchgeo_cg.mesh.marching_cubes._tables.configuration_tensors`.
    """
    gr = g[:, tables.face_rings]  # (N, 6, 4)
    det = gr[..., 0] * gr[..., 2] - gr[..., 1] * gr[..., 3]  # (N, 6)
    join = ((gr[..., 0] < 0) & (det > 0)) | ((gr[..., 1] < 0) & (det < 0))
    weights = 1 << torch.arange(6, device=g.device)
    return (join.long() * weights).sum(1) & take(tables.face_mask, cases)


def interior_decisions(g: torch.Tensor, config: torch.Tensor, tables: ConfigurationTables):
    """Tube ids ``(N,)`` long (0: none) from the extremal slice along each axis.

    Args:
        g: ``(N, 8)`` corner values minus ``iso``.
        config: ``(N,)`` long ``case * 64 + face_bits``.
        tables: the configuration tables.
    """
    tube = torch.zeros_like(config)
    witness = take(tables.witness, config)  # (N, 3, 2, 2)
    rows = torch.arange(config.shape[0], device=g.device)
    for axis in range(3):  # loop over the three axes, not over cells
        ring = tables.face_rings[2 * axis]
        u = g[:, ring]  # (N, 4) at the face side 0
        w = g[:, ring | (4 >> axis)] - u  # (N, 4) change along the axis
        quad = w[:, 0] * w[:, 2] - w[:, 1] * w[:, 3]
        lin = u[:, 0] * w[:, 2] + u[:, 2] * w[:, 0] - u[:, 1] * w[:, 3] - u[:, 3] * w[:, 1]
        t = -lin / torch.where(quad == 0, torch.ones_like(quad), 2 * quad)
        valid = (quad != 0) & (t > 0) & (t < 1)
        a = u + w * t[:, None]  # (N, 4) slice corners at t*
        inside = a < 0
        ambiguous = (inside[:, 0] == inside[:, 2]) & (inside[:, 1] == inside[:, 3]) & (
            inside[:, 0] != inside[:, 1])
        h = a[:, 0] * a[:, 2] - a[:, 1] * a[:, 3]
        sign = torch.where(inside[:, 0], h > 0, h < 0)  # the joined diagonal is inside
        diagonal = inside[:, 0] != sign
        found = witness[rows, axis, diagonal.long(), sign.long()]
        tube = torch.maximum(tube, torch.where(valid & ambiguous, found, 0))
    return tube


def _unit_scaled(g: torch.Tensor) -> torch.Tensor:
    """``g`` times a power of two per cell (exact) making its largest ``|g|`` ``[0.5, 1)``.

    The decisions read only signs of products of ``g``, which this leaves unchanged,
    while the products no longer underflow (fields of 1e-200) or overflow (1e200).
    Cells whose largest ``|g|`` is 0 or not finite are left as they are.
    """
    return g / power_of_two_scale(g.abs().amax(1, keepdim=True))


def _decider_values(f: torch.Tensor, iso_c: torch.Tensor) -> torch.Tensor:
    """``g = f - iso`` per cell, in a range where products of up to four ``g`` neither
    underflow nor overflow.

    One pass checks the plain difference: when every nonzero ``|g|`` lies in
    ``[2**-250, 2**250]`` (the usual case) it is used as is. Otherwise the cells are
    scaled twice by powers of two (exact, signs kept): before the difference, so
    ``f - iso`` cannot overflow near the top of float64, and after it, for the products.
    """
    g = f - iso_c[:, None]
    if g.numel():
        a = g.abs()
        low = torch.where(a > 0, a, math.inf).amin()
        if float(low) >= 2.0**-250 and float(a.amax()) <= 2.0**250:
            return g
    f_iso = _unit_scaled(torch.cat([f, iso_c[:, None]], 1))  # (N, 9)
    return _unit_scaled(f_iso[:, :8] - f_iso[:, 8:])


def asymptotic_rows(vol: torch.Tensor, iso_b: torch.Tensor, cell_id: torch.Tensor,
                    cases: torch.Tensor, real: torch.Tensor):
    """The configuration row of every active cell.

    Only real cells whose case has an ambiguous face or a possible tube read their
    corner values; the others take the row of their case (no decision to take).

    Args:
        vol: ``(B, X, Y, Z)`` samples (detached); iso_b: ``(B,)``.
        cell_id, cases: ``(A,)`` from :func:`~._steps.classify`.
        real: ``(A,)`` bool, cells that make triangles (padded cells read no values).

    Returns:
        ``(rows (A,) long, decided (N,) long sorted indices of the cells that took
        decisions, tables)``.
    """
    B, X, Y, Z = vol.shape
    device = vol.device
    tables = configuration_tensors(device)
    needs_values = (tables.face_mask != 0) | tables.needs_interior.view(256, 64).any(1)
    rows = take(tables.row.view(256, -1)[:, 0], cases)
    pick = (take(needs_values, cases) & real).nonzero().squeeze(1)
    if pick.numel() == 0:
        return rows, pick, tables
    corner_off = corner_tables(device)[2]
    corner_delta = (corner_off * torch.tensor([Y * Z, Z, 1], device=device)).sum(-1)
    cells = take(cell_id, pick)
    flat = vol.reshape(-1)
    f = take(flat, (cells[:, None] + corner_delta).view(-1)).view(-1, 8).double()
    iso_c = take(iso_b.double(), idiv(cells, X * Y * Z))
    g = _decider_values(f, iso_c)  # (N, 8)
    case_p = take(cases, pick)
    config = case_p * 64 + face_decisions(g, case_p, tables)
    tube = torch.zeros_like(config)
    ask = take(tables.needs_interior, config).nonzero().squeeze(1)
    if ask.numel():
        tube[ask] = interior_decisions(take(g, ask), take(config, ask), tables)
    rows[pick] = take(tables.row, config * MAX_TUBES + tube)
    return rows, pick, tables


def cell_rows(vol: torch.Tensor, iso_b: torch.Tensor, mask: torch.Tensor | None,
              cell_id: torch.Tensor, cases: torch.Tensor, ambiguity: str):
    """Table rows, triangle counts (0 where a cell makes none) and the table, per active cell.

    Args:
        vol: ``(B, X, Y, Z)`` samples (detached); iso_b: ``(B,)`` (detached).
        mask: ``None`` or bool ``(B, X, Y, Z)``: a cell makes triangles only where the
            mask is True at its far corner (corner 7).
        cell_id, cases: ``(A,)`` from :func:`~._steps.classify`.
        ambiguity: ``"asymptotic"`` or ``"separate"``.

    Returns:
        ``(rows (A,), n_tri (A,), tri_table (R, T, 3), centre)``: ``centre`` is
        ``(centre_mask (R,), decided (N,))`` for the asymptotic rule, else None.
    """
    B, X, Y, Z = vol.shape
    k, j, layer = imod(cell_id, Z), imod(idiv(cell_id, Z), Y), idiv(cell_id, Y * Z)
    real = (imod(layer, X) < X - 1) & (j < Y - 1) & (k < Z - 1)  # padded cells make nothing
    if mask is not None:  # the cell's far corner (corner 7) decides, as scikit-image
        far = cell_id + (Y * Z + Z + 1)
        real &= take(mask.view(-1), far.clamp_max(mask.numel() - 1))
    centre = None
    if ambiguity == "separate":
        tri_table, num_tris = table_tensors(vol.device)[:2]
        rows = cases
    else:
        rows, decided, tables = asymptotic_rows(vol, iso_b, cell_id, cases, real)
        tri_table, num_tris = tables.triangles, tables.num_triangles
        centre = (tables.centre_mask, decided)  # only decided cells can have a centre
    n_tri = torch.where(real, take(num_tris, rows), 0)
    return rows, n_tri, tri_table, centre
