"""The grid walk of :mod:`~torchgeo_cg.rays._grid` as one Warp kernel (``backend="warp"``).

One thread per ray walks the same grid (built in torch), tests the same faces with the
same float64 watertight test (:mod:`~torchgeo_cg.rays._watertight`, exact signs from
:mod:`~torchgeo_cg.rays._exact`), operation for operation, and keeps the same
lexicographic minimum ``(t, face)``. The module compiles with ``fuse_fp=False`` (no
fused multiply-add contraction), so every operation rounds exactly as torch's, and the
two backends return identical faces. Only the face index leaves the kernel; the hit is
evaluated and refined in torch.

Convention:
    As :func:`~torchgeo_cg.rays._grid.walk` (float64 scaled data, flat rays); the
    entry parameters and first cells come from torch.
"""

import torch

from torchgeo_cg.engine import launch_rows, load_warp, register_kernels, to_warp
from torchgeo_cg.rays._grid import RayGrid, enter_grid
from torchgeo_cg.rays._watertight import ray_shear

__all__: list[str] = []


def _exact_funcs(wp):
    """Error-free transformations and the exact sign of ``a b - c d`` (mirrors ``_exact``)."""

    @wp.func
    def two_sum(a: wp.float64, b: wp.float64):
        s = a + b
        bb = s - a
        return s, (a - (s - bb)) + (b - bb)

    @wp.func
    def split(a: wp.float64):
        c = (wp.float64(134217728.0) + wp.float64(1.0)) * a  # 2**27 + 1, exact in float64
        hi = c - (c - a)
        return hi, a - hi

    @wp.func
    def two_prod(a: wp.float64, b: wp.float64):
        p = a * b
        ah, al = split(a)
        bh, bl = split(b)
        return p, al * bl - (((p - ah * bh) - al * bh) - ah * bl)

    @wp.func
    def sgn(x: wp.float64) -> int:
        if x > wp.float64(0.0):
            return 1
        if x < wp.float64(0.0):
            return -1
        return 0

    @wp.func
    def cross_sign(a: wp.float64, b: wp.float64, c: wp.float64, d: wp.float64):
        p1 = a * b
        p2 = c * d
        value = p1 - p2
        s = sgn(value)
        if wp.abs(value) <= wp.float64(4.440892098500626e-16) * (wp.abs(p1) + wp.abs(p2)):
            q1, e1 = two_prod(a, b)
            q2, e2 = two_prod(c, d)
            # grow-expansion of [e1, -e2, q1, -q2]; the last nonzero component decides
            q, h0 = two_sum(-e2, e1)
            r, g0 = two_sum(q1, h0)
            r, g1 = two_sum(r, q)
            w, k0 = two_sum(-q2, g0)
            w, k1 = two_sum(w, g1)
            w, k2 = two_sum(w, r)
            s = int(0)  # noqa: UP018 - a dynamic variable for Warp
            if k0 != wp.float64(0.0):
                s = sgn(k0)
            if k1 != wp.float64(0.0):
                s = sgn(k1)
            if k2 != wp.float64(0.0):
                s = sgn(k2)
            if w != wp.float64(0.0):
                s = sgn(w)
        return value, s

    @wp.func
    def tie(px: wp.float64, py: wp.float64, qx: wp.float64, qy: wp.float64) -> int:
        first = sgn(qy - py)
        if first != 0:
            return first
        return sgn(px - qx)

    return cross_sign, tie


def _test_func(wp):
    """The watertight test of one ray and one face (mirrors ``watertight_test``)."""
    cross_sign, tie = _exact_funcs(wp)
    f64 = wp.float64

    @wp.func
    def test(tri: wp.array(dtype=wp.float64, ndim=3), f: wp.int64, o: wp.vec3d,
             kx: int, ky: int, kz: int, sh: wp.vec3d, t_lo: f64, t_hi: f64):
        """Watertight test of face ``f``: ``(hit in [t_lo, t_hi], t)``."""
        x = wp.vec3d()
        y = wp.vec3d()
        z = wp.vec3d()
        fi = int(f)
        for c in range(3):
            r0 = tri[fi, c, kx] - o[kx]
            r1 = tri[fi, c, ky] - o[ky]
            r2 = tri[fi, c, kz] - o[kz]
            x[c] = r0 - sh[0] * r2
            y[c] = r1 - sh[1] * r2
            z[c] = sh[2] * r2
        u, su = cross_sign(x[2], y[1], y[2], x[1])
        if su == 0:
            su = tie(x[1], y[1], x[2], y[2])
        v, sv = cross_sign(x[0], y[2], y[0], x[2])
        if sv == 0:
            sv = tie(x[2], y[2], x[0], y[0])
        if su != sv:  # (the decision needs all three signs equal: stop early)
            return False, f64(0.0)
        w, sw = cross_sign(x[1], y[0], y[1], x[0])
        if sw == 0:
            sw = tie(x[0], y[0], x[1], y[1])
        det = u + v + w
        if su != sv or sv != sw or su == 0 or det == f64(0.0):
            return False, f64(0.0)
        t = (u * z[0] + v * z[1] + w * z[2]) / det
        if not wp.isfinite(t):
            return False, t
        return t >= t_lo and t <= t_hi, t

    return test


