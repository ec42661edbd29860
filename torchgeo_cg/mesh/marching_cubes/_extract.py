"""Marching cubes over a sparse set of blocks, welded by global edge keys.

The active blocks are processed in groups. Each group gathers the samples of its
blocks (``block + 1`` per side, so a block holds the samples of its far faces too),
evaluates every distinct sample once, and runs the steps of the dense path on the
batch of block volumes: :func:`~._steps.classify`, :func:`~._decider.cell_rows` (with a
mask that keeps the cells inside the grid), :func:`~._steps.triangulate`,
:func:`~._steps.find_centres`. A vertex is then named by its global key ``3 * (flat
sample index of the edge's lower end) + axis``, the key of the dense path, so the
vertices of a seam computed by two blocks are the same vertex, and sorting by key
gives the dense path's vertex order. Positions and normals come from
:func:`~._steps.place_vertices` on the global stencil of each vertex (the samples the
normals' central differences read beyond the blocks are evaluated as well), so they
equal the dense path's.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.mesh.marching_cubes._decider import cell_rows
from torchgeo_cg.mesh.marching_cubes._field import FieldEvaluator, Grid
from torchgeo_cg.mesh.marching_cubes._kernels import kernel_backend
from torchgeo_cg.mesh.marching_cubes._steps import (
    Centres,
    Welded,
    classify,
    find_centres,
    place_centres,
    place_vertices,
    sample_stencil,
    take,
    triangulate,
    weld,
)

__all__ = ["GroupMesh", "extract_group", "global_welded", "vertex_samples", "assemble"]


class GroupMesh(NamedTuple):
    """One group's part: ``keys (V,)`` sorted global vertex keys, ``verts``/``normals``
    ``(V, 3)`` (or None when they are recomputed with autograd), ``faces (F, 3)`` global
    keys (``-1 - cell`` for the centre vertex of ``cell``), ``centre_cells (C,)`` flat cell
    ids, ``centre_keys (C, 12)`` member keys (-1 unused), ``centre_weight (C, 12)``."""

    keys: torch.Tensor
    verts: torch.Tensor | None
    normals: torch.Tensor | None
    faces: torch.Tensor
    centre_cells: torch.Tensor
    centre_keys: torch.Tensor
    centre_weight: torch.Tensor


def _block_samples(blocks: torch.Tensor, grid: Grid, block: int):
    """``(unclipped (G, S^3, 3), flat (G * S^3,))`` indices of the blocks' samples."""
    s = torch.arange(block + 1, device=blocks.device)
    local = torch.stack(torch.meshgrid(s, s, s, indexing="ij"), -1).view(-1, 3)
    ijk = blocks[:, None, :] * block + local  # (G, S^3, 3)
    last = torch.tensor(grid.sizes, device=blocks.device) - 1
    flat = (torch.minimum(ijk, last) * grid.strides).sum(-1).view(-1)
    return ijk, flat


def global_welded(keys: torch.Tensor, grid: Grid) -> Welded:
    """The :class:`Welded` vertices of global keys (``cell`` is unused here)."""
    lower = keys // 3
    return Welded(lower, keys % 3, keys, lower, grid.unflatten(lower))


def vertex_samples(welded: Welded, grid: Grid, lookup):
    """``(samples (10, V), axes, steps)`` of the vertices' stencils; ``lookup`` maps
    flat sample ids ``(N,)`` to values ``(N,)``."""
    stencil, axes, steps = sample_stencil(welded, grid.sizes)
    return lookup(stencil.view(-1)).view(stencil.shape), axes, steps


def _lookup(evaluate: FieldEvaluator, grid: Grid, uid: torch.Tensor, uval: torch.Tensor):
    """Values of flat ids from the sorted ``uid``/``uval``, evaluating the others."""
    def get(ids: torch.Tensor) -> torch.Tensor:
        pos = torch.searchsorted(uid, ids).clamp_max(uid.shape[0] - 1)
        hit = take(uid, pos) == ids
        out = take(uval, pos)
        if not bool(hit.all()):
            extra = torch.unique(ids[~hit])
            vals = evaluate(grid, grid.unflatten(extra))
            out[~hit] = take(vals, torch.searchsorted(extra, ids[~hit]))
        return out
    return get


def _places(samples, welded, axes, steps, grid: Grid, iso, work):
    iso_v = iso.to(work).expand(samples.shape[1])
    origin, spacing = grid.origin.to(work), grid.spacing.to(work)
    return place_vertices(samples.to(work), iso_v, welded, axes, steps, spacing[None],
                          lambda index_pos: origin + spacing * index_pos)


