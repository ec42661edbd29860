"""The Warp kernels of marching cubes: cube cases, welded vertices and face lists.

Kernels decide, torch differentiates: these return integers only (active cells and
their cases, the crossing lower edges, the faces' vertex ids), each exactly what the
torch steps of ``_steps`` return, so positions, normals, gradients and the soft weights
are computed from them by the same torch code. Every step is count, prefix sum (torch),
write: one thread per row of cells (a few dozen rows on the CPU), each writing
its own contiguous range, so the order is the torch order and no atomic decides it.

The samples are compared with ``iso`` by torch (the same ``torch.lt`` as the torch path,
any float dtype) and packed 64 to a word; the kernels read those bits. Volumes of
``2**31`` samples or more stay on the torch path (Warp indexes arrays with 32-bit
integers).
"""

from types import SimpleNamespace

import torch

from torchgeo_cg.engine import launch, load_warp, register_kernels, to_warp
from torchgeo_cg.mesh.marching_cubes._tables import corner_tables

__all__ = ["KERNEL_MAX_SAMPLES", "kernel_backend", "classify_cells", "weld_edges",
           "face_lists", "vertex_stencils"]

#: Samples of a volume the kernels take at most.
KERNEL_MAX_SAMPLES = 2**31 - 1


def kernel_backend(backend: str, samples: torch.Tensor) -> str:
    """``backend`` (resolved: ``"torch"`` or ``"warp"``), or ``"torch"`` where a kernel
    cannot read ``samples``' memory (a wrapper of a ``torch.func`` transform has none)."""
    if backend != "warp":
        return backend
    try:
        samples.data_ptr()
    except RuntimeError:
        return "torch"
    return backend


