"""The slab scheduler of :func:`~torchgeo_cg.mesh.marching_cubes.marching_cubes`.

A volume with many active cells, in hard mode without a ``mask`` and with no gradient
recorded, is extracted a few cell layers (a slab of about :data:`SLAB_ACTIVE` active
cells) at a time along the stacked x, so the working buffers follow the slab, not the
volume; the result is the one-go result bit for bit.
"""

from __future__ import annotations

import torch

from torchgeo_cg.mesh.marching_cubes._args import world_map
from torchgeo_cg.mesh.marching_cubes._decider import cell_rows
from torchgeo_cg.mesh.marching_cubes._steps import (
    any_centre,
    find_centres,
    idiv,
    interpolate,
    lower_crossings,
    place_centres,
    take,
    triangulate,
    weld,
)

__all__ = ["SLAB_ACTIVE", "wants_slabs", "extract_slabbed"]

#: Active cells per slab (about) of a volume extracted slab by slab; a volume with
#: at most twice as many is extracted in one go.
SLAB_ACTIVE = 1 << 15


def wants_slabs(n_active: int, args, grad: bool) -> bool:
    """Whether a call with ``n_active`` active cells runs slab by slab (hard mode, no
    ``mask``, no gradient recorded, more than ``2 * SLAB_ACTIVE`` active cells)."""
    return n_active > 2 * SLAB_ACTIVE and args.tau is None and args.mask is None and not grad


def _slab_plan(cell_id, cases_a, shape):
    """Where the slabs of about :data:`SLAB_ACTIVE` active cells start and end (as many
    slabs as the nearest whole number of :data:`SLAB_ACTIVE` in the active cells, cut at
    even shares).

    Returns ``(bounds, a_lo, a_next, v_at, w_per)``: the slabs' first cell layers (and the
    end), the first active cell of each slab and of the layer after each slab, the welded
    vertices before each slab, and the welded vertices per volume ``(B,)``.
    """
    B, X, Y, Z = shape
    YZ, device = Y * Z, cell_id.device
    nv = take(lower_crossings(device).sum(1), cases_a)  # (A,) vertices each cell owns
    v_start = torch.cat([nv.new_zeros(1), nv.cumsum(0)])  # (A + 1,)
    layer = idiv(cell_id, YZ)
    n_active = cell_id.shape[0]
    n_slabs = max(1, round(n_active / SLAB_ACTIVE))  # slabs of 0.75 to 1.25 SLAB_ACTIVE cells
    at = torch.arange(1, n_slabs, device=device) * n_active // n_slabs
    cuts = torch.unique(take(layer, at))
    bounds = [0, *(c for c in cuts.tolist() if c > 0), B * X]
    edges = torch.tensor(bounds + [min(b + 1, B * X) for b in bounds[1:]], device=device)
    cell_at = torch.searchsorted(cell_id, edges * YZ).tolist()
    n_slabs = len(bounds) - 1
    a_lo, a_next = cell_at[:n_slabs + 1], cell_at[n_slabs + 1:]
    v_at = take(v_start, torch.tensor(a_lo, device=device)).tolist()
    w_per = torch.zeros(B, dtype=torch.long, device=device)
    if B > 1:
        w_per.index_add_(0, idiv(cell_id, Y * Z * X), nv)
    return bounds, a_lo, a_next, v_at, w_per


