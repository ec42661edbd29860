"""Closest-face search of the torch backend: exact, float64, CPU, batched over meshes.

The search answers one question per point: which face is closest. It is piecewise
constant (no gradient); :func:`~torchgeo_cg.sdf.mesh_distance.mesh_sdf` then evaluates
the exact distance on that face in torch, where gradients flow.

Algorithm (no Python loop over points, faces or batch items):

1. A KD-tree over face centroids (``scipy.spatial.cKDTree``, k = 1) gives every point a
   nearby face of its own mesh, hence an upper bound ``u`` on its distance. With several
   meshes the tree is 4-D, the mesh index times a separation larger than any distance
   being the 4th coordinate, so a point only ever meets its own mesh.
2. A pyramid of uniform grids (cell size doubling) bins each face once, in the cell of
   its bounding-box centre (CSR, built with sort and bincount; cells keyed by
   ``(mesh, i, j, k)``), so no face is scanned twice for a point. Each point scans the
   cells whose content box (the union of its faces' boxes) meets its ball of radius
   ``u``, among the cells its ball grown by the largest overhang of a face box out of
   its cell reaches, on the finest level where that spans at most 2 (else 4, else 8)
   cells per axis. A face is kept only if its bounding sphere, then its bounding disc in its
   plane, may hold a point within ``u``; the exact distance to the face of smallest
   bound tightens ``u``, and only the faces whose bound is within it get the exact
   point-triangle distance. No face that could be closer is skipped, so the search
   is exhaustive.

Convention:
    Inputs are ``tri (B, F, 3, 3)`` float64 corners and ``points (B, N, 3)`` float64,
    on the CPU, finite, already scaled by a power of two into a unit-sized box (see
    :func:`torchgeo_cg.core.numerics.power_of_two_scale` of the mesh): scaling by a power
    of two is exact, so the face chosen is the one of the unscaled problem, and squared
    distances cannot overflow.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import torch

from torchgeo_cg.sdf._triangle import face_table, gather_rows, pair_d2

__all__: list[str] = []


def far_radius(dtype: torch.dtype) -> float:
    """The radius beyond which a scaled point (mesh inside ``[-1, 1]``) is "far":
    ``1 / eps`` of ``dtype`` (2**52 in float64, 2**23 in float32). There the input's own
    rounding reaches the size of the mesh, so which feature is closest, and where on it,
    cannot be resolved any further; squared distances and the closest-point products stay
    far from overflow and underflow.

    Example:
        >>> far_radius(torch.float64) == 2.0**52, far_radius(torch.float32) == 2.0**23
        (True, True)
    """
    return 1.0 / torch.finfo(dtype).eps


def pull_in_far_points(points_bn3: torch.Tensor) -> torch.Tensor:
    """Scaled points with a coordinate beyond :func:`far_radius`, moved along their own
    direction to that radius (the others unchanged; no copy when none is far).

    Seen from so far, the closest feature of a mesh inside ``[-1, 1]`` is the same up to
    rounding, and squared distances to it can neither overflow nor drown the differences
    between faces; the distance itself is then measured from the original point.

    Example:
        >>> pull_in_far_points(torch.tensor([[[1e30, 0.0, 0.0], [1.0, 2.0, 3.0]]]))
        tensor([[[8.3886e+06, 0.0000e+00, 0.0000e+00],
                 [1.0000e+00, 2.0000e+00, 3.0000e+00]]])
    """
    radius = far_radius(points_bn3.dtype)
    top = points_bn3.detach().abs().amax(-1, keepdim=True)
    far = top > radius
    try:
        if not bool(far.any()):
            return points_bn3
    except RuntimeError:  # no data-dependent branch possible (vmap): always select
        pass
    return torch.where(far, points_bn3 * (radius / torch.where(far, top, 1.0)), points_bn3)


class FaceGrid(NamedTuple):
    """Faces binned into a uniform grid of cell size ``h`` (CSR), each face once, in the
    cell of its bounding-box centre; one block of ``cells`` per mesh: key
    ``b * cells + (i * Y + j) * Z + k``. A face's box sticks out of its cell by at most
    ``overhang`` on any side, so a ball meets a face's box only if the ball grown by
    ``overhang`` meets the face's cell."""

    lo: torch.Tensor  # (3,) float64
    h: float
    dims: torch.Tensor  # (3,) long
    cells: int  # cells per mesh
    overhang: float
    start: torch.Tensor  # (B cells + 1,) long, CSR row pointers
    count: torch.Tensor  # (B cells,) long, faces per cell
    faces: torch.Tensor  # (F,) long global face ids, grouped by cell
    box_lo: torch.Tensor  # (B cells, 3) tight box of the boxes of the cell's faces
    box_hi: torch.Tensor  # (B cells, 3)


