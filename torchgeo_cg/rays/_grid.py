"""Candidate search of the torch backend: a uniform grid walked by all rays in lock-step.

Structure: every face of every mesh is binned into each cell its bounding box, grown by
a margin ``delta``, overlaps (CSR, built with sort and bincount; cells keyed by
``(mesh, i, j, k)``, one grid shape shared by the meshes of a batch), so B meshes build
one structure with no Python loop over them.

Traversal (Amanatides and Woo 1987, "A fast voxel traversal algorithm"), vectorised:
each step, every active ray tests the faces of its current cell with the exact
watertight test (:mod:`~torchgeo_cg.rays._watertight`), then moves to the neighbouring
cell through which it leaves; the boundary parameters are recomputed from the cell
index each step (no accumulated error). A first-hit ray stops once its best hit lies
before the exit of the current cell: every face met earlier along the ray overlaps a
visited cell. The margin ``delta`` (``2**-30`` of the grid's extent, far above the
rounding of the cell arithmetic) keeps this exhaustive when a ray passes a cell corner
within rounding. Cells only *propose* faces; the test alone decides, so the hits do not
depend on the grid, and the best hit of a ray is the lexicographic minimum of
``(t, face)``: ties go to the smaller face index, whatever the order of the rays.

Convention:
    Inputs are float64, scaled by powers of two (corners into ``[-1, 1]``); rays are
    flat ``(n,)`` with ``item (n,)`` their mesh, ``t`` in units of the scaled direction.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.rays._watertight import ray_shear, watertight_test

__all__: list[str] = []

_MAX_DIMS = 256  # cells per axis at most


class RayGrid(NamedTuple):
    """Faces of ``B`` meshes binned into a uniform grid (CSR over ``B * cells`` keys)."""

    tri: torch.Tensor  # (B F, 3, 3) float64 corners, global face id b * F + f
    faces_per_mesh: int
    lo: torch.Tensor  # (3,) float64 lower corner
    h: float  # cell size
    dims: torch.Tensor  # (3,) long
    cells: int  # cells per mesh
    start: torch.Tensor  # (B cells,) long first entry of each cell
    count: torch.Tensor  # (B cells,) long faces per cell
    faces: torch.Tensor  # (M,) long global face ids grouped by cell


def build_grid(tri_bf33: torch.Tensor, cell_edges: float = 2.0) -> RayGrid:
    """The grid of ``tri (B, F, 3, 3)`` (float64, scaled), cells about ``cell_edges`` mean
    edge lengths wide (at most ``256`` per axis).

    Example:
        >>> g = build_grid(torch.eye(3, dtype=torch.float64)[None, None])
        >>> g.faces_per_mesh, int(g.count.sum()) >= 1
        (1, True)
    """
    B, F = tri_bf33.shape[:2]
    tri = tri_bf33.reshape(B * F, 3, 3)
    finite = torch.isfinite(tri).all(-1).all(-1)
    safe = torch.where(finite[:, None, None], tri, 0.0)
    fmin, fmax = safe.amin(1), safe.amax(1)
    lo, hi = fmin.amin(0), fmax.amax(0)
    extent = max(float((hi - lo).max()), 2.0**-40)
    delta = extent * 2.0**-30
    lo = lo - 2 * delta
    edge = float((safe - safe.roll(1, dims=1)).norm(dim=-1).mean())
    h = max(cell_edges * edge, extent / _MAX_DIMS, 2.0**-40)
    dims = ((hi + 2 * delta - lo) / h).floor().long().clamp_min(0) + 1
    c0 = ((fmin - delta - lo) / h).floor().long().clamp(min=torch.zeros_like(dims), max=dims - 1)
    c1 = ((fmax + delta - lo) / h).floor().long().clamp(min=torch.zeros_like(dims), max=dims - 1)
    m = torch.where(finite[:, None], c1 - c0 + 1, 0)  # (BF, 3) cells per axis
    per_face = m.prod(-1)
    face = torch.repeat_interleave(torch.arange(B * F, device=tri.device), per_face)
    k = torch.arange(face.numel(), device=tri.device) - (torch.cumsum(per_face, 0)
                                                         - per_face).repeat_interleave(per_face)
    mf = m.index_select(0, face)
    ijk = c0.index_select(0, face) + torch.stack(
        [k // (mf[:, 1] * mf[:, 2]), (k // mf[:, 2]) % mf[:, 1], k % mf[:, 2]], -1)
    cells = int(dims.prod())
    key = (face // F) * cells + (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = torch.argsort(key, stable=True)
    count = torch.bincount(key, minlength=B * cells)
    start = torch.cumsum(count, 0) - count
    return RayGrid(tri, F, lo, h, dims, cells, start, count, face.index_select(0, order))


def enter_grid(grid: RayGrid, o: torch.Tensor, d: torch.Tensor, t_lo: torch.Tensor,
           t_hi: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(t0, t1)``: the part of ``[t_lo, t_hi]`` inside the grid's box (slabs)."""
    lo = grid.lo
    hi = lo + grid.dims.to(lo.dtype) * grid.h
    zero = d == 0
    inside = (o >= lo) & (o <= hi)
    safe = torch.where(zero, 1.0, d)
    a, b = (lo - o) / safe, (hi - o) / safe
    near = torch.where(zero, torch.where(inside, -torch.inf, torch.inf), torch.minimum(a, b))
    far = torch.where(zero, torch.where(inside, torch.inf, -torch.inf), torch.maximum(a, b))
    return torch.maximum(near.amax(-1), t_lo), torch.minimum(far.amin(-1), t_hi)