def _build(wp):
    wp.set_module_options({"fuse_fp": False}, module=__name__)
    test = _test_func(wp)
    f64 = wp.float64

    @wp.kernel
    def walk_kernel(tri: wp.array(dtype=wp.float64, ndim=3), o: wp.array(dtype=wp.vec3d),
                    d: wp.array(dtype=wp.vec3d), item: wp.array(dtype=wp.int64),
                    perm: wp.array(dtype=wp.int64, ndim=2), shear: wp.array(dtype=wp.vec3d),
                    t_lo: wp.array(dtype=f64), t_hi: wp.array(dtype=f64),
                    t1: wp.array(dtype=f64), cell0: wp.array(dtype=wp.int64, ndim=2),
                    lo: wp.vec3d, h: f64, dims: wp.vec3i, cells: wp.int64,
                    start: wp.array(dtype=wp.int64), count: wp.array(dtype=wp.int64),
                    faces: wp.array(dtype=wp.int64), sel: wp.array(dtype=wp.int64),
                    out_face: wp.array(dtype=wp.int64)):
        i = int(sel[wp.tid()])  # the ray (and output row) this thread answers
        oi, di = o[i], d[i]
        kx, ky, kz = int(perm[i, 0]), int(perm[i, 1]), int(perm[i, 2])
        cx, cy, cz = int(cell0[i, 0]), int(cell0[i, 1]), int(cell0[i, 2])
        best_t = f64(wp.inf)
        best_f = wp.int64(-1)
        running = bool(True)  # noqa: UP018 - a dynamic variable for Warp
        while running:
            key = int(item[i] * cells + wp.int64((cx * dims[1] + cy) * dims[2] + cz))
            first = int(start[key])
            for k in range(first, first + int(count[key])):
                f = faces[k]
                hit, t = test(tri, f, oi, kx, ky, kz, shear[i], t_lo[i], t_hi[i])
                if hit and (t < best_t or (t == best_t and f < best_f)):
                    best_t = t
                    best_f = f
            cell = wp.vec3i(cx, cy, cz)
            t_exit = f64(wp.inf)
            axis = int(-1)  # noqa: UP018 - a dynamic variable for Warp
            for a in range(3):
                tb = f64(wp.inf)
                if di[a] != f64(0.0):
                    inc = int(0)  # noqa: UP018 - a dynamic variable for Warp
                    if di[a] > f64(0.0):
                        inc = 1
                    tb = (lo[a] + f64(cell[a] + inc) * h - oi[a]) / di[a]
                if axis < 0 or tb < t_exit:
                    t_exit = tb
                    axis = a
            if t_exit >= t1[i] or best_t <= t_exit:
                running = False
            else:
                step = int(1)  # noqa: UP018 - a dynamic variable for Warp
                if di[axis] < f64(0.0):
                    step = -1
                cell[axis] = cell[axis] + step
                cx, cy, cz = cell[0], cell[1], cell[2]
                if cell[axis] < 0 or cell[axis] >= dims[axis]:
                    running = False
        out_face[i] = best_f

    return walk_kernel


_kernels = register_kernels(_build)


def warp_first_faces(grid: RayGrid, o: torch.Tensor, d: torch.Tensor, item: torch.Tensor,
                     t_lo: torch.Tensor, t_hi: torch.Tensor) -> torch.Tensor:
    """Global face id of the first hit of every ray (``-1`` none), as
    :func:`~torchgeo_cg.rays._grid.walk` finds it, in one launch (split across torch's CPU
    threads).

    Example:
        >>> from torchgeo_cg.engine import warp_status
        >>> from torchgeo_cg.rays._grid import build_grid
        >>> tri = torch.tensor([[[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]]], dtype=torch.float64)
        >>> o = torch.tensor([[0.25, 0.25, 1.0]], dtype=torch.float64)
        >>> d = torch.tensor([[0.0, 0.0, -1.0]], dtype=torch.float64)
        >>> args = (o, d, torch.zeros(1, dtype=torch.long), o.new_zeros(1), o.new_ones(1) * 9)
        >>> warp_first_faces(build_grid(tri), *args) if warp_status()[0] == "ok" else [0]
        tensor([0])
    """
    wp = load_warp()
    kernel = _kernels()
    n = o.shape[0]
    out = torch.full((n,), -1, dtype=torch.long, device=o.device)
    perm, shear = ray_shear(d)
    t0, t1 = enter_grid(grid, o, d, t_lo, t_hi)
    rows = (t0 <= t1).nonzero().squeeze(1)
    if rows.numel() == 0:
        return out
    o, d, t0 = o[rows].contiguous(), d[rows].contiguous(), t0[rows]
    dims, lo, h = grid.dims, grid.lo, grid.h
    cell = ((o + t0[:, None] * d - lo) / h).floor().long()
    cell = cell.clamp(min=torch.zeros_like(dims), max=dims - 1)
    found = torch.empty(rows.numel(), dtype=torch.long, device=o.device)
    dims_i = [int(x) for x in dims]
    launch_rows(kernel, torch.arange(rows.numel(), device=o.device), [
        to_warp(grid.tri), to_warp(o, wp.vec3d), to_warp(d, wp.vec3d), to_warp(item[rows]),
        to_warp(perm[rows]), to_warp(shear[rows], wp.vec3d), to_warp(t_lo[rows]),
        to_warp(t_hi[rows]), to_warp(t1[rows]), to_warp(cell),
        wp.vec3d(*[float(x) for x in lo]), float(h), wp.vec3i(*dims_i), int(grid.cells),
        to_warp(grid.start), to_warp(grid.count), to_warp(grid.faces), None, to_warp(found)],
        17, o.device)  # on torch's CPU threads
    out[rows] = found
    return out