def _face_grid(fmin: torch.Tensor, fmax: torch.Tensor, item: torch.Tensor, items: int,
               lo: torch.Tensor, h: float, dims: torch.Tensor) -> FaceGrid:
    """Bin every face once, into the cell of its box centre (sort and bincount, no loop):
    no face is ever scanned twice for one point, unlike binning into every cell a box
    overlaps."""
    cell = (((fmin + fmax) / 2 - lo) / h).floor().long().clamp(
        min=torch.zeros_like(dims), max=dims - 1)
    cmin = lo + cell.to(fmin.dtype) * h
    overhang = float(torch.maximum(cmin - fmin, fmax - (cmin + h)).clamp_min(0.0).max())
    cells = int(dims.prod())
    key = item * cells + (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = torch.argsort(key, stable=True)
    per_cell = torch.bincount(key, minlength=cells * items)
    start = torch.cat([per_cell.new_zeros(1), torch.cumsum(per_cell, 0)])
    empty = fmin.new_zeros(cells * items, 3)
    index = key[:, None].expand(-1, 3)
    box_lo = empty.scatter_reduce(0, index, fmin, "amin", include_self=False)
    box_hi = empty.scatter_reduce(0, index, fmax, "amax", include_self=False)
    return FaceGrid(lo, h, dims, cells, overhang, start, per_cell, order, box_lo, box_hi)


def _candidate_cells(grid: FaceGrid, p: torch.Tensor, item: torch.Tensor, u2: torch.Tensor,
                     m_max: int):
    """Cells (point row, cell key) whose content box meets each point's ball, for the
    points whose ball spans <= ``m_max`` cells per axis (mask ``ok``)."""
    lo, h, dims = grid.lo, grid.h, grid.dims
    u = u2.sqrt()[:, None] + grid.overhang
    zero = torch.zeros_like(dims)
    a = ((p - u - lo) / h).floor().long().clamp(min=zero, max=dims - 1)
    b = ((p + u - lo) / h).floor().long().clamp(min=zero, max=dims - 1)
    m = b - a + 1
    ok = (m <= m_max).all(1)
    rows_pt = ok.nonzero().squeeze(1)
    a, m, item = a.index_select(0, rows_pt), m.index_select(0, rows_pt), item[rows_pt]
    r = torch.arange(m_max)
    offs = torch.stack(torch.meshgrid(r, r, r, indexing="ij"), dim=-1).reshape(-1, 3)  # (S, 3)
    cell = torch.minimum(a[:, None] + offs[None], dims - 1)  # (n, S, 3)
    valid = (offs[None] < m[:, None]).all(-1)
    key = (item[:, None] * grid.cells
           + (cell[..., 0] * dims[1] + cell[..., 1]) * dims[2] + cell[..., 2]).view(-1)
    count = grid.count.index_select(0, key)
    flat = (valid.view(-1) & (count > 0)).nonzero().squeeze(1)
    pt = flat // offs.shape[0]
    key = key.index_select(0, flat)
    # keep the cells whose clipped face box meets the ball
    q = p.index_select(0, rows_pt).index_select(0, pt)
    gap = ((grid.box_lo.index_select(0, key) - q).clamp_min_(0.0)
           + (q - grid.box_hi.index_select(0, key)).clamp_min_(0.0))
    uu2 = u2.index_select(0, rows_pt)
    near = (torch.einsum("nk,nk->n", gap, gap) <= uu2.index_select(0, pt)).nonzero().squeeze(1)
    return ok, rows_pt, pt.index_select(0, near), key.index_select(0, near)


def _grid_search(grid: FaceGrid, table: torch.Tensor, p: torch.Tensor, item: torch.Tensor,
                 u2: torch.Tensor, best_f: torch.Tensor, m_max: int) -> torch.Tensor:
    """Refine ``u2, best_f`` in place for points whose ball spans <= ``m_max`` cells per axis.

    Every face within ``sqrt(u2)`` of a point overlaps a cell that meets the ball of
    that radius, so scanning those cells' faces is exhaustive. ``p`` is ``(n, 3)``.
    Returns the mask of points handled here.
    """
    ok, rows_pt, pt, key = _candidate_cells(grid, p, item, u2, m_max)
    if rows_pt.numel() == 0:
        return ok
    pp, uu2 = p.index_select(0, rows_pt), u2.index_select(0, rows_pt)
    first, count = grid.start.index_select(0, key), grid.count.index_select(0, key)
    pair_pt = torch.repeat_interleave(pt, count)
    offset = torch.repeat_interleave(first - (torch.cumsum(count, 0) - count), count)
    faces = grid.faces.index_select(0, torch.arange(pair_pt.numel()) + offset)
    # bounding-sphere test |p - c_f| <= u + r_f (cheap), then a tighter lower bound of
    # d(p, f)^2 from the face's disc (centre c_f, radius r_f, in the face's plane): with
    # w = p - c_f and n the unit normal, d^2 >= (w.n)^2 + max(0, |w - (w.n) n| - r_f)^2
    ppt = pp.t().contiguous()
    g = gather_rows(table, faces, range(20, 24))
    q = gather_rows(ppt, pair_pt, range(3))
    wx, wy, wz = q[0] - g[0], q[1] - g[1], q[2] - g[2]
    ww = wx * wx + wy * wy + wz * wz
    reach = uu2.sqrt().index_select(0, pair_pt).add_(g[3])  # u + r_f
    keep = (ww <= reach.square_()).nonzero().squeeze(1)
    pair_pt, faces = pair_pt.index_select(0, keep), faces.index_select(0, keep)
    wx, wy, wz, ww, r = (x.index_select(0, keep) for x in (wx, wy, wz, ww, g[3]))
    q = [c.index_select(0, keep) for c in q]
    n = gather_rows(table, faces, (9, 10, 11))
    h2 = (wx * n[0] + wy * n[1] + wz * n[2]).square_()
    lb = (ww - h2).clamp_min_(0.0).sqrt_().sub_(r).clamp_min_(0.0).square_().add_(h2)
    # rounding slack: the bound must never exceed the computed distance of the face
    lb.sub_(ww.add_(r.square()), alpha=1e-12)
    # the exact distance to the face of smallest bound of each point tightens u; then
    # only the faces whose bound is within the tightened u are evaluated
    lmin = uu2.new_full(uu2.shape, math.inf).scatter_reduce_(0, pair_pt, lb, reduce="amin")
    sel = lb <= lmin.index_select(0, pair_pt)
    one = sel.nonzero().squeeze(1)
    pt1, f1 = pair_pt.index_select(0, one), faces.index_select(0, one)
    d2_1 = pair_d2(table, torch.stack([c.index_select(0, one) for c in q]), f1)
    m2 = uu2.clone().scatter_reduce_(0, pt1, d2_1, reduce="amin")
    keep = ((lb <= m2.index_select(0, pair_pt)) & ~sel).nonzero().squeeze(1)
    pt2, f2 = pair_pt.index_select(0, keep), faces.index_select(0, keep)
    d2_2 = pair_d2(table, torch.stack([c.index_select(0, keep) for c in q]), f2)
    pair_pt, faces, d2 = torch.cat([pt1, pt2]), torch.cat([f1, f2]), torch.cat([d2_1, d2_2])
    m2.scatter_reduce_(0, pt2, d2_2, reduce="amin")
    win = d2 <= m2.index_select(0, pair_pt)
    bf = best_f[rows_pt]
    bf[pair_pt[win]] = faces[win]
    u2[rows_pt] = m2
    best_f[rows_pt] = bf
    return ok


class TorchSearch(NamedTuple):
    """The torch backend's search structure for ``B`` meshes of ``F`` faces each."""

    table: torch.Tensor  # (24, B F) face table, global face id b * F + f
    grids: list  # FaceGrid pyramid, finest first
    tree: object  # scipy cKDTree over the centroids (4-D with the mesh index when B > 1)
    separation: float  # 4th KD-tree coordinate per mesh index
    faces_per_mesh: int


def build_torch_search(tri_bf33: torch.Tensor) -> TorchSearch:
    """Face table, grid pyramid and centroid KD-tree for ``tri (B, F, 3, 3)`` (float64, CPU,
    scaled into ``[-1, 1]``).

    Example:
        >>> s = build_torch_search(torch.eye(3, dtype=torch.float64)[None, None])
        >>> s.faces_per_mesh, len(s.grids)
        (1, 1)
    """
    from scipy.spatial import cKDTree

    B, F = tri_bf33.shape[:2]
    tri = tri_bf33.reshape(B * F, 3, 3)
    table = face_table(tri)
    item = torch.arange(B).repeat_interleave(F)
    fmin, fmax = tri.amin(1), tri.amax(1)
    lo, hi = fmin.amin(0), fmax.amax(0)
    extent = float((hi - lo).max())
    edge = float((tri - tri.roll(1, dims=1)).norm(dim=-1).mean())
    h = max(2.5 * edge, extent / 128.0, 2.0**-40)
    grids = []
    while True:
        dims = ((hi - lo) / h).floor().long() + 1
        grids.append(_face_grid(fmin, fmax, item, B, lo, h, dims))
        if int(dims.max()) <= 2:
            break
        h *= 2.0
    centroids = table[20:23].t()
    separation = 0.0
    if B > 1:  # a point only meets its own mesh: other meshes are >= separation away
        separation = 1e8
        centroids = torch.cat([centroids, item[:, None].double() * separation], dim=1)
    return TorchSearch(table, grids, cKDTree(centroids.numpy()), separation, F)


def _search_block(search: TorchSearch, p: torch.Tensor, item: torch.Tensor) -> torch.Tensor:
    """Global closest face ids of a block of points ``p (n, 3)`` of meshes ``item (n,)``."""
    query = p if search.separation == 0 else torch.cat(
        [p, item[:, None].double() * search.separation], dim=1)
    workers = max(1, torch.get_num_threads())
    _, idx = search.tree.query(query.numpy(), k=1, workers=workers)
    bf = torch.from_numpy(np.asarray(idx, dtype=np.int64).reshape(-1))
    # a point farther than the separation may get another mesh's face: any face of its
    # own mesh is a valid (if loose) upper bound
    own = item * search.faces_per_mesh
    bf = torch.where(bf // search.faces_per_mesh == item, bf, own)
    u2 = pair_d2(search.table, p.t().contiguous(), bf)
    todo = torch.arange(p.shape[0])
    for grid in search.grids:
        for m_max in (2, 4, 8):
            if todo.numel() == 0:
                break
            sub_u2, sub_f = u2[todo], bf[todo]
            done = _grid_search(grid, search.table, p[todo], item[todo], sub_u2, sub_f, m_max)
            u2[todo], bf[todo] = sub_u2, sub_f
            todo = todo[~done]
    if todo.numel() > 0:  # pragma: no cover - the coarsest level spans <= 2 cells
        raise RuntimeError("mesh_sdf: internal search failed to resolve all points")
    return bf


def torch_closest_faces(search: TorchSearch, points_bn3: torch.Tensor, block: int = 1 << 13,
                        progress: bool = False) -> torch.Tensor:
    """Index of the exact closest face of every point, per mesh: ``(B, N)`` long.

    Args:
        search: :func:`build_torch_search` of the ``B`` meshes.
        points_bn3: ``(B, N, 3)`` float64 CPU points, finite, scaled like the meshes.
        block: points per step (bounds the memory).
        progress: show a tqdm progress bar over the blocks.

    Example:
        >>> tri = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]],
        ...                     [[0.0, 0, 1], [1, 0, 1], [0, 1, 1]]], dtype=torch.float64)
        >>> s = build_torch_search(tri[None])
        >>> torch_closest_faces(s, torch.tensor([[[0.1, 0.1, 0.9], [0.1, 0.1, -1.0]]],
        ...                                     dtype=torch.float64))
        tensor([[1, 0]])
    """
    from tqdm.auto import tqdm

    B, N = points_bn3.shape[:2]
    F = search.faces_per_mesh
    flat = points_bn3.reshape(B * N, 3)
    item = torch.arange(B).repeat_interleave(N)
    out = torch.empty(B * N, dtype=torch.long)
    for s in tqdm(range(0, B * N, block), disable=not progress, desc="mesh_sdf search",
                  unit="block"):
        out[s:s + block] = _search_block(search, flat[s:s + block], item[s:s + block])
    return (out - item * F).reshape(B, N)