def _cell_pairs(grid: RayGrid, key: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(row, face)``: the faces of cell ``key[row]`` for every row (CSR expansion)."""
    count = grid.count.index_select(0, key)
    row = torch.repeat_interleave(torch.arange(key.numel(), device=key.device), count)
    first = grid.start.index_select(0, key) - (torch.cumsum(count, 0) - count)
    pos = torch.arange(row.numel(), device=key.device) + first.index_select(0, row)
    return row, grid.faces.index_select(0, pos)


def walk(grid: RayGrid, o: torch.Tensor, d: torch.Tensor, item: torch.Tensor,
         t_lo: torch.Tensor, t_hi: torch.Tensor, first: bool):
    """Walk rays ``(o, d) (n, 3)`` of meshes ``item (n,)`` through the grid.

    Returns ``(t (n,), face (n,) global id or -1)`` of the first hit in ``[t_lo, t_hi]``
    when ``first``, else ``(ray, face)`` of every distinct hit (one pair per face).

    Example:
        >>> tri = torch.tensor([[[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]]], dtype=torch.float64)
        >>> g = build_grid(tri)
        >>> o = torch.tensor([[0.25, 0.25, 1.0]], dtype=torch.float64)
        >>> d = torch.tensor([[0.0, 0.0, -1.0]], dtype=torch.float64)
        >>> lo, hi = o.new_zeros(1), o.new_full((1,), torch.inf)
        >>> walk(g, o, d, torch.zeros(1, dtype=torch.long), lo, hi, True)
        (tensor([1.], dtype=torch.float64), tensor([0]))
    """
    n, dev = o.shape[0], o.device
    perm, shear = ray_shear(d)
    t0, t1 = enter_grid(grid, o, d, t_lo, t_hi)
    best_t = o.new_full((n,), torch.inf)
    best_f = torch.full((n,), -1, dtype=torch.long, device=dev)
    found_r, found_f = [], []
    act = (t0 <= t1).nonzero().squeeze(1)
    dims, lo, h = grid.dims, grid.lo, grid.h
    cell = ((o[act] + t0[act, None] * d[act] - lo) / h).floor().long()
    cell = cell.clamp(min=torch.zeros_like(dims), max=dims - 1)
    step = torch.sign(d).long()
    while act.numel():
        key = item[act] * grid.cells + (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
        row, face = _cell_pairs(grid, key)
        if row.numel():
            ray = act.index_select(0, row)
            hit, t = watertight_test(grid.tri.index_select(0, face), o.index_select(0, ray),
                                     perm.index_select(0, ray), shear.index_select(0, ray))
            ok = (hit & (t >= t_lo.index_select(0, ray)) & (t <= t_hi.index_select(0, ray))
                  ).nonzero().squeeze(1)
            ray, face, t = ray.index_select(0, ok), face.index_select(0, ok), t.index_select(0, ok)
            if first:
                _keep_best(best_t, best_f, ray, face, t)
            else:
                found_r.append(ray)
                found_f.append(face)
        oa, da = o.index_select(0, act), d.index_select(0, act)
        bound = lo + (cell + (da > 0).long()).to(lo.dtype) * h
        tb = torch.where(da == 0, torch.inf, (bound - oa) / torch.where(da == 0, 1.0, da))
        t_exit, axis = tb.min(-1)
        done = t_exit >= t1.index_select(0, act)
        if first:
            done |= best_t.index_select(0, act) <= t_exit
        move = step.index_select(0, act).gather(1, axis[:, None])
        cell = cell.scatter_add(1, axis[:, None], move)
        done |= ((cell < 0) | (cell >= dims)).any(-1)
        keep = (~done).nonzero().squeeze(1)
        act, cell = act.index_select(0, keep), cell.index_select(0, keep)
    if first:
        return best_t, best_f
    return _distinct(found_r, found_f, grid.tri.shape[0], dev)


def _keep_best(best_t, best_f, ray, face, t) -> None:
    """In place: ``(best_t, best_f)`` <- the lexicographic minimum with ``(t, face)``."""
    if ray.numel() == 0:
        return
    new_t = best_t.scatter_reduce(0, ray, t, "amin")
    tie = (t == new_t.index_select(0, ray)).nonzero().squeeze(1)
    big = torch.iinfo(torch.long).max
    cand = torch.full_like(best_f, big).scatter_reduce(
        0, ray.index_select(0, tie), face.index_select(0, tie), "amin")
    kept = torch.where(best_f < 0, big, best_f)
    merged = torch.where(new_t == best_t, torch.minimum(kept, cand), cand)
    best_f.copy_(torch.where(merged == big, best_f, merged))
    best_t.copy_(new_t)


def _distinct(rays: list, faces: list, num_faces: int, dev) -> tuple[torch.Tensor, torch.Tensor]:
    """Unique ``(ray, face)`` pairs (a face met in several cells counts once)."""
    if not rays:
        empty = torch.zeros(0, dtype=torch.long, device=dev)
        return empty, empty
    key = torch.unique(torch.cat(rays) * num_faces + torch.cat(faces))
    return key // num_faces, key % num_faces


def grid_hits(grid: RayGrid, o: torch.Tensor, d: torch.Tensor, item: torch.Tensor,
              t_lo: torch.Tensor, t_hi: torch.Tensor, first: bool, block: int = 1 << 16):
    """:func:`walk` in blocks of ``block`` rays (bounds the memory); crossings counted per
    ray when not ``first``: returns ``(t, face)`` or ``count (n,) long``.

    Example:
        >>> tri = torch.tensor([[[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]]], dtype=torch.float64)
        >>> o = torch.tensor([[0.25, 0.25, 1.0]], dtype=torch.float64)
        >>> d = torch.tensor([[0.0, 0.0, -1.0]], dtype=torch.float64)
        >>> grid_hits(build_grid(tri), o, d, torch.zeros(1, dtype=torch.long),
        ...           o.new_zeros(1), o.new_full((1,), torch.inf), False)
        tensor([1])
    """
    n = o.shape[0]
    if first:
        t = o.new_full((n,), torch.inf)
        f = torch.full((n,), -1, dtype=torch.long, device=o.device)
    else:
        count = torch.zeros(n, dtype=torch.long, device=o.device)
    for s in range(0, n, block):
        sl = slice(s, s + block)
        out = walk(grid, o[sl], d[sl], item[sl], t_lo[sl], t_hi[sl], first)
        if first:
            t[sl], f[sl] = out
        else:
            count[sl] = torch.bincount(out[0], minlength=min(block, n - s))
    return (t, f) if first else count
