"""NVIDIA Warp engine for the closest-face search (optional extra ``fast``).

Warp (``pip install warp-lang``) builds a BVH per mesh (``wp.Mesh``) and answers
``mesh_query_point_no_sign`` in float32 with a compiled kernel, on the CPU or on CUDA. A
float32 face choice is not exact: measured on a 16k-face torus with 250k DeepSDF points,
0.9% of the faces returned are not the closest (distance off by up to 1e-7, the float32
rounding), and every one of them is a neighbour of the returned face. So the same kernel
then checks, in float64, every face that shares a vertex with the returned one and keeps
the closest. When asked (``mode``), it also evaluates the distance on that face in
float64 with the operations of the torch evaluation
(:func:`~torchgeo_cg.sdf._triangle.closest_point_on_triangle`) and signs it with the
pseudo-normal of the closest feature, so queries that need no gradient never leave the
kernel; otherwise only the face index leaves it.

Convention:
    Inputs are scaled by a power of two into ``[-1, 1]`` (see
    :func:`~torchgeo_cg.core.numerics.power_of_two_scale`), vertices ``(B, V, 3)``,
    triangles ``(T, 3)`` shared by the ``B`` meshes, points ``(B, N, 3)`` finite. Points
    and meshes stay on their device (CPU or CUDA). One BVH is built per mesh of the batch
    (Warp has no batched constructor); the query is one launch for all meshes.
"""

from typing import NamedTuple

import torch
from tqdm.auto import tqdm

from torchgeo_cg.engine import load_warp, register_kernels
from torchgeo_cg.sdf._triangle import pseudo_normals, unit_normals

__all__: list[str] = []

def _edge_funcs(wp):
    """The Warp functions on points and segments."""

    @wp.func
    def _dot3(u: wp.vec3d, v: wp.vec3d) -> wp.float64:
        """``u . v`` summed left to right, as the torch evaluation does."""
        return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]

    @wp.func
    def _segment(p: wp.vec3d, u: wp.vec3d, v: wp.vec3d):
        """Closest point of segment ``uv`` to ``p``: ``(squared distance, t in [0, 1],
        point)``, zero length safe (the torch evaluation's formula)."""
        ab = v - u
        den = _dot3(ab, ab)
        t = wp.float64(0.0)
        if den > wp.float64(0.0):
            t = wp.clamp(_dot3(p - u, ab) / den, wp.float64(0.0), wp.float64(1.0))
        q = wp.vec3d(u[0] + t * ab[0], u[1] + t * ab[1], u[2] + t * ab[2])
        d = p - q
        return _dot3(d, d), t, q

    @wp.func
    def _defers(t: wp.float64, t_prev: wp.float64, t_next: wp.float64) -> bool:
        """An edge's candidate clamped to a corner that the other edge at that corner does
        not clamp to defers to it (the rule of the torch evaluation's ``_defer_vertices``)."""
        at_start = t <= wp.float64(0.0) and not (t_prev >= wp.float64(1.0))
        at_end = t >= wp.float64(1.0) and not (t_next <= wp.float64(0.0))
        return at_start or at_end

    @wp.func
    def _nearer_edge(d2: wp.float64, t: wp.float64, qe: wp.vec3d, edge: int, skip: bool,
                     best: wp.float64, t_best: wp.float64, q: wp.vec3d, code: int):
        """The candidate ``(squared distance, t, point, code)`` after edge ``edge`` is
        tried: it replaces the current one only when strictly nearer and not skipped."""
        if d2 < best and not skip:
            return d2, t, qe, edge
        return best, t_best, q, code


    return _dot3, _segment, _defers, _nearer_edge


