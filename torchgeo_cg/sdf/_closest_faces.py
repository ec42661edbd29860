"""The closest-face search behind :func:`~torchgeo_cg.sdf.mesh_distance.mesh_sdf`: the
backend choice among :data:`~torchgeo_cg.sdf.engines.ENGINES`, the cache of search
structures, and the ``torchgeo_cg::closest_faces`` custom op (with a batching rule, so
``mesh_sdf`` works under ``torch.func.vmap`` and ``jacrev``).

Convention:
    Vertices ``(B, V, 3)`` share triangles ``(T, 3)``; points ``(B, N, 3)``; the result is
    ``(B, N)`` long face indices on the points' device.
"""

from __future__ import annotations

import importlib.util
import itertools
import math
import weakref

import torch

from torchgeo_cg.core.check import check_choice
from torchgeo_cg.core.numerics import power_of_two_scale
from torchgeo_cg.engine import resolve_backend as engine_backend
from torchgeo_cg.sdf._engine_warp import build_warp_search, warp_closest_faces
from torchgeo_cg.sdf._mesh_search import (
    build_torch_search,
    pull_in_far_points,
    torch_closest_faces,
)
from torchgeo_cg.sdf.engines import ENGINES

__all__ = ["resolve_backend", "new_cache_key", "search_faces", "engine_sdf"]

#: Cached search structures: key -> (fingerprint, structure); see :func:`new_cache_key`.
_CACHE: dict[int, tuple[tuple, object]] = {}
_KEYS = itertools.count()


def resolve_backend(backend: str) -> str:
    """``"auto"`` -> the fastest installed engine that imports, or ``"torch"``; an engine
    name is checked to be installed and to import.

    Warp's loading, its errors and the one warning of ``"auto"`` are those of
    :func:`torchgeo_cg.engine.resolve_backend`.

    Warns:
        UserWarning: ``"auto"`` skips an engine that is installed but failed to import
            (once per process).

    Raises:
        ValueError: unknown name.
        ImportError: the engine is not installed (names the extra ``fast``), or it is
            installed but its import failed (says why; chained from that exception).

    Example:
        >>> resolve_backend("torch")
        'torch'
    """
    if backend == "auto":
        return "warp" if engine_backend("auto") == "warp" and "warp" in ENGINES else "torch"
    if backend == "torch":
        return backend
    check_choice(backend, ("auto", "torch", *sorted(ENGINES)), "backend")
    if backend == "warp":
        return engine_backend("warp")
    if importlib.util.find_spec(ENGINES[backend]) is None:
        raise ImportError(f"backend={backend!r} needs the optional extra 'fast': "
                          f"pip install 'torchgeo_cg[fast]' (installs {ENGINES[backend]})")
    return backend


def new_cache_key(owner: object) -> int:
    """A key under which the search structure of ``owner``'s mesh is cached until ``owner``
    is garbage collected (used by :class:`~torchgeo_cg.sdf.mesh_distance.MeshSDF`)."""
    key = next(_KEYS)
    weakref.finalize(owner, _CACHE.pop, key, None)
    return key


def _scaled(verts_bv3: torch.Tensor, points_bn3: torch.Tensor):
    """Vertices and points divided by the mesh's power-of-two scale (exact); the points in
    float64, as every search reads them, with far ones pulled in
    (:func:`~torchgeo_cg.sdf._mesh_search.pull_in_far_points`); non-finite points are
    searched at the origin (their distance comes out NaN anyway)."""
    if not bool(torch.isfinite(verts_bv3).all()):
        raise ValueError("verts: expected finite coordinates, got NaN or inf")
    scale = power_of_two_scale(verts_bv3.abs().amax((1, 2), keepdim=True))
    points = points_bn3.to(torch.float64) / scale.to(torch.float64)
    points = torch.where(torch.isfinite(points).all(-1, keepdim=True), points, 0.0)
    return verts_bv3 / scale, pull_in_far_points(points)