def _global_flat(local: torch.Tensor, base: torch.Tensor, S: int, grid: Grid) -> torch.Tensor:
    """Global flat sample ids of local flat ids in the stacked ``(G * S, S, S)`` blocks."""
    ijk = torch.stack([(local // (S * S)) % S, (local // S) % S, local % S], dim=1)
    return ((take(base, local // S**3) + ijk) * grid.strides).sum(1)


def extract_group(evaluate: FieldEvaluator, grid: Grid, blocks: torch.Tensor, block: int,
                  iso: torch.Tensor, ambiguity: str, work, place: bool,
                  backend: str = "torch") -> GroupMesh:
    """Marching cubes on the blocks ``(G, 3)``; see the module docstring.

    ``place``: compute the positions and normals here (no autograd); ``backend``:
    ``"torch"`` or ``"warp"`` (classification, welding and faces as kernels).
    """
    S, G = block + 1, blocks.shape[0]
    ijk, flat = _block_samples(blocks, grid, block)
    uid, inverse = torch.unique(flat, return_inverse=True)
    uval = evaluate(grid, grid.unflatten(uid))
    vols = take(uval, inverse).view(G, S, S, S)
    del inverse, flat
    last = torch.tensor(grid.sizes, device=blocks.device) - 1
    inside_grid = (ijk <= last).all(-1).view(G, S, S, S)  # cells' far corners in the grid
    iso_b = iso.detach().to(vols.dtype).expand(G)
    backend = kernel_backend(backend, vols)
    cell_id, cases = classify(vols, iso_b, backend)
    welded = weld(cell_id, cases, (S, S, S), backend)
    rows, n_tri, tri_table, centre = cell_rows(vols, iso_b, inside_grid, cell_id, cases,
                                               ambiguity)
    faces, cell_of_face, centre_slot = triangulate(cell_id, rows, n_tri, tri_table,
                                                   welded.key, (S, S, S), G, backend=backend)
    centres = None
    if centre is not None:
        centres = find_centres(cell_id, rows, *centre, welded.key, cell_of_face, centre_slot,
                               faces, (S, S, S))
    base = blocks * block  # (G, 3) lower sample of each block
    vkey = _global_flat(welded.lower, base, S, grid) * 3 + welded.d  # (V_local,)
    gfaces = take(vkey, faces.view(-1).clamp_max(vkey.shape[0] - 1)).view(-1, 3)
    used_keys = torch.unique(gfaces[~centre_slot])
    c_cells, c_keys, c_weight = _group_centres(centres, centre, rows, cell_id, vkey, base, S,
                                               grid)
    if centres is not None:  # centre entries: -1 - (global cell id)
        number = (faces - vkey.shape[0]).clamp_min(0)
        gfaces = torch.where(centre_slot, -1 - take(c_cells, number.view(-1)).view(-1, 3),
                             gfaces)
    verts = normals = None
    if place:
        welded_g = global_welded(used_keys, grid)
        samples, axes, steps = vertex_samples(welded_g, grid, _lookup(evaluate, grid, uid, uval))
        verts, normals = _places(samples, welded_g, axes, steps, grid, iso.detach(), work)
    return GroupMesh(used_keys, verts, normals, gfaces, c_cells, c_keys, c_weight)


def _group_centres(centres: Centres | None, centre, rows, cell_id, vkey, base, S, grid):
    """``(cells (C,), member keys (C, 12), weights (C, 12))`` of the group's centres."""
    device = cell_id.device
    if centres is None:
        return (torch.zeros(0, dtype=torch.long, device=device),
                torch.zeros(0, 12, dtype=torch.long, device=device),
                torch.zeros(0, 12, dtype=torch.float64, device=device))
    centre_mask, decided = centre
    has = take(centre_mask, take(rows, decided)) != 0  # the cells find_centres numbered
    cells = _global_flat(take(cell_id, decided[has]), base, S, grid)
    keys = torch.where(centres.weight > 0, take(vkey, centres.members.view(-1)).view(-1, 12), -1)
    return cells, keys, centres.weight


def assemble(parts: list[GroupMesh], grid: Grid, work, lookup_grad=None, iso=None):
    """The welded mesh ``(verts, faces, normals)`` from the groups' parts.

    Vertices are sorted by global key (the dense path's order), then the centres by
    cell. With ``lookup_grad`` (flat ids -> values with autograd) the positions and
    normals are recomputed from those values.
    """
    device = grid.origin.device
    keys = torch.cat([p.keys for p in parts])
    uniq, inverse = torch.unique(keys, return_inverse=True)
    if lookup_grad is None:
        first = torch.full((uniq.shape[0],), keys.shape[0], dtype=torch.long, device=device)
        first.scatter_reduce_(0, inverse, torch.arange(keys.shape[0], device=device), "amin")
        verts = take(torch.cat([p.verts for p in parts]), first)
        normals = take(torch.cat([p.normals for p in parts]), first)
    else:
        welded = global_welded(uniq, grid)
        samples, axes, steps = vertex_samples(welded, grid, lookup_grad)
        verts, normals = _places(samples, welded, axes, steps, grid, iso, work)
    del keys, inverse
    c_cells = torch.cat([p.centre_cells for p in parts])
    order = torch.argsort(c_cells)
    c_sorted = take(c_cells, order)
    c_keys = take(torch.cat([p.centre_keys for p in parts]), order)
    c_weight = take(torch.cat([p.centre_weight for p in parts]), order)
    V = uniq.shape[0]
    faces = torch.empty(sum(p.faces.shape[0] for p in parts), 3, dtype=torch.long, device=device)
    start = 0
    while parts:  # loop over groups, freeing each part once it is mapped
        f = parts.pop(0).faces
        centre = f < 0
        idx = torch.searchsorted(uniq, f)
        if bool(centre.any()):
            idx[centre] = V + torch.searchsorted(c_sorted, -1 - f[centre])
        faces[start:start + f.shape[0]] = idx
        start += f.shape[0]
    if c_sorted.numel():
        members = torch.where(c_keys >= 0, torch.searchsorted(uniq, c_keys), 0)
        verts, normals = place_centres(verts, normals, Centres(members, c_weight, c_sorted))
    return verts, normals, faces