def _closest_funcs(wp, _dot3, _segment, _defers, _nearer_edge):
    """The Warp function of the closest point on a triangle."""

    @wp.func
    def _closest_on_triangle(p: wp.vec3d, a: wp.vec3d, b: wp.vec3d, c: wp.vec3d):
        """Squared distance, closest point and feature code (0 face, 1-3 edges ab, bc,
        ca, 4-6 vertices a, b, c) of triangle ``abc`` to ``p``, with the operations of
        :func:`~torchgeo_cg.sdf._triangle.closest_point_on_triangle`: the plane
        projection when it falls inside the (non-degenerate) triangle, else the nearest
        edge point, the face first and then the edges in order on ties."""
        e0 = b - a
        e1 = c - a
        w = p - a
        d00 = _dot3(e0, e0)
        d01 = _dot3(e0, e1)
        d11 = _dot3(e1, e1)
        dot0 = _dot3(w, e0)
        dot1 = _dot3(w, e1)
        den = d00 * d11 - d01 * d01
        best = wp.float64(wp.inf)
        q = a
        code = wp.int32(0)
        t_best = wp.float64(0.0)
        inside = False
        if den > wp.float64(1.0e-12) * d00 * d11:
            bv = (d11 * dot0 - d01 * dot1) / den
            bw = (d00 * dot1 - d01 * dot0) / den
            if bv >= wp.float64(0.0) and bw >= wp.float64(0.0) and bv + bw <= wp.float64(1.0):
                q = wp.vec3d(a[0] + bv * e0[0] + bw * e1[0], a[1] + bv * e0[1] + bw * e1[1],
                             a[2] + bv * e0[2] + bw * e1[2])
                d = p - q
                best = _dot3(d, d)
                inside = True
        d1, t1, q1 = _segment(p, a, b)
        d2, t2, q2 = _segment(p, b, c)
        d3, t3, q3 = _segment(p, c, a)
        s1 = _defers(t1, t3, t2)
        s2 = _defers(t2, t1, t3)
        s3 = _defers(t3, t2, t1)
        if s1 and s2 and s3:  # a degenerate triangle: then no edge defers
            s1 = False
            s2 = False
            s3 = False
        best, t_best, q, code = _nearer_edge(d1, t1, q1, 1, inside or s1, best, t_best, q, code)
        best, t_best, q, code = _nearer_edge(d2, t2, q2, 2, inside or s2, best, t_best, q, code)
        best, t_best, q, code = _nearer_edge(d3, t3, q3, 3, inside or s3, best, t_best, q, code)
        feature = code
        if code > 0 and t_best <= wp.float64(0.0):
            feature = 3 + code  # the edge's start vertex: a, b, c
        if code > 0 and t_best >= wp.float64(1.0):
            feature = 4 + code % 3  # its end vertex: b, c, a
        return best, q, feature


    return _closest_on_triangle


def _distance_funcs(wp, _dot3):
    """The Warp functions of squared distances to triangles and segments."""

    @wp.func
    def _triangle_d2(p: wp.vec3d, a: wp.vec3d, b: wp.vec3d, c: wp.vec3d) -> wp.float64:
        """Squared point-triangle distance only (the neighbour check's comparison): the
        plane projection when it falls inside the triangle, else the nearest edge."""
        e0 = b - a
        e1 = c - a
        w = p - a
        d00 = _dot3(e0, e0)
        d01 = _dot3(e0, e1)
        d11 = _dot3(e1, e1)
        dot0 = _dot3(w, e0)
        dot1 = _dot3(w, e1)
        den = d00 * d11 - d01 * d01
        if den > wp.float64(1.0e-12) * d00 * d11:
            bv = (d11 * dot0 - d01 * dot1) / den
            bw = (d00 * dot1 - d01 * dot0) / den
            if bv >= wp.float64(0.0) and bw >= wp.float64(0.0) and bv + bw <= wp.float64(1.0):
                d = w - bv * e0 - bw * e1
                return _dot3(d, d)
        return wp.min(wp.min(_segment_d2(w, e0), _segment_d2(w, e1)), _segment_d2(p - b, c - b))

    @wp.func
    def _segment_d2(w: wp.vec3d, e: wp.vec3d) -> wp.float64:
        """Squared distance from ``w`` to the segment ``[0, e]`` (zero length safe)."""
        ee = _dot3(e, e)
        t = wp.float64(0.0)
        if ee > wp.float64(0.0):
            t = wp.clamp(_dot3(w, e) / ee, wp.float64(0.0), wp.float64(1.0))
        d = w - t * e
        return _dot3(d, d)


    return _triangle_d2