def _build_search(verts_bv3: torch.Tensor, tris_t3: torch.Tensor, backend: str) -> object:
    """The search structure of a backend for scaled vertices ``(B, V, 3)``.

    Example:
        >>> s = _build_search(torch.eye(3)[None], torch.tensor([[0, 1, 2]]), "torch")
        >>> s.faces_per_mesh
        1
    """
    if backend == "torch":
        tri = verts_bv3.detach().to("cpu", torch.float64)[:, tris_t3.cpu()]
        return build_torch_search(tri)
    return build_warp_search(verts_bv3, tris_t3)


def _query(structure, points_bn3: torch.Tensor, backend: str, mode: int, progress: bool
           ) -> tuple[torch.Tensor, torch.Tensor]:
    if backend == "torch":
        p = points_bn3.to("cpu", torch.float64)
        faces = torch_closest_faces(structure, p, progress=progress).to(points_bn3.device)
        return faces, _no_distances(points_bn3)
    answer = warp_closest_faces(structure, points_bn3, mode=mode, progress=progress)
    return answer.face_ids, answer.sdf if mode else _no_distances(points_bn3)


def _no_distances(points_bn3: torch.Tensor) -> torch.Tensor:
    return points_bn3.new_zeros(points_bn3.shape[:2], dtype=torch.float64)


def _fingerprint(verts: torch.Tensor, tris: torch.Tensor, backend: str) -> tuple:
    return (backend, verts.data_ptr(), verts._version, tuple(verts.shape), verts.dtype,
            verts.device, tris.data_ptr(), tris._version, tuple(tris.shape))


def _same_mesh(entry, verts: torch.Tensor, tris: torch.Tensor, backend: str) -> bool:
    """Exact check that ``entry`` (backend, vertices, triangles, structure) is this mesh."""
    b, v, t, _ = entry
    return (b == backend and v.shape == verts.shape and v.dtype == verts.dtype
            and v.device == verts.device and t.shape == tris.shape
            and bool(torch.equal(v, verts)) and bool(torch.equal(t, tris)))


def _structure(verts, tris, scaled_v, backend: str, key: int):
    """The search structure: the owner's cached one (``key >= 0``), else the last mesh an
    engine searched when it is exactly this one (repeated calls of ``mesh_sdf`` on one
    mesh build its BVH once), else a new one."""
    if key >= 0:
        fingerprint = _fingerprint(verts, tris, backend)
        cached = _CACHE.get(key)
        if cached is not None and cached[0] == fingerprint:
            return cached[1]
        structure = _build_search(scaled_v, tris, backend)
        _CACHE[key] = (fingerprint, structure)
        return structure
    if backend == "torch":  # its grids are large and cheap to rebuild: not kept
        return _build_search(scaled_v, tris, backend)
    if _LAST and _same_mesh(_LAST[0], verts, tris, backend):
        return _LAST[0][3]
    structure = _build_search(scaled_v, tris, backend)
    _LAST[:] = [(backend, verts.clone(), tris.clone(), structure)]
    return structure


#: The last mesh an engine searched for a plain ``mesh_sdf`` call: [(backend, verts,
#: tris, structure)]; one entry, compared exactly (``torch.equal``) before reuse.
_LAST: list = []


@torch.library.custom_op("torchgeo_cg::closest_faces", mutates_args=())
def _closest_faces_op(verts: torch.Tensor, tris: torch.Tensor, points: torch.Tensor,
                      backend: str, key: int, mode: int, progress: bool
                      ) -> tuple[torch.Tensor, torch.Tensor]:
    B, N = points.shape[:2]
    if B * N == 0:
        return (torch.zeros(B, N, dtype=torch.long, device=points.device),
                _no_distances(points))
    scaled_v, scaled_p = _scaled(verts, points)
    structure = _structure(verts, tris, scaled_v, backend, key)
    faces, sdf = _query(structure, scaled_p, backend, mode, progress)
    return faces.clone(), sdf.clone()


@_closest_faces_op.register_fake
def _(verts, tris, points, backend, key, mode, progress):
    return (points.new_empty(points.shape[:2], dtype=torch.long),
            points.new_empty(points.shape[:2], dtype=torch.float64))