def _build(wp):
    @wp.func
    def shifted(bits: wp.array(dtype=wp.uint64), row: int, w: int, W: int, Z: int):
        # the inside bits of samples k + 1 at bit k (the last sample replicated)
        word = bits[row * W + w] >> wp.uint64(1)
        if w + 1 < W:
            word = word | (bits[row * W + w + 1] << wp.uint64(63))
        else:
            last = wp.uint64((Z - 1) - w * 64)
            word = word | (((bits[row * W + w] >> last) & wp.uint64(1)) << last)
        return word

    @wp.func
    def popcount(x: wp.uint64):
        # the number of set bits (SWAR: pairs, nibbles, bytes, then one multiply)
        x = x - ((x >> wp.uint64(1)) & wp.uint64(0x5555555555555555))
        x = (x & wp.uint64(0x3333333333333333)) + ((x >> wp.uint64(2))
                                                   & wp.uint64(0x3333333333333333))
        x = (x + (x >> wp.uint64(4))) & wp.uint64(0x0F0F0F0F0F0F0F0F)
        return int((x * wp.uint64(0x0101010101010101)) >> wp.uint64(56))

    @wp.func
    def classify_row(bits: wp.array(dtype=wp.uint64), r: int, X: int, Y: int, Z: int, W: int,
                     write: int, first: wp.array(dtype=wp.int64),
                     count: wp.array(dtype=wp.int64), cell_id: wp.array(dtype=wp.int64),
                     cases: wp.array(dtype=wp.int64)):
        # one row (l, j) of cells along z: its mixed cells (not all eight corners of one
        # class), 64 at a time from the packed bits; count them, or write them in order
        layer = r // Y
        j0 = r - layer * Y
        l1 = layer + 1
        if layer - (layer // X) * X == X - 1:  # padded cell: dx = 1 corners replicate dx = 0
            l1 = layer
        j1 = wp.min(j0 + 1, Y - 1)
        r00 = layer * Y + j0
        r01 = layer * Y + j1
        r10 = l1 * Y + j0
        r11 = l1 * Y + j1
        n = wp.int64(0)
        base = wp.int64(0)
        if write != 0:
            base = first[r]
        for w in range(W):
            c0 = bits[r00 * W + w]
            c2 = bits[r01 * W + w]
            c4 = bits[r10 * W + w]
            c6 = bits[r11 * W + w]
            c1 = shifted(bits, r00, w, W, Z)
            c3 = shifted(bits, r01, w, W, Z)
            c5 = shifted(bits, r10, w, W, Z)
            c7 = shifted(bits, r11, w, W, Z)
            any_in = c0 | c1 | c2 | c3 | c4 | c5 | c6 | c7
            all_in = c0 & c1 & c2 & c3 & c4 & c5 & c6 & c7
            mixed = any_in & (all_in ^ wp.uint64(0xFFFFFFFFFFFFFFFF))
            if Z - w * 64 < 64:
                mixed = mixed & ((wp.uint64(1) << wp.uint64(Z - w * 64)) - wp.uint64(1))
            if write == 0:  # counting: the set bits, no loop
                n += wp.int64(popcount(mixed))
                mixed = wp.uint64(0)
            while mixed != wp.uint64(0):  # the set bits, lowest first
                low = mixed & (wp.uint64(0) - mixed)
                u = wp.uint64(popcount(low - wp.uint64(1)))
                mixed = mixed ^ low
                one = wp.uint64(1)
                case = (((c0 >> u) & one) | (((c1 >> u) & one) << wp.uint64(1))
                        | (((c2 >> u) & one) << wp.uint64(2))
                        | (((c3 >> u) & one) << wp.uint64(3))
                        | (((c4 >> u) & one) << wp.uint64(4))
                        | (((c5 >> u) & one) << wp.uint64(5))
                        | (((c6 >> u) & one) << wp.uint64(6))
                        | (((c7 >> u) & one) << wp.uint64(7)))
                cell_id[base + n] = wp.int64(r) * wp.int64(Z) + wp.int64(w * 64) + wp.int64(u)
                cases[base + n] = wp.int64(case)
                n += wp.int64(1)
        if write == 0:
            count[r] = n
        return 0

    @wp.kernel
    def classify_rows(bits: wp.array(dtype=wp.uint64), X: int, Y: int, Z: int, W: int,
                      write: int, first: wp.array(dtype=wp.int64),
                      count: wp.array(dtype=wp.int64), cell_id: wp.array(dtype=wp.int64),
                      cases: wp.array(dtype=wp.int64), G: int, rows: int):
        # rows t G .. t G + G - 1 (a few rows a thread: a CPU thread costs more than a row)
        t = wp.tid()
        for r in range(t * G, wp.min(t * G + G, rows)):
            classify_row(bits, r, X, Y, Z, W, write, first, count, cell_id, cases)

    @wp.func
    def crosses(case: wp.int64, corner: wp.int64):
        # 1 when the lower edge from corner 0 to ``corner`` (4, 2, 1: x, y, z) crosses
        return (case & wp.int64(1)) ^ ((case >> corner) & wp.int64(1))

    @wp.kernel
    def weld_rows(cell_id: wp.array(dtype=wp.int64), cases: wp.array(dtype=wp.int64),
                  first: wp.array(dtype=wp.int64), row_cell: wp.array(dtype=wp.int64),
                  row_lo: wp.int64, X: wp.int64, Y: wp.int64, Z: wp.int64,
                  lower: wp.array(dtype=wp.int64), d: wp.array(dtype=wp.int64),
                  key: wp.array(dtype=wp.int64), cell: wp.array(dtype=wp.int64),
                  ijk: wp.array2d(dtype=wp.int64)):
        # the crossing lower edges (x, y, z: corner 0 against 4, 2, 1) of the active cells
        # of one row (l, j) of cells, in (cell, axis) order (the row's i, j computed once)
        rr = wp.tid()
        r = row_lo + wp.int64(rr)
        i = (r // Y) % X
        j = r % Y
        for a in range(int(row_cell[rr]), int(row_cell[rr + 1])):
            case = cases[a]
            c = cell_id[a]
            k = c - r * Z
            nx = crosses(case, wp.int64(4))
            ny = crosses(case, wp.int64(2))
            nz = crosses(case, wp.int64(1))
            for axis in range(3):
                on = nx
                at = first[a]
                if axis == 1:
                    on = ny
                    at = first[a] + nx
                if axis == 2:
                    on = nz
                    at = first[a] + nx + ny
                if on != wp.int64(0):
                    lower[at] = c
                    d[at] = wp.int64(axis)
                    key[at] = c * wp.int64(3) + wp.int64(axis)
                    cell[at] = wp.int64(a)
                    ijk[at, 0] = i
                    ijk[at, 1] = j
                    ijk[at, 2] = k

    @wp.func
    def advance(vert_key: wp.array(dtype=wp.int64), p: wp.int64, end: wp.int64,
                want: wp.int64):
        # the first vertex at or after p (and before end) whose key is not below want
        q = p
        while q < end and vert_key[int(q)] < want:
            q = q + wp.int64(1)
        return q

    @wp.func
    def faces_of_row(cell_id: wp.array(dtype=wp.int64), rows: wp.array(dtype=wp.int64),
                     n_tri: wp.array(dtype=wp.int64), first: wp.array(dtype=wp.int64),
                     row_cell: wp.array(dtype=wp.int64), code: wp.array(dtype=wp.int32),
                     T: wp.int64, Y: wp.int64, Z: wp.int64, row_vert: wp.array(dtype=wp.int64),
                     vert_key: wp.array(dtype=wp.int64), faces: wp.array(dtype=wp.int64),
                     cell_of_face: wp.array(dtype=wp.int64), centre: wp.array(dtype=wp.uint8),
                     rr: int):
        # the triangles of the active cells of row rr (cell row (l, j)), in order: the
        # code of local edge e is 8 q + off, its vertex in row q = 2 dx + dy (4: the cell
        # centre, written 0 and flagged) with the key 3 (that row's first sample + k) + off;
        # one cursor per such row moves forward with the cells (keys grow along a row)
        p00 = row_vert[rr]
        p01 = row_vert[rr + 1]
        p10 = row_vert[rr + int(Y)]
        p11 = row_vert[rr + int(Y) + 1]
        e00 = row_vert[rr + 1]
        e01 = row_vert[rr + 2]
        e10 = row_vert[rr + int(Y) + 1]
        e11 = row_vert[rr + int(Y) + 2]
        flag = centre.shape[0] > 0
        for a in range(int(row_cell[rr]), int(row_cell[rr + 1])):
            b00 = cell_id[a] * wp.int64(3)
            b01 = b00 + wp.int64(3) * Z
            b10 = b00 + wp.int64(3) * Y * Z
            b11 = b10 + wp.int64(3) * Z
            p00 = advance(vert_key, p00, e00, b00)
            p01 = advance(vert_key, p01, e01, b01)
            p10 = advance(vert_key, p10, e10, b10)
            p11 = advance(vert_key, p11, e11, b11)
            f0 = first[a]
            c0 = int(rows[a] * T * wp.int64(3))
            for s in range(int(n_tri[a])):
                f = f0 + wp.int64(s)
                for m in range(3):
                    e = code[c0 + 3 * s + int(m)]
                    q = e >> 3
                    off = wp.int64(e & 7)
                    found = wp.int64(0)  # a centre (q = 4): filled by the caller
                    if q == 0:
                        found = advance(vert_key, p00, e00, b00 + off)
                    elif q == 1:
                        found = advance(vert_key, p01, e01, b01 + off)
                    elif q == 2:
                        found = advance(vert_key, p10, e10, b10 + off)
                    elif q == 3:
                        found = advance(vert_key, p11, e11, b11 + off)
                    faces[f * wp.int64(3) + wp.int64(m)] = found
                    if flag:
                        centre[f * wp.int64(3) + wp.int64(m)] = wp.where(q == 4, wp.uint8(1),
                                                                         wp.uint8(0))
                cell_of_face[f] = wp.int64(a)
        return 0

    @wp.kernel
    def faces_of_rows(cell_id: wp.array(dtype=wp.int64), rows: wp.array(dtype=wp.int64),
                      n_tri: wp.array(dtype=wp.int64), first: wp.array(dtype=wp.int64),
                      row_cell: wp.array(dtype=wp.int64), code: wp.array(dtype=wp.int32),
                      T: wp.int64, Y: wp.int64, Z: wp.int64,
                      row_vert: wp.array(dtype=wp.int64), vert_key: wp.array(dtype=wp.int64),
                      faces: wp.array(dtype=wp.int64), cell_of_face: wp.array(dtype=wp.int64),
                      centre: wp.array(dtype=wp.uint8), G: int, n_rows: int):
        # rows t G .. t G + G - 1 (a few rows a thread on the CPU)
        t = wp.tid()
        for rr in range(t * G, wp.min(t * G + G, n_rows)):
            faces_of_row(cell_id, rows, n_tri, first, row_cell, code, T, Y, Z, row_vert, vert_key,
                         faces, cell_of_face, centre, rr)

    @wp.kernel
    def stencils(lower: wp.array(dtype=wp.int64), d: wp.array(dtype=wp.int64),
                 ijk: wp.array2d(dtype=wp.int64), G: int, X: wp.int64, Y: wp.int64,
                 Z: wp.int64, index: wp.array2d(dtype=wp.int32),
                 steps: wp.array2d(dtype=wp.int32)):
        # the ten samples each vertex reads: its edge's ends, and for the two axes across
        # the edge the differences at both ends (central, one-sided on the border)
        t = wp.tid()
        for v in range(t * G, wp.min(t * G + G, lower.shape[0])):
            lo = lower[v]
            dv = d[v]
            up_end = lo + wp.where(dv == wp.int64(0), Y * Z, wp.where(dv == wp.int64(1), Z,
                                                                        wp.int64(1)))
            index[0, v] = wp.int32(lo)
            index[1, v] = wp.int32(up_end)
            for s in range(2):
                a = (dv + wp.int64(1 + s)) % wp.int64(3)
                c = ijk[v, int(a)]
                last = wp.where(a == wp.int64(0), X, wp.where(a == wp.int64(1), Y, Z))
                stride = wp.where(a == wp.int64(0), Y * Z, wp.where(a == wp.int64(1), Z,
                                                                     wp.int64(1)))
                up = wp.where(c < last - wp.int64(1), wp.int64(1), wp.int64(0))
                down = wp.where(c > wp.int64(0), wp.int64(1), wp.int64(0))
                index[2 + 4 * s, v] = wp.int32(lo + up * stride)
                index[3 + 4 * s, v] = wp.int32(lo - down * stride)
                index[4 + 4 * s, v] = wp.int32(up_end + up * stride)
                index[5 + 4 * s, v] = wp.int32(up_end - down * stride)
                steps[s, v] = wp.int32(up + down)

    return SimpleNamespace(classify_rows=classify_rows,
                           weld_rows=weld_rows,
                           faces_of_rows=faces_of_rows, stencils=stencils)


_kernels = register_kernels(_build)


def _rows_per_thread(device: torch.device) -> int:
    """Rows of cells one thread takes: one on CUDA; on the CPU (where Warp runs each
    thread as a call that copies the kernel's arguments) a few dozen."""
    return 1 if device.type == "cuda" else 32


def _exclusive(count: torch.Tensor) -> tuple[torch.Tensor, int]:
    """``(first (N,), total)``: the exclusive prefix sum of ``count`` and its sum."""
    inclusive = count.cumsum(0)
    total = int(inclusive[-1]) if count.shape[0] else 0
    return inclusive - count, total


#: Samples per slab of the inside test (its buffers stay small).
_SLAB_SAMPLES = 1 << 19
#: Multiplying eight 0/1 bytes (little-endian int64) by this puts byte ``i`` at bit
#: ``56 + i`` of the product: eight inside flags packed into one byte.
_PACK8 = 0x0102040810204080


def _packed_inside(stacked: torch.Tensor, iso_b: torch.Tensor, X: int, W: int) -> torch.Tensor:
    """``(B*X*Y * W,)`` int64 words: bit ``t`` of word ``w`` of row ``(l, j)`` is set when
    sample ``(l, j, 64 w + t)`` is inside (``f < iso``), slab by slab (torch compares
    and packs 64 flags to a word in a few vectorised operations)."""
    layers, Y, Z = stacked.shape
    iso_layer = iso_b.repeat_interleave(X).view(layers, 1, 1)
    bits = torch.empty(layers * Y, W, dtype=torch.int64, device=stacked.device)
    bytes_out = bits.view(torch.uint8).view(layers * Y, W * 8)
    slab = max(1, _SLAB_SAMPLES // (Y * W * 64))
    # one flag buffer for every slab; its padding (past Z) stays False
    flag_buf = torch.zeros(min(slab, layers), Y, W * 64, dtype=torch.bool, device=stacked.device)
    for l0 in range(0, layers, slab):  # loop over slabs of layers, not over samples
        l1 = min(layers, l0 + slab)
        inside = flag_buf[:l1 - l0]
        torch.lt(stacked[l0:l1], iso_layer[l0:l1], out=inside[..., :Z])
        flags = inside.view(torch.uint8).view(-1, 8).view(torch.int64)  # 8 flags a value
        # packed in place (the next slab's comparison rewrites the flags; the padding,
        # all zero, stays zero); the copy keeps the low byte of each value
        packed = flags.mul_(_PACK8).bitwise_right_shift_(56)
        bytes_out[l0 * Y:l1 * Y] = packed.view(-1, W * 8)
    return bits.view(-1)


def classify_cells(stacked: torch.Tensor, iso_b: torch.Tensor, X: int):
    """``(cell_id (A,), case (A,))`` long of the mixed cells of the padded cell grid of
    ``stacked (B*X, Y, Z)`` (levels ``iso_b (B,)``), as ``_steps.classify``."""
    k = _kernels()
    layers, Y, Z = stacked.shape
    device = stacked.device
    rows, W = layers * Y, (Z + 63) // 64
    bits = _packed_inside(stacked, iso_b, X, W)
    bits_w = to_warp(bits, dtype=load_warp().uint64)
    count = torch.empty(rows, dtype=torch.long, device=device)
    empty = torch.empty(0, dtype=torch.long, device=device)
    G = _rows_per_thread(device)
    launch(k.classify_rows, (rows + G - 1) // G,
           [bits_w, X, Y, Z, W, 0, to_warp(empty), to_warp(count), to_warp(empty),
            to_warp(empty), G, rows], device)
    first, total = _exclusive(count)
    cell_id = torch.empty(total, dtype=torch.long, device=device)
    cases = torch.empty(total, dtype=torch.long, device=device)
    if total:
        launch(k.classify_rows, (rows + G - 1) // G,
               [bits_w, X, Y, Z, W, 1, to_warp(first), to_warp(count), to_warp(cell_id),
                to_warp(cases), G, rows], device)
    return cell_id, cases


def _row_ranges(ids: torch.Tensor, per_row: int, row_lo: int, n_rows: int) -> torch.Tensor:
    """``(n_rows + 1,)``: entry ``i`` counts the sorted ``ids`` of rows before ``row_lo + i``
    (``per_row`` ids a row), i.e. where row ``row_lo + i`` starts in ``ids``."""
    row = ids // per_row if per_row & (per_row - 1) else ids >> (per_row.bit_length() - 1)
    bucket = (row - (row_lo - 1)).clamp_(0, n_rows + 1)  # 0: rows before row_lo
    return torch.bincount(bucket, minlength=n_rows + 2).cumsum(0)[:n_rows + 1]


def weld_edges(cell_id: torch.Tensor, cases: torch.Tensor, sizes):
    """``(lower, d, key, cell, corner_ijk)`` of the crossing lower edges of the active
    cells, sorted by ``(cell, d)``, as ``_steps.weld``."""
    k = _kernels()
    X, Y, Z = sizes
    device = cell_id.device
    every = torch.arange(256, device=device)
    flips = every ^ ((every & 1) * 0b10110)  # bits 4, 2, 1 set where they differ from bit 0
    per_case = ((flips >> 4) & 1) + ((flips >> 2) & 1) + ((flips >> 1) & 1)  # (256,)
    count = torch.index_select(per_case, 0, cases)  # crossing lower edges per cell
    first, total = _exclusive(count)
    out = [torch.empty(total, dtype=torch.long, device=device) for _ in range(4)]
    ijk = torch.empty(total, 3, dtype=torch.long, device=device)
    if cell_id.shape[0]:
        row_lo = int(cell_id[0]) // Z
        n_rows = int(cell_id[-1]) // Z + 1 - row_lo
        launch(k.weld_rows, n_rows,
               [to_warp(cell_id), to_warp(cases), to_warp(first),
                to_warp(_row_ranges(cell_id, Z, row_lo, n_rows)), row_lo, X, Y, Z,
                *(to_warp(o) for o in out), to_warp(ijk)], device)
    return (*out, ijk)


#: Edge codes of the triangle tables, by table (see :func:`_edge_codes`).
_CODES: dict[tuple, torch.Tensor] = {}


def _edge_codes(tri_table: torch.Tensor) -> torch.Tensor:
    """``(R * T * 3,)`` int32: for each local edge of the table, ``8 q + off``: the row
    ``q = 2 dx + dy`` holding its vertex (4 for the centre, edge 12) and its key within
    that row's cell ``k``, ``off = 3 dz + d`` (cached per table)."""
    key = (tri_table.data_ptr(), tuple(tri_table.shape), tri_table.device)
    if key not in _CODES:
        edge_dir, edge_off = corner_tables(tri_table.device)[:2]
        per_edge = (edge_off[:, 0] * 2 + edge_off[:, 1]) * 8 + edge_off[:, 2] * 3 + edge_dir
        per_edge = torch.cat([per_edge, per_edge.new_tensor([4 * 8])])  # (13,)
        _CODES[key] = per_edge[tri_table.clamp_min(0)].to(torch.int32).reshape(-1)
    return _CODES[key]


def face_lists(cell_id, rows, n_tri, tri_table, vert_key, sizes, layers, centres: bool = True):
    """``(faces (F, 3), cell_of_face (F,))`` long and ``centre_slot (F, 3)`` bool (or None
    when ``centres`` is False: no cell has a centre vertex), as ``_steps.triangulate``
    (the entries of centre vertices are 0: the caller fills them). ``layers``: the
    stacked cell layers ``(first, stop)`` of the cells; ``vert_key`` holds the vertices
    of those layers and of layer ``stop``."""
    k = _kernels()
    X, Y, Z = sizes
    device = cell_id.device
    rows, n_tri = rows.long(), n_tri.long()
    first, total = _exclusive(n_tri)
    row_lo, n_rows = layers[0] * Y, (layers[1] - layers[0]) * Y
    # first vertex of each row of the layers and of two more rows of layer ``stop``
    # (its vertices end at its last row's start plus its own)
    row_vert = _row_ranges(vert_key, 3 * Z, row_lo, n_rows + Y + 1)
    row_cell = _row_ranges(cell_id, Z, row_lo, n_rows)
    faces = torch.empty(total, 3, dtype=torch.long, device=device)
    cell_of_face = torch.empty(total, dtype=torch.long, device=device)
    centre = torch.empty(total if centres else 0, 3, dtype=torch.bool, device=device)
    G = _rows_per_thread(device)
    launch(k.faces_of_rows, (n_rows + G - 1) // G,
           [to_warp(cell_id), to_warp(rows), to_warp(n_tri), to_warp(first), to_warp(row_cell),
            to_warp(_edge_codes(tri_table)), tri_table.shape[1], Y, Z, to_warp(row_vert),
            to_warp(vert_key), to_warp(faces.view(-1)), to_warp(cell_of_face),
            to_warp(centre.view(-1).view(torch.uint8)), G, n_rows],
           device)
    return faces, cell_of_face, centre if centres else None


def vertex_stencils(lower, d, corner_ijk, sizes):
    """``(index (10, V), None, steps (2, V))`` int32 (the samples' flat indices fit: the
    kernels take volumes of fewer than ``2**31`` samples), as ``_steps.sample_stencil``
    (without its ``axes``, which placing the vertices does not read)."""
    k = _kernels()
    X, Y, Z = sizes
    device = lower.device
    V = lower.shape[0]
    index = torch.empty(10, V, dtype=torch.int32, device=device)
    steps = torch.empty(2, V, dtype=torch.int32, device=device)
    G = 1 if device.type == "cuda" else 64
    launch(k.stencils, (V + G - 1) // G,
           [to_warp(lower), to_warp(d), to_warp(corner_ijk), G, X, Y, Z, to_warp(index),
            to_warp(steps)], device)
    return index, None, steps
