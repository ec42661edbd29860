"""NVIDIA Warp engine for the closest-face search (optional extra ``fast``).

Warp (``pip install warp-lang``) builds a BVH per mesh (``wp.Mesh``) and answers
``mesh_query_point_no_sign`` in float32 with a compiled kernel, on the CPU or on CUDA. A
float32 face choice is not exact: measured on a 16k-face torus with 250k DeepSDF points,
0.9% of the faces returned are not the closest (distance off by up to 1e-7, the float32
rounding), and every one of them is a neighbour of the returned face. So the same kernel
then checks, in float64, every face that shares a vertex with the returned one and keeps
the closest. Only the face index leaves the engine; the distance is evaluated in torch.

Convention:
    Inputs are scaled by a power of two into ``[-1, 1]`` (see
    :func:`~torchgeo_cg.sdf.mesh_search.power_of_two_scale`), vertices ``(B, V, 3)``,
    triangles ``(T, 3)`` shared by the ``B`` meshes, points ``(B, N, 3)`` finite. Points
    and meshes stay on their device (CPU or CUDA). One BVH is built per mesh of the batch
    (Warp has no batched constructor); the query is one launch for all meshes.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import torch
from tqdm.auto import tqdm

try:
    import warp as wp
except ImportError:  # the optional extra "fast" is not installed
    wp = None

__all__ = ["WarpSearch", "morton_order", "face_rings", "build_warp_search", "warp_closest_faces"]

if wp is not None:  # kernels exist only with the optional extra
    # Warp's info banner and kernel-load lines would print on every import; warnings stay
    if wp.config.log_level < logging.WARNING:
        wp.config.log_level = logging.WARNING
    wp.init()
    wp.set_module_options({"enable_backward": False})  # the search needs no adjoint kernels

    @wp.func
    def _segment_d2(w: wp.vec3d, e: wp.vec3d) -> wp.float64:
        """Squared distance from ``w`` to the segment ``[0, e]`` (zero length safe)."""
        ee = wp.dot(e, e)
        t = wp.float64(0.0)
        if ee > wp.float64(0.0):
            t = wp.clamp(wp.dot(w, e) / ee, wp.float64(0.0), wp.float64(1.0))
        d = w - t * e
        return wp.dot(d, d)


    @wp.func
    def _triangle_d2(p: wp.vec3d, a: wp.vec3d, b: wp.vec3d, c: wp.vec3d) -> wp.float64:
        """Squared point-triangle distance: the plane projection when it falls inside the
        (non-degenerate) triangle, else the closest of the three edges."""
        e0 = b - a
        e1 = c - a
        w = p - a
        d00 = wp.dot(e0, e0)
        d01 = wp.dot(e0, e1)
        d11 = wp.dot(e1, e1)
        dot0 = wp.dot(w, e0)
        dot1 = wp.dot(w, e1)
        den = d00 * d11 - d01 * d01
        if den > wp.float64(1.0e-12) * d00 * d11:
            bv = (d11 * dot0 - d01 * dot1) / den
            bw = (d00 * dot1 - d01 * dot0) / den
            if bv >= wp.float64(0.0) and bw >= wp.float64(0.0) and bv + bw <= wp.float64(1.0):
                q = w - bv * e0 - bw * e1
                return wp.dot(q, q)
        best = wp.min(_segment_d2(w, e0), _segment_d2(w, e1))
        return wp.min(best, _segment_d2(p - b, c - b))


    @wp.kernel
    def _closest_face_kernel(
        mesh_ids: wp.array(dtype=wp.uint64),
        points32: wp.array(dtype=wp.vec3),
        points64: wp.array(dtype=wp.vec3d),
        verts64: wp.array(dtype=wp.vec3d),
        tris: wp.array(dtype=wp.int32, ndim=2),
        ring_start: wp.array(dtype=wp.int32),
        ring_faces: wp.array(dtype=wp.int32),
        first: int,
        points_per_mesh: int,
        num_vertices: int,
        out: wp.array(dtype=wp.int32),
    ):
        i = wp.tid() + first
        item = i // points_per_mesh
        query = wp.mesh_query_point_no_sign(mesh_ids[item], points32[i], 1.0e30)
        best = query.face
        p = points64[i]
        base = item * num_vertices
        best_d2 = _triangle_d2(p, verts64[base + tris[best, 0]], verts64[base + tris[best, 1]],
                               verts64[base + tris[best, 2]])
        f0 = best
        for j in range(ring_start[f0], ring_start[f0 + 1]):  # float64 check of the 1-ring
            g = ring_faces[j]
            d2 = _triangle_d2(p, verts64[base + tris[g, 0]], verts64[base + tris[g, 1]],
                              verts64[base + tris[g, 2]])
            if d2 < best_d2 or (d2 == best_d2 and g < best):
                best_d2 = d2
                best = g
        out[i] = best


class WarpSearch(NamedTuple):
    """Warp BVHs of ``B`` meshes sharing ``(T, 3)`` triangles, with the float64 data of the
    neighbour check. Torch tensors are kept alive: the Warp arrays alias them."""

    meshes: list
    mesh_ids: object  # wp.array of uint64
    verts32: torch.Tensor  # (B V, 3) float32
    verts64: torch.Tensor  # (B V, 3) float64
    tris: torch.Tensor  # (T, 3) int32
    ring_start: torch.Tensor  # (T + 1,) int32 CSR: the other faces sharing a vertex
    ring_faces: torch.Tensor  # (nnz,) int32
    num_vertices: int


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
    lo, hi = points_n3.amin(0), points_n3.amax(0)
    span = torch.where(hi > lo, hi - lo, torch.ones_like(hi))
    q = ((points_n3 - lo) / span * 1023).long()
    key = _spread_bits(q[:, 0]) | (_spread_bits(q[:, 1]) << 1) | (_spread_bits(q[:, 2]) << 2)
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
    """One Warp BVH per mesh, plus the vertex-to-face table of the float64 check.

    Args:
        verts_bv3: ``(B, V, 3)`` scaled vertices (any float dtype), CPU or CUDA.
        tris_t3: ``(T, 3)`` long triangles.

    Returns:
        :class:`WarpSearch`.

    Raises:
        ImportError: Warp is not installed (the message names the extra ``fast``).

    Example:
        >>> v = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
        >>> tris = torch.tensor([[0, 1, 2], [0, 1, 3]])
        >>> try:
        ...     rings = build_warp_search(v, tris).ring_start.tolist()
        ... except ImportError as e:  # without the extra: the message names it
        ...     rings = face_rings(tris, 4)[0].tolist() if "fast" in str(e) else None
        >>> rings
        [0, 1, 2]
    """
    if wp is None:
        raise ImportError("the Warp engine needs the optional extra 'fast': "
                          "pip install 'torchgeo_cg[fast]'")
    B, V = verts_bv3.shape[:2]
    device = wp.device_from_torch(verts_bv3.device)
    verts32 = verts_bv3.detach().reshape(B * V, 3).float().contiguous()
    verts64 = verts_bv3.detach().reshape(B * V, 3).double().contiguous()
    tris = tris_t3.to(device=verts_bv3.device, dtype=torch.int32).contiguous()
    ring_start, ring_faces = face_rings(tris_t3.to(verts_bv3.device), V)
    indices = wp.from_torch(tris.reshape(-1), dtype=wp.int32)
    meshes = [wp.Mesh(points=wp.from_torch(verts32[b * V:(b + 1) * V], dtype=wp.vec3),
                      indices=indices) for b in range(B)]  # Warp builds one BVH per call
    ids = wp.array([m.id for m in meshes], dtype=wp.uint64, device=device)
    return WarpSearch(meshes, ids, verts32, verts64, tris, ring_start, ring_faces, V)


def warp_closest_faces(search: WarpSearch, points_bn3: torch.Tensor, block: int = 1 << 16,
                       progress: bool = False) -> torch.Tensor:
    """Closest face of every point, per mesh: ``(B, N)`` long, on the points' device.

    Args:
        search: :func:`build_warp_search` of the ``B`` meshes (same device as the points).
        points_bn3: ``(B, N, 3)`` scaled finite points.
        block: points per launch (for the progress bar).
        progress: show a tqdm progress bar over the launches.

    Example:
        >>> v = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
        >>> tris = torch.tensor([[0, 1, 2], [0, 1, 3]])
        >>> p = torch.tensor([[[0.2, 0.2, -1.0], [0.2, -1.0, 0.2]]])
        >>> if wp is not None:
        ...     print(warp_closest_faces(build_warp_search(v, tris), p))
        ... else:  # without the extra, the same answer from the torch search
        ...     from torchgeo_cg.sdf.engines import search_faces
        ...     print(search_faces(v, tris, p, "torch"))
        tensor([[0, 1]])
    """
    B, N = points_bn3.shape[:2]
    device = wp.device_from_torch(points_bn3.device)
    order = morton_order(points_bn3.detach().reshape(B * N, 3))
    item = torch.div(order, N, rounding_mode="floor")
    order = order[torch.argsort(item, stable=True)]  # rows of mesh b stay rows of mesh b
    p64 = points_bn3.detach().reshape(B * N, 3).double()[order].contiguous()
    p32 = p64.float()
    out = torch.empty(B * N, dtype=torch.int32, device=points_bn3.device)
    args = [search.mesh_ids, wp.from_torch(p32, dtype=wp.vec3),
            wp.from_torch(p64, dtype=wp.vec3d), wp.from_torch(search.verts64, dtype=wp.vec3d),
            wp.from_torch(search.tris, dtype=wp.int32), wp.from_torch(search.ring_start),
            wp.from_torch(search.ring_faces)]
    out_wp = wp.from_torch(out)
    for s in tqdm(range(0, B * N, block), disable=not progress, desc="mesh_sdf search",
                  unit="block"):
        wp.launch(_closest_face_kernel, dim=min(block, B * N - s), device=device,
                  inputs=[*args, s, N, search.num_vertices, out_wp])
    wp.synchronize_device(device)
    faces = torch.empty_like(out, dtype=torch.long)
    faces[order] = out.long()
    return faces.reshape(B, N)