def _build(wp):
    """The closest-face kernel (and the functions it calls)."""
    _dot3, _segment, _defers, _nearer_edge = _edge_funcs(wp)
    _closest_on_triangle = _closest_funcs(wp, _dot3, _segment, _defers, _nearer_edge)
    _triangle_d2 = _distance_funcs(wp, _dot3)

    @wp.kernel
    def _closest_face_kernel(
        mesh_ids: wp.array(dtype=wp.uint64),
        order: wp.array(dtype=wp.int32),
        sorted_points: wp.array(dtype=wp.vec3d),
        corners: wp.array(dtype=wp.vec3d),
        planes: wp.array(dtype=wp.vec3d),
        ring_start: wp.array(dtype=wp.int32),
        ring_faces: wp.array(dtype=wp.int32),
        normals: wp.array(dtype=wp.vec3d),
        first: int,
        points_per_mesh: int,
        faces_per_mesh: int,
        mode: int,
        out_face: wp.array(dtype=wp.int64),
        out_sdf: wp.array(dtype=wp.float64),
    ):
        k = wp.tid() + first  # the k-th point in Morton order, row i of the input
        i = order[k]
        item = i // points_per_mesh
        p = sorted_points[k]
        p32 = wp.vec3(wp.float32(p[0]), wp.float32(p[1]), wp.float32(p[2]))
        query = wp.mesh_query_point_no_sign(mesh_ids[item], p32, 1.0e30)
        best = query.face
        face0 = item * faces_per_mesh
        base = 3 * face0
        best_d2 = _triangle_d2(p, corners[base + 3 * best], corners[base + 3 * best + 1],
                               corners[base + 3 * best + 2])
        bound = best_d2 * wp.float64(1.000001)  # above any rounding of the plane distance
        f0 = best
        for j in range(ring_start[f0], ring_start[f0 + 1]):  # float64 check of the 1-ring
            g = ring_faces[j]
            h = _dot3(p - corners[base + 3 * g], planes[face0 + g])
            if h * h <= bound:  # the plane distance is a lower bound of the face's
                d2 = _triangle_d2(p, corners[base + 3 * g], corners[base + 3 * g + 1],
                                  corners[base + 3 * g + 2])
                if d2 < best_d2 or (d2 == best_d2 and g < best):
                    best_d2 = d2
                    best = g
                    bound = best_d2 * wp.float64(1.000001)
        out_face[k] = wp.int64(best)
        if mode > 0:  # the distance (and sign) on that face, evaluated here in float64
            c = base + 3 * best
            d2, q, feature = _closest_on_triangle(p, corners[c], corners[c + 1],
                                                  corners[c + 2])
            dist = wp.sqrt(d2)
            if mode == 2:
                n = normals[7 * (face0 + best) + feature]
                if _dot3(p - q, n) < wp.float64(0.0):
                    dist = -dist
            out_sdf[k] = dist

    return _closest_face_kernel


_kernels = register_kernels(_build)


class WarpSearch:
    """Warp BVHs of ``B`` meshes sharing ``(T, 3)`` triangles, with the float64 data of the
    neighbour check and of the evaluation. Torch tensors are kept alive: the Warp arrays
    alias them.

    Attributes:
        meshes: the ``wp.Mesh`` of every batch item; ``mesh_ids`` their ids (``wp.array``).
        verts32: ``(B V, 3)`` float32 vertices the BVHs are built on.
        corners: ``(B T 3, 3)`` float64 triangle corners.
        planes: ``(B T, 3)`` float64 unit face normals (zero for degenerate faces).
        tris: ``(T, 3)`` long triangles.
        ring_start, ring_faces: int32 CSR, the other faces sharing a vertex with each face.
        num_vertices: ``V``.
    """

    def __init__(self, meshes, mesh_ids, verts32, corners, planes, tris, ring_start,
                 ring_faces, num_vertices):
        self.meshes, self.mesh_ids, self.verts32 = meshes, mesh_ids, verts32
        self.corners, self.planes = corners, planes
        self.tris, self.num_vertices = tris, num_vertices
        self.ring_start, self.ring_faces = ring_start, ring_faces
        self._normals = None

    def normals(self) -> torch.Tensor:
        """``(B T 7, 3)`` float64 feature pseudo-normals (face, 3 edges, 3 vertices) of
        :func:`~torchgeo_cg.sdf._triangle.pseudo_normals`, computed on first use."""
        if self._normals is None:
            tri = self.corners.reshape(-1, self.tris.shape[0], 3, 3)
            self._normals = pseudo_normals(tri, self.tris, self.num_vertices).reshape(
                -1, 3).contiguous()
        return self._normals


