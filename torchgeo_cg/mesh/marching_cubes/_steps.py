"""The steps of :func:`torchgeo_cg.mesh.marching_cubes` (report section 1.4).

1. :func:`classify` every sample once (inside when ``f < iso``) and pack the eight
   corner bits of every cell into a case index, slab by slab along x;
2. :func:`weld` makes one vertex per crossing grid edge, keyed by (lower grid corner,
   direction), so neighbouring cells share the vertex of their common edge;
3. :func:`triangulate` looks each cell's triangles up in the generated table (row
   chosen by the case and, with ``ambiguity="asymptotic"``, the face and interior
   decisions of :mod:`torchgeo_cg.mesh.marching_cubes._decider`) and maps local
   edges to global vertex ids through a dense id map, one slab at a time;
4. :func:`interpolate` places the vertices, ``t = (iso - f1) / (f2 - f1)``, and
   computes the normals (the only differentiable step besides 5);
5. :func:`soft_weights` gives each face the probability of its cell configuration.

The batch is stacked along x, so one call costs one pass over all the volumes.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.grid import edge_fraction
from torchgeo_cg.core.numerics import power_of_two_scale
from torchgeo_cg.mesh.marching_cubes._kernels import (
    KERNEL_MAX_SAMPLES,
    classify_cells,
    face_lists,
    vertex_stencils,
    weld_edges,
)
from torchgeo_cg.mesh.marching_cubes._tables import CENTRE, corner_tables

__all__ = [
    "SLAB_CELLS",
    "MAP_CELLS",
    "take",
    "idiv",
    "imod",
    "classify",
    "Welded",
    "lower_crossings",
    "weld",
    "triangulate",
    "any_centre",
    "Centres",
    "find_centres",
    "place_centres",
    "sample_stencil",
    "interpolate",
    "place_vertices",
    "soft_weights",
]

#: Cells per slab (about): the volume is classified slab by slab along x, so every
#: intermediate stays small (cache-resident, no page faults on big fresh buffers).
SLAB_CELLS = 1 << 19
#: Cells per slab of the (cell, direction) -> vertex id map used to weld the faces.
MAP_CELLS = 1 << 17


def take(source: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``source[index]`` along dim 0 (``index_select``: much faster than advanced indexing)."""
    return torch.index_select(source, 0, index)


def idiv(x: torch.Tensor, d: int) -> torch.Tensor:
    """``x // d`` of non-negative integers; a shift when ``d`` is a power of two (integer
    division is an order of magnitude slower than a shift)."""
    return x >> (d.bit_length() - 1) if d & (d - 1) == 0 else x // d


def imod(x: torch.Tensor, d: int) -> torch.Tensor:
    """``x % d`` of non-negative integers; a mask when ``d`` is a power of two."""
    return x & (d - 1) if d & (d - 1) == 0 else x % d


def _nonzero_sparse(mask: torch.Tensor) -> torch.Tensor:
    """``mask.nonzero()`` for a sparse flat bool mask: scan 8 bytes at a time, then refine."""
    n8 = mask.shape[0] // 8 * 8
    words = mask[:n8].view(torch.int64).nonzero().squeeze(1)  # (W,) words with a True
    cand = (words[:, None] * 8 + torch.arange(8, device=mask.device)).view(-1)
    found = cand[take(mask, cand)]
    if n8 == mask.shape[0]:
        return found
    return torch.cat([found, n8 + mask[n8:].nonzero().squeeze(1)])


