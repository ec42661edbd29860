"""The Warp kernels of marching cubes: cube cases, welded vertices and face lists.

Kernels decide, torch differentiates: these return integers only (active cells and
their cases, the crossing lower edges, the faces' vertex ids), each exactly what the
torch steps of ``_steps`` return, so positions, normals, gradients and the soft weights
are computed from them by the same torch code. Every step is count, prefix sum (torch),
write: one thread per row of cells (classification) or per active cell, each writing
its own contiguous range, so the order is the torch order and no atomic decides it.

The kernels read ``float32`` and ``float64`` samples; other dtypes stay on the torch path.
"""

from types import SimpleNamespace
from typing import Any

import torch

from torchgeo_cg.engine import launch, register_kernels, to_warp

__all__ = ["KERNEL_DTYPES", "classify_cells", "weld_edges", "face_lists"]

#: Sample dtypes the kernels read.
KERNEL_DTYPES = (torch.float32, torch.float64)


def _build(wp):
    @wp.func
    def column_bits(vol: wp.array(dtype=Any), iso: Any, r00: int, r01: int, r10: int,
                    r11: int, k: int):
        # inside bits of the four samples (dx, dy) at z = k, at bit 4 dx + 2 dy
        bits = wp.int32(0)
        if vol[r00 + k] < iso:
            bits = bits | 1
        if vol[r01 + k] < iso:
            bits = bits | 4
        if vol[r10 + k] < iso:
            bits = bits | 16
        if vol[r11 + k] < iso:
            bits = bits | 64
        return bits

    @wp.kernel
    def classify_rows(vol: wp.array(dtype=Any), iso: wp.array(dtype=Any), X: int, Y: int,
                      Z: int, write: int, first: wp.array(dtype=wp.int64),
                      count: wp.array(dtype=wp.int64), cell_id: wp.array(dtype=wp.int64),
                      cases: wp.array(dtype=wp.int64)):
        # one row (l, j) of cells along z of the stacked (B*X, Y, Z) samples: count its
        # mixed cells, or write them
        r = wp.tid()
        layer = r // Y
        j0 = r - layer * Y
        b = layer // X
        l1 = layer + 1
        if layer - b * X == X - 1:  # padded cell: its dx = 1 corners replicate dx = 0
            l1 = layer
        j1 = wp.min(j0 + 1, Y - 1)
        r00 = (layer * Y + j0) * Z
        r01 = (layer * Y + j1) * Z
        r10 = (l1 * Y + j0) * Z
        r11 = (l1 * Y + j1) * Z
        level = iso[b]
        lo = column_bits(vol, level, r00, r01, r10, r11, 0)
        n = wp.int64(0)
        base = wp.int64(0)
        if write != 0:
            base = first[r]
        row_start = wp.int64(r00)
        for k in range(Z):
            hi = column_bits(vol, level, r00, r01, r10, r11, wp.min(k + 1, Z - 1))
            case = lo | (hi << 1)
            if case != 0 and case != 255:
                if write != 0:
                    cell_id[base + n] = row_start + wp.int64(k)
                    cases[base + n] = wp.int64(case)
                n += wp.int64(1)
            lo = hi
        if write == 0:
            count[r] = n

    @wp.func
    def lower_count(case: wp.int64):
        bit0 = case & wp.int64(1)
        n = wp.int32(0)
        if bit0 != ((case >> wp.int64(4)) & wp.int64(1)):
            n += 1
        if bit0 != ((case >> wp.int64(2)) & wp.int64(1)):
            n += 1
        if bit0 != ((case >> wp.int64(1)) & wp.int64(1)):
            n += 1
        return n

    @wp.kernel
    def count_edges(cases: wp.array(dtype=wp.int64), count: wp.array(dtype=wp.int64)):
        a = wp.tid()
        count[a] = wp.int64(lower_count(cases[a]))

    @wp.func
    def write_edge(c: wp.int64, axis: wp.int64, a: wp.int64, v: wp.int64, X: wp.int64,
                   Y: wp.int64, Z: wp.int64, lower: wp.array(dtype=wp.int64),
                   d: wp.array(dtype=wp.int64), key: wp.array(dtype=wp.int64),
                   cell: wp.array(dtype=wp.int64), ijk: wp.array2d(dtype=wp.int64)):
        lower[v] = c
        d[v] = axis
        key[v] = c * wp.int64(3) + axis
        cell[v] = a
        ijk[v, 0] = (c // (Y * Z)) % X
        ijk[v, 1] = (c // Z) % Y
        ijk[v, 2] = c % Z

    @wp.kernel
    def weld_cells(cell_id: wp.array(dtype=wp.int64), cases: wp.array(dtype=wp.int64),
                   first: wp.array(dtype=wp.int64), X: wp.int64, Y: wp.int64, Z: wp.int64,
                   lower: wp.array(dtype=wp.int64), d: wp.array(dtype=wp.int64),
                   key: wp.array(dtype=wp.int64), cell: wp.array(dtype=wp.int64),
                   ijk: wp.array2d(dtype=wp.int64)):
        # the crossing lower edges (x, y, z: corner 0 against 4, 2, 1) of one active cell
        a = wp.tid()
        case = cases[a]
        c = cell_id[a]
        v = first[a]
        aa = wp.int64(a)
        bit0 = case & wp.int64(1)
        if bit0 != ((case >> wp.int64(4)) & wp.int64(1)):
            write_edge(c, wp.int64(0), aa, v, X, Y, Z, lower, d, key, cell, ijk)
            v = v + wp.int64(1)
        if bit0 != ((case >> wp.int64(2)) & wp.int64(1)):
            write_edge(c, wp.int64(1), aa, v, X, Y, Z, lower, d, key, cell, ijk)
            v = v + wp.int64(1)
        if bit0 != ((case >> wp.int64(1)) & wp.int64(1)):
            write_edge(c, wp.int64(2), aa, v, X, Y, Z, lower, d, key, cell, ijk)

    @wp.func
    def lower_bound(keys: wp.array(dtype=wp.int64), value: wp.int64):
        lo = wp.int32(0)
        hi = keys.shape[0]
        while lo < hi:
            mid = (lo + hi) // 2
            if keys[mid] < value:
                lo = mid + 1
            else:
                hi = mid
        return wp.int64(lo)

    @wp.kernel
    def faces_of_cells(cell_id: wp.array(dtype=wp.int64), rows: wp.array(dtype=wp.int64),
                       n_tri: wp.array(dtype=wp.int64), first: wp.array(dtype=wp.int64),
                       tri_delta: wp.array2d(dtype=wp.int64), T: wp.int64,
                       vert_key: wp.array(dtype=wp.int64), faces: wp.array2d(dtype=wp.int64),
                       cell_of_face: wp.array(dtype=wp.int64),
                       tri_row: wp.array(dtype=wp.int64)):
        # the triangles of one active cell, local edges mapped to welded vertex ids
        a = wp.tid()
        c3 = cell_id[a] * wp.int64(3)
        for s in range(int(n_tri[a])):
            f = first[a] + wp.int64(s)
            row = rows[a] * T + wp.int64(s)
            faces[f, 0] = lower_bound(vert_key, c3 + tri_delta[int(row), 0])
            faces[f, 1] = lower_bound(vert_key, c3 + tri_delta[int(row), 1])
            faces[f, 2] = lower_bound(vert_key, c3 + tri_delta[int(row), 2])
            cell_of_face[f] = wp.int64(a)
            tri_row[f] = row

    for T in (wp.float32, wp.float64):
        wp.overload(classify_rows, {"vol": wp.array(dtype=T), "iso": wp.array(dtype=T)})
    return SimpleNamespace(classify_rows=classify_rows, count_edges=count_edges,
                           weld_cells=weld_cells, faces_of_cells=faces_of_cells)


_kernels = register_kernels(_build)


def _exclusive(count: torch.Tensor) -> tuple[torch.Tensor, int]:
    """``(first (N,), total)``: the exclusive prefix sum of ``count`` and its sum."""
    inclusive = count.cumsum(0)
    total = int(inclusive[-1]) if count.shape[0] else 0
    return inclusive - count, total


def classify_cells(stacked: torch.Tensor, iso_b: torch.Tensor, X: int):
    """``(cell_id (A,), case (A,))`` long of the mixed cells of the padded cell grid of
    ``stacked (B*X, Y, Z)`` (``iso_b (B,)`` of its dtype), as ``_steps.classify``."""
    k = _kernels()
    layers, Y, Z = stacked.shape
    device = stacked.device
    rows = layers * Y
    count = torch.empty(rows, dtype=torch.long, device=device)
    empty = torch.empty(0, dtype=torch.long, device=device)
    vol_w, iso_w = to_warp(stacked.reshape(-1)), to_warp(iso_b)
    launch(k.classify_rows, rows, [vol_w, iso_w, X, Y, Z, 0, to_warp(empty), to_warp(count),
                                   to_warp(empty), to_warp(empty)], device)
    first, total = _exclusive(count)
    cell_id = torch.empty(total, dtype=torch.long, device=device)
    cases = torch.empty(total, dtype=torch.long, device=device)
    if total:
        launch(k.classify_rows, rows, [vol_w, iso_w, X, Y, Z, 1, to_warp(first), to_warp(count),
                                       to_warp(cell_id), to_warp(cases)], device)
    return cell_id, cases


def weld_edges(cell_id: torch.Tensor, cases: torch.Tensor, sizes):
    """``(lower, d, key, cell, corner_ijk)`` of the crossing lower edges of the active
    cells, sorted by ``(cell, d)``, as ``_steps.weld``."""
    k = _kernels()
    X, Y, Z = sizes
    device = cell_id.device
    count = torch.empty_like(cases)
    launch(k.count_edges, cases.shape[0], [to_warp(cases), to_warp(count)], device)
    first, total = _exclusive(count)
    out = [torch.empty(total, dtype=torch.long, device=device) for _ in range(4)]
    ijk = torch.empty(total, 3, dtype=torch.long, device=device)
    launch(k.weld_cells, cell_id.shape[0],
           [to_warp(cell_id), to_warp(cases), to_warp(first), X, Y, Z,
            *(to_warp(o) for o in out), to_warp(ijk)], device)
    return (*out, ijk)


def face_lists(cell_id, rows, n_tri, tri_delta, T: int, vert_key):
    """``(faces (F, 3), cell_of_face (F,), tri_row (F,))`` long, as ``_steps.triangulate``
    (the entries of centre vertices are left undefined: the caller fills them)."""
    k = _kernels()
    device = cell_id.device
    rows, n_tri = rows.long(), n_tri.long()
    first, total = _exclusive(n_tri)
    faces = torch.empty(total, 3, dtype=torch.long, device=device)
    cell_of_face = torch.empty(total, dtype=torch.long, device=device)
    tri_row = torch.empty(total, dtype=torch.long, device=device)
    launch(k.faces_of_cells, cell_id.shape[0],
           [to_warp(cell_id), to_warp(rows), to_warp(n_tri), to_warp(first),
            to_warp(tri_delta), T, to_warp(vert_key), to_warp(faces), to_warp(cell_of_face),
            to_warp(tri_row)], device)
    return faces, cell_of_face, tri_row