class WarpAnswer(NamedTuple):
    """What the kernel returns per point: the closest face (``(B, N)`` long) and, when
    asked for, the distance on it in float64, in the scaled units (``(B, N)``; signed
    with the pseudo-normals, or unsigned), else ``None``."""

    face_ids: torch.Tensor
    sdf: torch.Tensor | None


def _spread_bits(x: torch.Tensor) -> torch.Tensor:
    """Insert two zero bits between the 10 low bits of ``x`` (Morton interleave)."""
    x = x & 0x3FF
    x = (x | (x << 16)) & 0x30000FF
    x = (x | (x << 8)) & 0x300F00F
    x = (x | (x << 4)) & 0x30C30C3
    return (x | (x << 2)) & 0x9249249


def morton_order(points_n3: torch.Tensor) -> torch.Tensor:
    """Permutation ``(N,)`` sorting points along a Z-order curve of their bounding box
    (1024 cells per axis): neighbours in space become neighbours in memory, so the BVH
    walks of consecutive points share cache lines.

    Example:
        >>> morton_order(torch.tensor([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0], [0.9, 1.0, 1.0]]))
        tensor([1, 2, 0])
    """
    lo, hi = torch.aminmax(points_n3, dim=0)
    step = 1023 / torch.where(hi > lo, hi - lo, torch.ones_like(hi))
    cells = torch.addcmul(-lo * step, points_n3, step).to(torch.int32)  # 30-bit keys: int32
    x, y, z = cells.unbind(1)
    key = _spread_bits(x) | (_spread_bits(y) << 1) | (_spread_bits(z) << 2)
    return torch.argsort(key)


def face_rings(tris_t3: torch.Tensor, num_vertices: int) -> tuple[torch.Tensor, torch.Tensor]:
    """For every face, the other faces sharing at least one vertex with it, as int32 CSR
    ``(start (T + 1,), faces (nnz,))``, each neighbour once (sort and unique, no loop).

    Example:
        >>> start, faces = face_rings(torch.tensor([[0, 1, 2], [0, 2, 3], [4, 5, 6]]), 7)
        >>> start.tolist(), faces.tolist()
        ([0, 1, 2, 2], [1, 0])
    """
    T = tris_t3.shape[0]
    flat = tris_t3.reshape(-1)
    order = torch.argsort(flat, stable=True)
    counts = torch.bincount(flat, minlength=num_vertices)
    start = torch.cat([counts.new_zeros(1), counts.cumsum(0)])
    around = order // 3  # faces grouped by vertex
    # every (face, corner) meets every face around that corner's vertex
    per = counts[flat]  # (3 T,)
    owner = torch.arange(T, device=flat.device).repeat_interleave(3).repeat_interleave(per)
    offset = torch.arange(int(per.sum()), device=flat.device) - torch.repeat_interleave(
        per.cumsum(0) - per, per)
    other = around[torch.repeat_interleave(start[flat], per) + offset]
    key = torch.unique((owner * T + other)[owner != other])  # sorted by owner
    owner, other = key // T, key % T
    ring_start = torch.cat([key.new_zeros(1), torch.bincount(owner, minlength=T).cumsum(0)])
    return ring_start.to(torch.int32), other.to(torch.int32).contiguous()


def build_warp_search(verts_bv3: torch.Tensor, tris_t3: torch.Tensor) -> WarpSearch:
    """One Warp BVH per mesh, plus the float64 corners and the vertex-to-face table of the
    float64 check.

    Args:
        verts_bv3: ``(B, V, 3)`` scaled vertices (any float dtype), CPU or CUDA.
        tris_t3: ``(T, 3)`` long triangles.

    Returns:
        :class:`WarpSearch`.

    Raises:
        ImportError: Warp is not installed (the message names the extra ``fast``), or it
            is installed but its import failed (the message says why; chained from the
            original exception).

    Example:
        >>> v = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
        >>> tris = torch.tensor([[0, 1, 2], [0, 1, 3]])
        >>> try:
        ...     rings = build_warp_search(v, tris).ring_start.tolist()
        ... except ImportError:  # without a working extra: the same table in torch
        ...     rings = face_rings(tris, 4)[0].tolist()
        >>> rings
        [0, 1, 2]
    """
    wp = load_warp()
    B, V = verts_bv3.shape[:2]
    device = wp.device_from_torch(verts_bv3.device)
    verts32 = verts_bv3.detach().reshape(B * V, 3).float().contiguous()
    tris = tris_t3.to(verts_bv3.device)
    tri = verts_bv3.detach().double()[:, tris]  # (B, T, 3, 3)
    corners = tri.reshape(-1, 3).contiguous()
    planes = unit_normals(tri)
    ring_start, ring_faces = face_rings(tris, V)
    indices = wp.from_torch(tris.to(torch.int32).reshape(-1).contiguous(), dtype=wp.int32)
    meshes = [wp.Mesh(points=wp.from_torch(verts32[b * V:(b + 1) * V], dtype=wp.vec3),
                      indices=indices) for b in range(B)]  # Warp builds one BVH per call
    ids = wp.array([m.id for m in meshes], dtype=wp.uint64, device=device)
    return WarpSearch(meshes, ids, verts32, corners, planes.reshape(-1, 3).contiguous(), tris,
                      ring_start, ring_faces, V)