def _slab_cases(stacked, iso_layer, start, stop, X):
    """uint8 cases ``(L, Y, Z)`` of the padded cells of layers ``start..stop``."""
    layers, Y, Z = stacked.shape
    n_samples = min(stop + 1, layers) - start
    inside = torch.empty(stop + 1 - start, Y + 1, Z + 1, dtype=torch.bool, device=stacked.device)
    torch.lt(stacked[start:start + n_samples], iso_layer[start:start + n_samples],
             out=inside[:n_samples, :Y, :Z])
    inside[:n_samples, Y, :Z] = inside[:n_samples, Y - 1, :Z]
    inside[:n_samples, :, Z] = inside[:n_samples, :, Z - 1]
    if n_samples < inside.shape[0]:
        inside[n_samples] = inside[n_samples - 1]
    bits = inside.view(torch.uint8)
    case = bits[..., 1:] << 1
    case += bits[..., :-1]  # (L, Y+1, Z), bits dz
    case_yz = case[:, 1:] << 2
    case_yz += case[:, :-1]  # (L, Y, Z)
    case = case_yz[1:] << 4
    case += case_yz[:-1]  # (L-1, Y, Z) uint8
    # layers x = X-1 are padded cells: their dx = 1 corners replicate dx = 0 (and
    # must not reach into the next volume of the batch)
    first_pad = (X - 1 - start) % X
    if first_pad < stop - start:
        pad_layers = torch.arange(first_pad, stop - start, X, device=stacked.device)
        low = case[pad_layers] & 15  # (P, Y, Z)
        case[pad_layers] = low | (low << 4)
    return case