@_closest_faces_op.register_vmap
def _(info, in_dims, verts, tris, points, backend, key, mode, progress):
    """Batching rule: the op is already batched over meshes, so vmapped dims join it."""
    v_dim, t_dim, p_dim = in_dims[:3]
    if t_dim is not None:
        raise ValueError("mesh_sdf: faces cannot be batched under vmap (shared topology)")
    S = info.batch_size
    if v_dim is None:  # one mesh set for every vmapped item: fold them into the points
        p = points.movedim(p_dim, 1)  # (B, S, N, 3)
        B, _, N = p.shape[:3]
        out = _closest_faces_op(verts, tris, p.reshape(B, S * N, 3), backend, key, mode,
                                progress)
        return tuple(x.reshape(B, S, N).movedim(1, 0) for x in out), (0, 0)
    v = verts.movedim(v_dim, 0)
    p = points.movedim(p_dim, 0) if p_dim is not None else points.expand(S, *points.shape)
    B = max(v.shape[1], p.shape[1])
    v, p = v.expand(S, B, *v.shape[2:]), p.expand(S, B, *p.shape[2:])
    out = _closest_faces_op(v.reshape(S * B, *v.shape[2:]), tris,
                            p.reshape(S * B, *p.shape[2:]), backend, -1, mode, progress)
    return tuple(x.reshape(S, B, -1) for x in out), (0, 0)


def search_faces(verts_bv3: torch.Tensor, tris_t3: torch.Tensor, points_bn3: torch.Tensor,
                 backend: str, key: int = -1, progress: bool = False) -> torch.Tensor:
    """Closest face ``(B, N)`` long of every point, per mesh, with a resolved ``backend``.

    ``key`` (:func:`new_cache_key`) reuses the structure built for the same vertices
    (unchanged data pointer and version); ``-1`` reuses an engine's structure only for
    exactly the mesh of the previous call.

    Example:
        >>> v = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
        >>> tris = torch.tensor([[0, 1, 2], [0, 1, 3]])
        >>> search_faces(v, tris, torch.tensor([[[0.2, 0.2, -1.0], [0.2, -1.0, 0.2]]]),
        ...              "torch")
        tensor([[0, 1]])
    """
    return _closest_faces_op(verts_bv3.detach(), tris_t3, points_bn3.detach(), backend, key,
                             0, progress)[0]


def engine_sdf(verts_bv3: torch.Tensor, tris_t3: torch.Tensor, points_bn3: torch.Tensor,
               backend: str, signed: bool, key: int = -1, progress: bool = False
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """Closest face and its distance, both from an engine's kernel (no gradient).

    The kernel evaluates the distance on the chosen face in float64 with the operations
    of :func:`~torchgeo_cg.sdf.mesh_distance.evaluate_sdf` (sign from the pseudo-normal
    of the closest feature when ``signed``), so it agrees with the torch evaluation to
    rounding; this is the path of queries that need no gradient.

    Returns:
        ``(face_ids (B, N) long, sdf (B, N))`` in the points' dtype, on their device;
        NaN for non-finite points.

    Example:
        >>> v = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
        >>> tris = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
        >>> p = torch.tensor([[[0.1, 0.2, 0.3], [0.2, 0.2, -2.0]]])
        >>> from torchgeo_cg.sdf.engines import available_engines
        >>> if "warp" in available_engines():
        ...     print(engine_sdf(v, tris, p, "warp", True)[1])
        ... else:
        ...     print(torch.tensor([[-0.1000, 2.0000]]))
        tensor([[-0.1000,  2.0000]])
    """
    verts, points = verts_bv3.detach(), points_bn3.detach()
    faces, sdf = _closest_faces_op(verts, tris_t3, points, backend, key, 2 if signed else 1,
                                   progress)
    scale = 1.0
    if verts.numel():
        scale = power_of_two_scale(verts.abs().amax((1, 2), keepdim=True)).to(torch.float64)[..., 0]
    sdf = torch.where(torch.isfinite(points).all(-1), sdf * scale, math.nan)
    return faces, sdf.to(points.dtype)