def warp_closest_faces(search: WarpSearch, points_bn3: torch.Tensor, mode: int = 0,
                       block: int = 1 << 16, progress: bool = False) -> WarpAnswer:
    """Closest face of every point, per mesh, and optionally its distance in float64.

    Args:
        search: :func:`build_warp_search` of the ``B`` meshes (same device as the points).
        points_bn3: ``(B, N, 3)`` scaled finite points, far ones pulled in
            (:func:`~torchgeo_cg.sdf._mesh_search.pull_in_far_points`).
        mode: ``0`` faces only, ``1`` also the unsigned distance, ``2`` also the distance
            signed by the pseudo-normal of the closest feature (negative inside).
        block: points per launch (for the progress bar).
        progress: show a tqdm progress bar over the launches.

    Returns:
        :class:`WarpAnswer` ``(face_ids (B, N) long, sdf (B, N) float64 | None)`` on the
        points' device.

    Example:
        >>> v = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
        >>> tris = torch.tensor([[0, 1, 2], [0, 1, 3]])
        >>> p = torch.tensor([[[0.2, 0.2, -1.0], [0.2, -1.0, 0.2]]])
        >>> from torchgeo_cg.engine import warp_status
        >>> if warp_status()[0] == "ok":
        ...     print(warp_closest_faces(build_warp_search(v, tris), p).face_ids)
        ... else:  # without the extra, the same answer from the torch search
        ...     from torchgeo_cg.sdf._closest_faces import search_faces
        ...     print(search_faces(v, tris, p, "torch"))
        tensor([[0, 1]])
    """
    wp = load_warp()
    kernel = _kernels()
    B, N = points_bn3.shape[:2]
    device = wp.device_from_torch(points_bn3.device)
    p64 = points_bn3.detach().reshape(B * N, 3).double().contiguous()
    order = morton_order(p64)
    if B > 1:  # rows of mesh b stay together: one BVH at a time
        order = order[torch.argsort(torch.div(order, N, rounding_mode="floor"), stable=True)]
    faces_sorted = torch.empty(B * N, dtype=torch.long, device=points_bn3.device)
    sdf_sorted = torch.empty(B * N if mode else 0, dtype=torch.float64,
                             device=points_bn3.device)
    normals = search.normals() if mode == 2 else search.corners[:0]
    args = [search.mesh_ids, wp.from_torch(order.to(torch.int32)),
            wp.from_torch(p64.index_select(0, order), dtype=wp.vec3d),
            wp.from_torch(search.corners, dtype=wp.vec3d),
            wp.from_torch(search.planes, dtype=wp.vec3d), wp.from_torch(search.ring_start),
            wp.from_torch(search.ring_faces), wp.from_torch(normals, dtype=wp.vec3d)]
    outs = [wp.from_torch(faces_sorted), wp.from_torch(sdf_sorted)]
    T = search.tris.shape[0]
    for s in tqdm(range(0, B * N, block), disable=not progress, desc="mesh_sdf search",
                  unit="block"):
        wp.launch(kernel, dim=min(block, B * N - s), device=device,
                  inputs=[*args, s, N, T, mode, *outs])
    wp.synchronize_device(device)
    face_ids = torch.empty_like(faces_sorted).index_copy_(0, order, faces_sorted)
    if not mode:
        return WarpAnswer(face_ids.reshape(B, N), None)
    sdf = torch.empty_like(sdf_sorted).index_copy_(0, order, sdf_sorted)
    return WarpAnswer(face_ids.reshape(B, N), sdf.reshape(B, N))