def classify(vol: torch.Tensor, iso_b: torch.Tensor, backend: str = "torch"):
    """Classify every sample and return the mixed cells of the padded cell grid.

    The batch is stacked along x, ``(B*X, Y, Z)``, and the cell grid is padded by
    one cell on the far side of each axis of each volume (samples replicated), so
    that every grid edge is the *lower* edge (from corner 0) of exactly one cell,
    and a cell's flat index equals the flat sample index of its corner 0. Padded
    cells own vertices but never make triangles.

    Args:
        vol: ``(B, X, Y, Z)`` contiguous samples (any float dtype: compared as they are).
        iso_b: ``(B,)`` levels (detached).
        backend: ``"torch"`` or ``"warp"`` (the kernel on the packed inside bits; the
            same result).

    Returns:
        ``(cell_id (A,), case (A,))`` long: ``cell_id`` is the flat index in
        ``(B*X, Y, Z)``, sorted; ``case`` has bit ``c`` set when corner
        ``c = 4*dx + 2*dy + dz`` is inside (``f < iso``).
    """
    B, X, Y, Z = vol.shape
    layers = B * X
    if backend == "warp" and vol.numel() <= KERNEL_MAX_SAMPLES:
        return classify_cells(vol.view(layers, Y, Z), iso_b.contiguous(), X)
    slab = max(1, SLAB_CELLS // (Y * Z))  # cell layers (along the stacked x) per slab
    stacked = vol.view(layers, Y, Z)
    iso_layer = iso_b.repeat_interleave(X).view(layers, 1, 1)  # (B*X, 1, 1)
    ids, cases = [], []
    for start in range(0, layers, slab):  # loop over slabs of cell layers, not over cells
        stop = min(start + slab, layers)
        case = _slab_cases(stacked, iso_layer, start, stop, X).view(-1)
        case -= 1  # 0 and 255 become 255 and 254
        active = _nonzero_sparse(case < 254)
        ids.append(active + start * (Y * Z))
        cases.append(take(case, active).long() + 1)
    return torch.cat(ids), torch.cat(cases)


class Welded(NamedTuple):
    """One vertex per crossing grid edge: ``lower (V,)`` flat sample at its lower end,
    ``d (V,)`` its axis, ``key (V,)`` sorted ``3 * lower + d``, ``cell (V,)`` the active
    cell owning it, ``corner_ijk (V, 3)`` its lower grid corner."""

    lower: torch.Tensor
    d: torch.Tensor
    key: torch.Tensor
    cell: torch.Tensor
    corner_ijk: torch.Tensor


def lower_crossings(device) -> torch.Tensor:
    """``(256, 3)`` bool: does a case's lower x / y / z edge (corner 0 against corners 4,
    2, 1) cross, i.e. own a vertex?"""
    case_ids = torch.arange(256, device=device)
    bit0 = case_ids & 1
    return torch.stack([bit0 != ((case_ids >> 4) & 1), bit0 != ((case_ids >> 2) & 1),
                        bit0 != ((case_ids >> 1) & 1)], dim=1)


def weld(cell_id: torch.Tensor, cases: torch.Tensor, sizes, backend: str = "torch") -> Welded:
    """Vertices of the crossing lower edges (corner 0 against corners 4, 2, 1) of the cells.

    Args:
        cell_id, cases: ``(A,)`` from :func:`classify`.
        sizes: ``(X, Y, Z)``.
        backend: ``"torch"`` or ``"warp"`` (the kernel; the same result).
    """
    X, Y, Z = sizes
    if backend == "warp":
        return Welded(*weld_edges(cell_id, cases, sizes))
    vert_cell, d_v = take(lower_crossings(cases.device), cases).nonzero().unbind(1)
    # sorted by (cell, d)
    lower = take(cell_id, vert_cell)
    ijk = torch.stack([imod(idiv(lower, Y * Z), X), imod(idiv(lower, Z), Y), imod(lower, Z)],
                      dim=1)
    return Welded(lower, d_v, lower * 3 + d_v, vert_cell, ijk)


def triangulate(cell_id, rows, n_tri, tri_table, vert_key, sizes, batch: int,
                layers: tuple[int, int] | None = None, backend: str = "torch",
                centres: bool = True):
    """Faces of the active cells: table rows -> local edges -> welded vertex ids.

    Local edge ``e`` of cell ``c`` is the lower edge (direction ``edge_dir[e]``) of the
    cell ``c + edge_off[e]``, i.e. has the key ``3 * c + key_delta[e]``.

    Args:
        cell_id: ``(A,)`` sorted flat cell ids.
        rows: ``(A,)`` table rows.
        n_tri: ``(A,)`` triangles per cell (0 for cells that make none).
        tri_table: ``(R, T, 3)`` local edge triples, ``-1`` padded.
        vert_key: ``(V,)`` sorted vertex keys (:class:`Welded`).
        sizes: ``(X, Y, Z)``; batch: ``B``.
        layers: ``(first, stop)`` stacked cell layers holding every cell of ``cell_id``
            (default: all ``B * X``); ``vert_key`` then holds the vertices of those
            layers and of layer ``stop``, and the ids are indices into it.
        backend: ``"torch"`` or ``"warp"`` (the kernel: each face's vertex ids found
            from cursors moving along the vertex rows; the same result).
        centres: whether a cell may have a centre vertex (:func:`any_centre`); False
            skips finding the centre entries.

    Returns:
        ``(faces (F, 3) long, cell_of_face (F,), centre_slot (F, 3) bool or None)``:
        ``centre_slot`` flags the entries of the centre vertex (edge 12), which are 0,
        left for :func:`find_centres` to fill (None when ``centres`` is False).
    """
    X, Y, Z = sizes
    if backend == "warp":
        return face_lists(cell_id, rows, n_tri, tri_table, vert_key, sizes,
                          (0, batch * X) if layers is None else layers, centres)
    YZ = Y * Z
    device = cell_id.device
    edge_dir, edge_off = corner_tables(device)[:2]
    strides = torch.tensor([YZ, Z, 1], device=device)
    key_delta = (edge_off * strides).sum(-1) * 3 + edge_dir  # (12,)
    key_delta = torch.cat([key_delta, key_delta.new_zeros(1)])  # the centre: fixed later
    tri_delta = torch.where(tri_table >= 0, key_delta[tri_table.clamp_min(0)], -1)
    tri_delta = tri_delta.view(-1, 3)  # (R * T, 3)
    cell_of_face = torch.repeat_interleave(n_tri)  # (F,) sorted
    first_face = n_tri.cumsum(0).sub_(n_tri)  # (A,)
    slot = torch.arange(cell_of_face.shape[0], device=device) - take(first_face, cell_of_face)
    tri_row = take(rows, cell_of_face) * tri_table.shape[1] + slot  # (F,)
    face_cell3 = take(cell_id, cell_of_face) * 3  # (F,) sorted
    faces = torch.empty(face_cell3.shape[0], 3, dtype=torch.long, device=device)
    map_slab = max(1, MAP_CELLS // YZ)
    first, stop = (0, batch * X) if layers is None else layers
    layer_bounds = torch.arange(first, stop + map_slab, map_slab, device=device)
    layer_bounds = layer_bounds.clamp_max(stop) * (3 * YZ)  # key bounds of the slabs
    face_bounds = torch.searchsorted(face_cell3, layer_bounds).tolist()
    vert_lo = torch.searchsorted(vert_key, layer_bounds).tolist()
    vert_hi = torch.searchsorted(
        vert_key, (layer_bounds + 3 * YZ).clamp_max(3 * batch * X * YZ)).tolist()
    id_dtype = torch.int32 if vert_key.shape[0] < 2**31 else torch.long
    id_map = torch.empty((map_slab + 1) * YZ * 3, dtype=id_dtype, device=device)
    for n in range(len(layer_bounds) - 1):  # loop over slabs, not over cells
        f0, f1 = face_bounds[n], face_bounds[n + 1]
        if f0 == f1:
            continue
        v0, v1 = vert_lo[n], vert_hi[n + 1]  # vertices of the slab and one more layer
        base = (first + n * map_slab) * YZ * 3
        id_map[vert_key[v0:v1] - base] = torch.arange(v0, v1, dtype=id_dtype, device=device)
        face_key = take(tri_delta, tri_row[f0:f1]).add_((face_cell3[f0:f1] - base)[:, None])
        faces[f0:f1] = take(id_map, face_key.view(-1)).view(-1, 3)
    if not centres:
        return faces, cell_of_face, None
    centre_slot = take(tri_table.view(-1, 3), tri_row) == CENTRE  # (F, 3)
    faces[centre_slot] = 0  # filled by find_centres
    return faces, cell_of_face, centre_slot


def any_centre(rows: torch.Tensor, centre) -> bool:
    """Whether a decided cell's table row has a centre vertex (``centre``: the
    ``(centre_mask, decided)`` of :func:`~._decider.cell_rows`, None for none)."""
    if centre is None:
        return False
    centre_mask, decided = centre
    return bool((take(centre_mask, take(rows, decided)) != 0).any())


class Centres(NamedTuple):
    """Cell-centre vertices: ``members (C, 12)`` long vertex ids of the edges each
    averages (0 where ``weight`` is 0), ``weight (C, 12)`` 1 / count or 0, ``b (C,)``
    volume of each."""

    members: torch.Tensor
    weight: torch.Tensor
    b: torch.Tensor


def find_centres(cell_id, rows, centre_mask, decided, vert_key, cell_of_face, tri_slots, faces,
                 sizes):
    """Give the centre entries of ``faces`` their vertex ids (after the welded ones).

    Args:
        cell_id, rows: ``(A,)`` per active cell.
        centre_mask: ``(R,)`` edge mask of each table row's centre (0: none).
        decided: ``(N,)`` sorted indices of the cells that took decisions (only they
            can have a centre).
        vert_key: ``(V,)`` sorted welded vertex keys.
        cell_of_face: ``(F,)``; tri_slots: ``(F, 3)`` bool, entries that are the centre.
        faces: ``(F, 3)``, updated in place.
        sizes: ``(X, Y, Z)``.

    Returns:
        :class:`Centres`, or None when no cell has one.
    """
    X, Y, Z = sizes
    mask_d = take(centre_mask, take(rows, decided))  # (N,)
    has = mask_d != 0
    if not bool(has.any()):
        return None
    device = cell_id.device
    centre_cells = decided[has]  # (C,) sorted active-cell indices
    slot_faces = tri_slots.any(1).nonzero().squeeze(1)
    number = torch.searchsorted(centre_cells, take(cell_of_face, slot_faces))  # (S,)
    sub = faces[slot_faces]
    sub[tri_slots[slot_faces]] = (vert_key.shape[0] + number)[:, None].expand_as(sub)[
        tri_slots[slot_faces]]
    faces[slot_faces] = sub
    mask_c = mask_d[has]
    bits = (mask_c[:, None] >> torch.arange(12, device=device)) & 1  # (C, 12)
    edge_dir, edge_off = corner_tables(device)[:2]
    strides = torch.tensor([Y * Z, Z, 1], device=device)
    key_delta = (edge_off * strides).sum(-1) * 3 + edge_dir  # (12,)
    cells = take(cell_id, centre_cells)
    keys = cells[:, None] * 3 + key_delta  # (C, 12)
    members = torch.searchsorted(vert_key, keys).clamp_max(vert_key.shape[0] - 1)
    # 1 / count in float64 (correctly rounded in every working dtype; a long / long
    # division would give float32 weights for float64 volumes)
    weight = bits.double() / bits.sum(1, keepdim=True).double()
    return Centres(members * bits, weight, idiv(cells, X * Y * Z))


def place_centres(verts, normals, centres: Centres):
    """Positions (mean of the members) and unit normals (of the members' sum) of the centres.

    Returns:
        ``(verts (V + C, 3), normals (V + C, 3))``.
    """
    w = centres.weight.to(verts.dtype)[..., None]  # (C, 12, 1)
    pos = (verts[centres.members] * w).sum(1)
    nrm = (normals[centres.members] * w).sum(1)
    big = nrm.abs().amax(dim=1, keepdim=True)
    nonzero = big > 0
    nrm = nrm / torch.where(nonzero, big, torch.ones_like(big))
    length = torch.linalg.vector_norm(nrm, dim=1, keepdim=True)
    nrm = nrm / torch.where(nonzero, length, torch.ones_like(length))
    return torch.cat([verts, pos]), torch.cat([normals, nrm])


def sample_stencil(welded: Welded, sizes):
    """Flat sample indices needed per vertex, gathered in one go (one backward scatter).

    Returns:
        ``(index (10, V), axes [2 x (V,)], steps (2, V))``: rows 0-1 of ``index`` are the
        edge ends; rows ``2 + 4 s .. 5 + 4 s`` are (lower + up, lower - down,
        upper + up, upper - down) along the ``s``-th axis across the edge, ``axes``;
        ``steps`` is the index distance covered by those differences (2, or 1 on the border).
    """
    X, Y, Z = sizes
    lower, d_v, corner_ijk = welded.lower, welded.d, welded.corner_ijk
    device = lower.device
    last = torch.tensor([X - 1, Y - 1, Z - 1], device=device)
    stride_t = torch.tensor([Y * Z, Z, 1], device=device)
    upper = lower + take(stride_t, d_v)
    index = torch.empty(10, lower.shape[0], dtype=torch.long, device=device)
    index[0], index[1] = lower, upper
    axes, steps = [], []
    for s, shift in enumerate((1, 2)):  # the two axes across the edge
        a = take(torch.tensor([shift, (1 + shift) % 3, (2 + shift) % 3], device=device),
                 d_v)  # (V,) (d + shift) % 3
        c = corner_ijk.gather(1, a[:, None]).squeeze(1)
        up = (c < take(last, a)).long()
        down = (c > 0).long()
        stride = take(stride_t, a)
        step_up, step_down = up * stride, down * stride
        torch.add(lower, step_up, out=index[2 + 4 * s])
        torch.sub(lower, step_down, out=index[3 + 4 * s])
        torch.add(upper, step_up, out=index[4 + 4 * s])
        torch.sub(upper, step_down, out=index[5 + 4 * s])
        axes.append(a)
        steps.append(up + down)
    return index, axes, torch.stack(steps)


#: ``_ROTATE[d, c]``: the column of ``(along d, across (d + 1) % 3, across (d + 2) % 3)``
#: that holds world axis ``c`` for an edge along axis ``d``.
_ROTATE = ((0, 1, 2), (2, 0, 1), (1, 2, 0))


def _unit_normals(samples, t, d_v, steps, spacing_v):
    """Unit field gradient at the vertices ``(V, 3)``, in world units, zero where it is zero.

    Along the edge the slope of the interpolant ``(f2 - f1) / spacing_d``; across it
    (axes ``(d + 1) % 3`` and ``(d + 2) % 3``, the stencil's order), central differences
    (one-sided on the border) at both edge ends, blended with ``t``; both across axes at
    once, then one gather puts the three components on their world axes. The gradient
    is divided by its largest component before normalising, so neither tiny nor huge
    gradients under- or overflow. Without a graph to record the steps run in place
    (fewer fresh buffers), with the same operations on the same operands, so the same bits.
    """
    if records_graph(samples, t):
        return _unit_normals_graph(samples, t, d_v, steps, spacing_v)
    across = samples[2:].view(2, 4, -1)  # (axis, [lower +- step, upper +- step], V)
    parts = samples.new_empty(3, samples.shape[1])  # d, d + 1, d + 2
    torch.sub(samples[1], samples[0], out=parts[0])
    g = torch.sub(across[:, 2], across[:, 3], out=parts[1:])  # g_upper
    g_lower = across[:, 0] - across[:, 1]
    g.sub_(g_lower).mul_(t).add_(g_lower).div_(steps)  # g_lower + t (g_upper - g_lower)
    rotate = torch.tensor(_ROTATE, device=d_v.device)
    grad = parts.T.gather(1, take(rotate, d_v))
    if not bool((spacing_v == 1).all()):  # relative spacings: often all one
        grad.div_(spacing_v)
    big = grad.abs().amax(dim=1, keepdim=True)  # (an inf-norm is many times slower)
    grad.div_(big.masked_fill_(big == 0, 1.0))  # components in [-1, 1]
    length = torch.linalg.vector_norm(grad, dim=1, keepdim=True)  # >= 1 where nonzero
    return grad.div_(length.clamp_min_(1.0))  # zero gradients: 0 / 1


def _unit_normals_graph(samples, t, d_v, steps, spacing_v):
    """:func:`_unit_normals` out of place, for autograd to record."""
    across = samples[2:].view(2, 4, -1)
    g_lower = across[:, 0] - across[:, 1]
    g_upper = across[:, 2] - across[:, 3]
    g = (g_lower + t * (g_upper - g_lower)) / steps.to(samples.dtype)  # (2, V)
    parts = torch.cat([(samples[1] - samples[0])[None], g]).T  # (V, 3): d, d + 1, d + 2
    rotate = torch.tensor(_ROTATE, device=d_v.device)
    grad = parts.gather(1, take(rotate, d_v)) / spacing_v
    big = grad.abs().amax(dim=1, keepdim=True)
    nonzero = big > 0
    scaled = grad / torch.where(nonzero, big, 1.0)  # components in [-1, 1]
    length = torch.linalg.vector_norm(scaled, dim=1, keepdim=True)  # >= 1 where nonzero
    return scaled / torch.where(nonzero, length, 1.0)


def _keep_in_range(samples: torch.Tensor, iso_v: torch.Tensor):
    """The stencil samples and ``iso`` of a vertex whose values are so large that their
    differences could overflow (beyond a quarter of the dtype's largest value) are divided
    by a power of two (exact), which changes neither ``t`` nor the normal's direction. One
    ``aminmax`` pass checks for it. The decision is per vertex, so a vertex's result never
    depends on the other vertices extracted with it (a slab or a block gives the one-go
    bits), and small samples elsewhere are never scaled down into subnormals.

    Args:
        samples: ``(10, V)`` the stencil samples of each vertex; iso_v: ``(V,)``.

    Returns:
        ``(samples, iso_v)``, rescaled only where needed.
    """
    if samples.numel() == 0:
        return samples, iso_v
    limit = torch.finfo(samples.dtype).max / 4
    low, high = torch.aminmax(samples.detach())
    _, iso_high = torch.aminmax(iso_v.detach().abs())
    if max(-float(low), float(high), float(iso_high)) <= limit:
        return samples, iso_v
    top = torch.maximum(samples.detach().abs().amax(0), iso_v.detach().abs())  # (V,)
    scale = torch.where(top > limit, power_of_two_scale(top), torch.ones_like(top))  # (V,)
    return samples / scale, iso_v / scale


def interpolate(vol, welded: Welded, b_v, args, to_world, backend: str = "torch"):
    """Vertex positions and unit normals, in ``args.work`` precision.

    Args:
        vol: ``(B, X, Y, Z)`` samples (differentiable).
        welded: the vertices (:func:`weld`).
        b_v: ``(V,)`` volume of each vertex, or None for one volume.
        args: the parsed arguments (``iso``, ``spacing``, ``work``).
        to_world: ``(index_pos (V, 3), b_v) -> (V, 3)`` world positions.
        backend: ``"torch"`` or ``"warp"`` (the samples' indices from a kernel; the
            same integers).

    Returns:
        ``(verts (V, 3), normals (V, 3))``.
    """
    sizes = vol.shape[1:]
    if backend == "warp":
        stencil, axes, steps = vertex_stencils(welded.lower, welded.d, welded.corner_ijk,
                                               sizes)
    else:
        stencil, axes, steps = sample_stencil(welded, sizes)
    flat = vol.reshape(-1)
    samples = take(flat, stencil.view(-1)).view(stencil.shape).to(args.work)  # (10, V)
    iso_v = args.iso.expand(samples.shape[1]) if b_v is None else take(args.iso, b_v)
    spacing_v = (args.spacing[:1] if b_v is None or args.shared_frame
                 else take(args.spacing, b_v))  # (1, 3) broadcasts when shared
    return place_vertices(samples, iso_v, welded, axes, steps, spacing_v,
                          lambda index_pos: to_world(index_pos, b_v))


def place_vertices(samples, iso_v, welded: Welded, axes, steps, spacing_v, to_world):
    """Positions and unit normals from the stencil samples of :func:`sample_stencil`.

    Args:
        samples: ``(10, V)`` stencil samples in the working dtype; iso_v: ``(V,)``.
        welded, axes, steps: the vertices and their stencil (``axes`` is not read: the
            kernel's stencil gives None).
        spacing_v: ``(V, 3)`` or ``(1, 3)`` grid spacing.
        to_world: ``index_pos (V, 3) -> (V, 3)`` world positions.

    Returns:
        ``(verts (V, 3), normals (V, 3))``.
    """
    samples, iso_v = _keep_in_range(samples, iso_v)
    delta = math.sqrt(torch.finfo(samples.dtype).eps)
    t = edge_fraction(samples[0], samples[1], iso_v, delta)  # (V,)
    index_pos = welded.corner_ijk.to(samples.dtype).scatter_add(  # (V, 3) index space
        1, welded.d[:, None], t[:, None])
    verts = to_world(index_pos)
    # normals depend on the ratios of the spacings only: relative spacings in (0, 1]
    # keep the world gradient from overflowing at a tiny spacing
    relative_v = spacing_v / spacing_v.amax(-1, keepdim=True)
    normals = _unit_normals(samples, t, welded.d, steps, relative_v)
    return verts, normals


def soft_weights(vol, cell_id, cases, cell_of_face, args) -> torch.Tensor:
    """``(F,)`` probability of each face's cell configuration under independent corners.

    Each corner is inside with probability ``p = sigmoid((iso - f) / tau)`` (Liao et al.
    2018, Deep Marching Cubes); a face gets ``prod p^inside (1 - p)^outside`` of its cell.
    """
    device = vol.device
    X, Y, Z = vol.shape[1:]
    corner_off = corner_tables(device)[2]
    strides = torch.tensor([Y * Z, Z, 1], device=device)
    cells, face_to_cell = torch.unique_consecutive(cell_of_face, return_inverse=True)
    corner_delta = (corner_off * strides).sum(-1)  # (8,)
    flat = vol.reshape(-1)
    f_corners = take(flat, (take(cell_id, cells)[:, None] + corner_delta).view(-1))
    f_corners = f_corners.view(-1, 8).to(args.work)  # (C, 8)
    inside_bits = (take(cases, cells)[:, None] >> torch.arange(8, device=device)) & 1
    sign = (2 * inside_bits - 1).to(args.work)  # (C, 8): +1 inside, -1 outside
    b_c = idiv(take(cell_id, cells), X * Y * Z)
    # halves first: iso - f cannot overflow near the top of the float range (a quotient
    # beyond it is +-inf, which logsigmoid saturates correctly)
    half_gap = take(args.iso, b_c)[:, None] * 0.5 - f_corners * 0.5
    logits = sign * (half_gap / take(args.tau, b_c)[:, None]) * 2
    cell_weight = torch.nn.functional.logsigmoid(logits).sum(-1).exp()  # (C,)
    return take(cell_weight, face_to_cell)