def extract_slabbed(vol, args, ambiguity, cell_id, cases_a, backend: str = "torch"):
    """Hard mode without a mask and without autograd, slab by slab along the stacked x:
    ``(verts (V, 3), faces (F, 3), normals (V, 3), (verts_per_mesh, faces_per_mesh))`` in
    the working dtype.

    The steps run on the active cells of a few cell layers at a time (about
    :data:`SLAB_ACTIVE` cells), so their buffers follow the slab, not the volume. A slab
    welds the vertices of its layers and of the next one (its faces and centres use
    those), places them from the same stencils, and keeps its own layers'; vertex and
    centre ids are offset by the counts before the slab, known from the cases. The
    result is the one-go result, bit for bit: every vertex and centre is computed by the
    same operations on the same samples, faces come in cell order, and the final
    order is the one-go order (welded vertices by key, then the centres by cell, per
    volume).
    """
    B, X, Y, Z = vol.shape
    XYZ = X * Y * Z
    device = vol.device
    det_vol, det_iso = vol.detach(), args.iso.detach()
    to_world = world_map(args)
    with torch.no_grad():
        bounds, a_lo, a_next, v_at, w_per = _slab_plan(cell_id, cases_a, vol.shape)
        n_slabs = len(bounds) - 1
        W = v_at[-1]  # welded vertices in all
        if B > 1:
            w_incl = w_per.cumsum(0)  # welded vertices in volumes <= b
            c_per = torch.zeros(B, dtype=torch.long, device=device)
    verts_w, normals_w, verts_c, normals_c, face_parts, b_f_parts = ([] for _ in range(6))
    n_centres = 0
    id_dtype = torch.int32
    for n in range(n_slabs):  # loop over slabs of cell layers, not over cells
        a0, a1, a2 = a_lo[n], a_lo[n + 1], a_next[n]
        if a0 == a1:
            continue
        with torch.no_grad():
            own_id = cell_id[a0:a1]
            n_own = v_at[n + 1] - v_at[n]
            faces, cell_of_face, centres, verts, normals = _slab_mesh(
                det_vol, det_iso, cell_id[a0:a2], cases_a[a0:a2], a1 - a0,
                (bounds[n], bounds[n + 1]), ambiguity, args, to_world, backend)
            V_sub = verts.shape[0]
            n_c = 0
            if centres is not None:
                both_v, both_n = place_centres(verts, normals, centres)
                verts_c.append(both_v[V_sub:])
                normals_c.append(both_n[V_sub:])
                n_c = both_v.shape[0] - V_sub
                if B > 1:
                    c_per += torch.bincount(centres.b, minlength=B)
                del both_v, both_n
            verts_w.append(verts[:n_own])
            normals_w.append(normals[:n_own])
            del verts, normals
            b_f = idiv(take(own_id, cell_of_face), XYZ) if B > 1 else None  # (F_s,)
            _packed_ids(faces, b_f, V_sub, v_at[n], W, n_centres, c_per if B > 1 else None,
                        w_incl if B > 1 else None, centres is not None)
            if B > 1:
                b_f_parts.append(b_f)
            n_centres += n_c
            face_parts.append(faces.to(id_dtype) if W + n_centres < 2**31 else faces)
            del faces, cell_of_face
    del cell_id, cases_a
    with torch.no_grad():
        faces = _cat_faces(face_parts, device)
    if B == 1 or not verts_c:
        verts, normals = _cat(verts_w + verts_c, args), _cat(normals_w + normals_c, args)
    else:  # volume b: its welded vertices, then its centres
        with torch.no_grad():
            c_excl = c_per.cumsum(0) - c_per
            new_w = torch.arange(W, device=device) + torch.repeat_interleave(c_excl, w_per)
            new_c = torch.arange(n_centres, device=device) + torch.repeat_interleave(
                w_incl, c_per)
        verts = _interleaved(verts_w, verts_c, new_w, new_c)
        normals = _interleaved(normals_w, normals_c, new_w, new_c)
    with torch.no_grad():
        if B == 1:
            counts = (torch.tensor([verts.shape[0]], device=device),
                      torch.tensor([faces.shape[0]], device=device))
        else:
            b_f = torch.cat(b_f_parts) if b_f_parts else torch.zeros(0, dtype=torch.long,
                                                                     device=device)
            counts = (w_per + c_per, torch.bincount(b_f, minlength=B))
    return verts, faces, normals, counts


def _packed_ids(faces, b_f, V_sub: int, v_lo: int, W: int, n_centres: int, c_per, w_incl,
                has_centres: bool) -> None:
    """Turn a slab's face ids (welded ``i < V_sub``, centres ``V_sub + k``) into packed
    ids, in place: welded ``v_lo + i``, centre ``W + n_centres + k`` (``W`` welded vertices
    in all, ``n_centres`` centres before the slab's). With a batch (``b_f (F_s,)`` the
    faces' volumes, ``c_per (B,)`` the centres per volume so far, ``w_incl (B,)`` the
    welded vertices in volumes ``<= b``), volume ``b``'s welded vertices follow the
    centres of the volumes before it, and its centres follow its welded vertices."""
    if b_f is not None and n_centres == 0 and not has_centres:
        b_f = None  # no centre so far: every volume's welded ids shift by v_lo alone
    c_excl = None if b_f is None else c_per.cumsum(0) - c_per  # centres in volumes < b
    is_c = faces >= V_sub if has_centres else None
    if b_f is None:
        faces += v_lo
    else:
        faces += (take(c_excl, b_f) + v_lo)[:, None]
    if is_c is None:
        return
    if b_f is None:
        faces[is_c] += W + n_centres - V_sub - v_lo
        return
    shift = take(w_incl, b_f) - take(c_excl, b_f) + (n_centres - V_sub - v_lo)
    faces += torch.where(is_c, shift[:, None], 0)


def _cat_faces(parts: list, device) -> torch.Tensor:
    """The slabs' faces (int32 or long) as one long ``(F, 3)`` tensor, emptying the list
    (each part converted straight into the result)."""
    faces = torch.empty(sum(p.shape[0] for p in parts), 3, dtype=torch.long, device=device)
    start = 0
    while parts:  # loop over slabs
        part = parts.pop(0)
        faces[start:start + part.shape[0]] = part
        start += part.shape[0]
    return faces


def _slab_mesh(vol, iso, cell_id, cases, n_own, layers, ambiguity, args, to_world, backend):
    """One slab's faces ``(F, 3)`` (welded ids local to the slab, centres from ``V``), their
    cells, its :class:`Centres` (or None) and its welded vertices and normals ``(V, 3)``.

    ``cell_id``/``cases`` are the slab's active cells followed by those of the next layer
    (whose vertices its faces use); the first ``n_own`` are the slab's own.
    """
    B, X, Y, Z = vol.shape
    own_id, own_case = cell_id[:n_own], cases[:n_own]
    welded = weld(cell_id, cases, (X, Y, Z), backend)
    rows, n_tri, tri_table, centre = cell_rows(vol, iso, None, own_id, own_case, ambiguity)
    has_centre = any_centre(rows, centre)
    faces, cell_of_face, centre_slot = triangulate(own_id, rows, n_tri, tri_table, welded.key,
                                                   (X, Y, Z), B, layers=layers, backend=backend,
                                                   centres=has_centre)
    centres = None
    if has_centre:
        centres = find_centres(own_id, rows, *centre, welded.key, cell_of_face, centre_slot,
                               faces, (X, Y, Z))
    b_sub = idiv(take(cell_id, welded.cell), X * Y * Z) if B > 1 else None
    verts, normals = interpolate(vol, welded, b_sub, args, to_world, backend)
    return faces, cell_of_face, centres, verts, normals


def _cat(parts: list, args) -> torch.Tensor:
    """``torch.cat`` of ``(n, 3)`` parts, emptying the list (an empty list: ``(0, 3)``)."""
    if not parts:
        return torch.zeros(0, 3, dtype=args.work, device=args.vol.device)
    out = torch.cat(parts)
    parts.clear()
    return out


def _interleaved(welded: list, centres: list, new_w, new_c) -> torch.Tensor:
    """The welded and centre rows placed at their packed ids ``new_w`` / ``new_c``."""
    w = torch.cat(welded)
    welded.clear()
    out = w.new_empty(new_w.shape[0] + new_c.shape[0], 3)
    out.index_copy_(0, new_w, w)
    del w
    out.index_copy_(0, new_c, torch.cat(centres))
    centres.clear()
    return out
