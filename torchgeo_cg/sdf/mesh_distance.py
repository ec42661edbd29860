"""Signed distance from points to a triangle mesh, exact, batched and headless.

``mesh_sdf`` finds the exact closest triangle of every point with a culled search,
then signs the distance with either

- the **angle-weighted pseudo-normal** of the closest feature (face, edge or vertex),
  Baerentzen & Aanaes 2005, "Signed distance computation using the angle weighted
  pseudonormal": exact for closed, consistently oriented (watertight) meshes; or
- the **generalized winding number** ``w(p) = sum_f Omega_f(p) / 4 pi`` (Jacobson et al.
  2013), ``Omega`` the solid angle of each triangle (Van Oosterom & Strackee 1983):
  inside where ``w > 1/2``; robust for meshes with holes or flipped patches.

Search and evaluation are split. The **search** (which face is closest) is piecewise
constant and needs no gradient: the torch backend
(:mod:`~torchgeo_cg.sdf._mesh_search`, float64, exhaustive) or a compiled engine
(:mod:`~torchgeo_cg.sdf.engines`, the optional extra ``fast``) answers it. The
**evaluation** (the exact point-triangle distance, closest point and sign on that face)
runs in torch in the input dtype and device, so it is differentiable w.r.t. points and
vertices and identical whatever the backend. A query that needs no gradient and no
closest points is answered by an engine alone: its kernel evaluates the same formulas
in float64 (agreeing with the torch evaluation to rounding). :class:`MeshSDF` caches
the search structure of a mesh for repeated queries; plain calls reuse an engine's
structure for exactly the mesh of the previous call.

Convention:
    - Faces are ``(F, 3)`` vertex indices wound counter-clockwise seen from outside
      (outward normals ``(v1 - v0) x (v2 - v0)``); the SDF is negative inside.
    - Degenerate (zero-area) faces are allowed: their distance is the distance to their
      edges, and they contribute nothing to normals and winding numbers. Unreferenced
      vertices are ignored.
    - ``sign="auto"`` uses pseudo-normals on watertight meshes (every directed edge
      used once and its reverse once) and otherwise warns and uses winding numbers.
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import torch
from torch import nn

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import (
    check_broadcastable,
    check_choice,
    check_float,
    check_shape,
    check_tensor,
)
from torchgeo_cg.core.numerics import cast_back, hypot, power_of_two_scale, working_dtype
from torchgeo_cg.mesh.faces import check_mesh
from torchgeo_cg.sdf._closest_faces import (
    engine_sdf,
    new_cache_key,
    resolve_backend,
    search_faces,
)
from torchgeo_cg.sdf._mesh_search import far_radius, pull_in_far_points
from torchgeo_cg.sdf._triangle import (
    closest_point_on_triangle,
    dot3,
    pseudo_normals,
    solid_angles_sum,
)

__all__ = ["MeshSDFResult", "MeshSDF", "is_watertight", "winding_number", "mesh_sdf"]

class MeshSDFResult(NamedTuple):
    """Result of :func:`mesh_sdf`; fields not asked for are ``None``.

    Attributes:
        sdf: ``(*, N)`` signed distances (negative inside; unsigned with ``sign="none"``).
        closest_points: ``(*, N, 3)`` closest points on the mesh, or ``None``.
        face_ids: ``(*, N)`` long index of the closest face, or ``None``.
    """

    sdf: torch.Tensor
    closest_points: torch.Tensor | None
    face_ids: torch.Tensor | None


def is_watertight(faces: torch.Tensor, num_vertices: int | None = None) -> bool:
    """Whether every directed edge occurs exactly once and its reverse exactly once.

    That is: closed (no boundary), edge-manifold and consistently oriented, the
    condition under which pseudo-normal signs are exact.

    Args:
        faces: ``(F, 3)`` integer vertex indices.
        num_vertices: ``V`` (default ``faces.max() + 1``).

    Returns:
        ``bool``.

    Example:
        >>> tet = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
        >>> is_watertight(tet), is_watertight(tet[:3])
        (True, False)
    """
    check_tensor(faces, "faces")
    check_shape(faces, ["F", "3"], "faces")
    if faces.shape[0] == 0:
        return False
    n = int(faces.max()) + 1 if num_vertices is None else int(num_vertices)
    f = faces.long()
    heads = f.reshape(-1)
    tails = f[:, [1, 2, 0]].reshape(-1)
    key = heads * n + tails
    rev = tails * n + heads
    if torch.unique(key).numel() != key.numel():
        return False
    return bool(torch.isin(rev, key).all())


def winding_number(
    verts: torch.Tensor,
    faces: torch.Tensor,
    points: torch.Tensor,
    chunk: int = 1 << 22,
    backend: str = "auto",
) -> torch.Tensor:
    """Generalized winding number of a triangle mesh at each point (brute force, chunked).

    ``w(p) = (1 / 4 pi) sum_f Omega_f(p)``, ``tan(Omega / 2) = det[a b c] / (|a||b||c| +
    (a.b)|c| + (a.c)|b| + (b.c)|a|)`` with ``a, b, c`` the corners minus ``p``.
    It is 1 inside and 0 outside a closed outward mesh, and degrades gracefully
    (fractional values) around holes. Cost ``O(N F)``, chunked to ``chunk`` point-face
    pairs at a time. Coordinates are divided by a power of two (exact) so that the
    triple products neither overflow nor underflow at any scale.

    Convention:
        Outward (counter-clockwise) faces give ``w = 1`` inside. Not differentiated
        (computed without a graph). Batched meshes share one topology: ``vertices
        (*, V, 3)`` and ``points (*, N, 3)`` with broadcasting batch dims, as a loop over
        the batch would give. Polygon faces are fan-triangulated.

    Args:
        verts: ``(V, 3)`` or ``(*, V, 3)``.
        faces: ``(F, K)`` integer, ``K >= 3`` (padded with ``-1``).
        points: ``(*, N, 3)``.
        chunk: maximal number of point-face pairs per step, a positive int (``ValueError``
            otherwise).
        backend: ``"auto"``, ``"torch"`` or an engine name; every backend computes the
            exact brute-force sum in torch today (validated like :func:`mesh_sdf`'s).

    Returns:
        ``(*, N)`` winding numbers, dtype of ``points`` (the vertices follow it;
        float16/bfloat16 are computed in float32), empty for ``N = 0``.

    Example:
        >>> tet = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        >>> winding_number(verts, tet, torch.tensor([[0.1, 0.1, 0.1], [1.0, 1.0, 1.0]])).abs()
        tensor([1., 0.])
    """
    tris = check_mesh(verts, faces)
    check_float(points, "points")
    check_shape(points, ["*", "N", "3"], "points")
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"chunk: expected a positive number of point-face pairs, got {chunk!r}")
    resolve_backend(backend)
    verts_bv3, points_bn3, lead = _batch_mesh_points(verts, points)
    work = working_dtype(points.dtype)  # float16/bfloat16: computed in float32
    with torch.no_grad():
        scale = power_of_two_scale(verts_bv3.to(work).abs().amax((1, 2), keepdim=True))
        tri = _gather_triangles(verts_bv3.detach().to(work) / scale, tris)
        total = solid_angles_sum(tri, points_bn3.detach().to(work) / scale, chunk)
    return cast_back((total / (4.0 * math.pi)).reshape(lead), points.dtype)


def _batch_mesh_points(verts: torch.Tensor, points: torch.Tensor):
    """Flatten a mesh batch and a point batch to ``(B, V, 3)``, ``(B, N, 3)`` and the result's
    leading shape ``(*, N)``.

    Unbatched ``verts (V, 3)`` give ``B = 1`` and all points in one item; batched
    vertices broadcast their batch dims against those of ``points``.

    Example:
        >>> v, p, lead = _batch_mesh_points(torch.zeros(2, 4, 3), torch.zeros(5, 3))
        >>> v.shape, p.shape, lead
        (torch.Size([2, 4, 3]), torch.Size([2, 5, 3]), (2, 5))
    """
    V, N = verts.shape[-2], points.shape[-2]
    if verts.dim() == 2:
        return (verts[None], points.reshape(1, points.shape[:-1].numel(), 3),
                tuple(points.shape[:-1]))
    batch = check_broadcastable({"verts": verts.shape[:-2], "points": points.shape[:-2]})
    B = math.prod(batch)
    verts = verts.expand(*batch, V, 3).reshape(B, V, 3)
    pts = points.expand(*batch, N, 3).reshape(B, N, 3)
    return verts, pts, (*batch, N)


def _gather_triangles(verts_bv3: torch.Tensor, tris_t3: torch.Tensor,
                     face_ids_bn: torch.Tensor | None = None) -> torch.Tensor:
    """Corners ``(B, T, 3, 3)`` of every triangle, or ``(B, N, 3, 3)`` of the triangles
    ``face_ids_bn (B, N)``; differentiable w.r.t. the vertices.

    Example:
        >>> _gather_triangles(torch.eye(3)[None], torch.tensor([[0, 1, 2]])).shape
        torch.Size([1, 1, 3, 3])
    """
    B = verts_bv3.shape[0]
    idx = tris_t3 if face_ids_bn is None else tris_t3[face_ids_bn]  # (T, 3) | (B, N, 3)
    idx = idx.expand(B, *idx.shape[-2:]) if idx.dim() == 2 else idx
    K = idx.shape[-2]
    flat = idx.reshape(B, 3 * K, 1).expand(-1, -1, 3)
    return torch.gather(verts_bv3, 1, flat).reshape(B, K, 3, 3)

def _resolve_sign(sign: str, tris_t3: torch.Tensor, num_vertices: int) -> str:
    """``"auto"`` -> ``"pseudonormal"`` on watertight meshes, else a warning and
    ``"winding"``; other values are validated and returned.

    Example:
        >>> _resolve_sign("none", torch.tensor([[0, 1, 2]]), 3)
        'none'
    """
    check_choice(sign, ("auto", "pseudonormal", "winding", "none"), "sign")
    if sign != "auto":
        return sign
    if is_watertight(tris_t3, num_vertices):
        return "pseudonormal"
    warnings.warn("mesh_sdf: the mesh is not watertight; using generalized winding "
                  "number signs", RuntimeWarning, stacklevel=3)
    return "winding"


def _evaluate_sdf(verts_bv3: torch.Tensor, tris_t3: torch.Tensor, points_bn3: torch.Tensor,
                 face_ids_bn: torch.Tensor, sign: str, normals_bt73: torch.Tensor | None = None
                 ) -> tuple[torch.Tensor, torch.Tensor]:
    """Exact signed distance and closest point on the given faces, in torch: ``(sdf (B, N),
    closest (B, N, 3))``, differentiable w.r.t. points and vertices.

    Coordinates are divided by a power of two per mesh (exact, detached) so that no
    product overflows or underflows, whatever the scale; results are scaled back.
    ``normals_bt73`` are the mesh's :func:`pseudo_normals` (computed when ``None``).

    Example:
        >>> v = torch.eye(3, dtype=torch.float64)[None]
        >>> sdf, q = _evaluate_sdf(v, torch.tensor([[0, 1, 2]]), v.new_zeros(1, 1, 3),
        ...                       torch.tensor([[0]]), "none")
        >>> sdf
        tensor([[0.5774]], dtype=torch.float64)
    """
    dtype = points_bn3.dtype
    if points_bn3.numel() == 0:  # empty in, empty out (still attached to the inputs)
        empty = points_bn3 * 0 + verts_bv3[:, :1].to(dtype) * 0
        return empty.sum(-1), empty
    scale = power_of_two_scale(verts_bv3.abs().amax((1, 2), keepdim=True)).to(dtype)  # (B, 1, 1)
    vn, pn = verts_bv3.to(dtype) / scale, points_bn3 / scale
    tri = _gather_triangles(vn, tris_t3, face_ids_bn)  # (B, N, 3, 3)
    near = pull_in_far_points(pn)  # the feature as seen from far; measured from pn below
    cp = closest_point_on_triangle(near, tri[..., 0, :], tri[..., 1, :], tri[..., 2, :])
    diff = pn - cp.points
    dist = hypot(*diff.unbind(-1))  # overflow-safe (far points); zero gradient at exactly 0
    if sign == "pseudonormal":
        with torch.no_grad():
            if normals_bt73 is None:
                normals_bt73 = pseudo_normals(_gather_triangles(vn.detach(), tris_t3), tris_t3,
                                              verts_bv3.shape[1])
            B, T = normals_bt73.shape[:2]
            rows = torch.arange(B, device=face_ids_bn.device)[:, None] * (T * 7)
            flat = (rows + face_ids_bn * 7 + cp.feature).reshape(-1)
            table = normals_bt73.to(dtype).reshape(B * T * 7, 3).t()  # (3, B T 7)
            normal = [table[k].index_select(0, flat).reshape(face_ids_bn.shape)
                      for k in range(3)]
            inside = dot3(diff.detach().unbind(-1), normal) < 0
        dist = torch.where(inside, -dist, dist)
    elif sign == "winding":
        with torch.no_grad():
            tri_all = _gather_triangles(vn.detach(), tris_t3)
            inside = solid_angles_sum(tri_all, pn.detach(), 1 << 22) > 2.0 * math.pi
        dist = torch.where(inside, -dist, dist)
    return dist * scale[..., 0], cp.points * scale


def _cast_result(result: MeshSDFResult, dtype: torch.dtype) -> MeshSDFResult:
    """``result`` with its float fields cast back to ``dtype`` (saturating, see
    :func:`~torchgeo_cg.core.numerics.cast_back`)."""
    return result._replace(sdf=cast_back(result.sdf, dtype), closest_points=None
                           if result.closest_points is None
                           else cast_back(result.closest_points, dtype))


def mesh_sdf(
    verts: torch.Tensor,
    faces: torch.Tensor,
    points: torch.Tensor,
    sign: str = "auto",
    return_closest: bool = False,
    backend: str = "auto",
    progress: bool = False,
) -> MeshSDFResult:
    """Exact signed distance from points to a triangle mesh (module docstring: method).

    Convention:
        Negative inside; faces wound counter-clockwise seen from outside. Distances are
        Euclidean and exact up to floating point (the search is exhaustive, not
        approximate). ``sdf`` and ``closest_points`` are differentiable w.r.t. ``points``
        and ``verts`` (the face choice and the sign are piecewise constant), also
        under ``torch.func.vmap``/``jacrev``. Batched meshes share one topology:
        ``verts (*, V, 3)`` with ``points (*, N, 3)`` (batch dims broadcast) gives what
        a loop over the batch would. Polygon faces ``(F, K)`` padded with ``-1`` are
        fan-triangulated (:func:`~torchgeo_cg.mesh.faces.triangulate_faces`); face ids
        index those triangles. Scale-free: every guard is relative to the mesh's box
        (coordinates are divided by a power of two), so a mesh and points scaled by any
        ``s`` give the distances scaled by ``s``. NaN points give NaN; no points give
        empty results. Results have the dtype of ``points``: the mesh follows it, as
        parameters follow the main input (float64 vertices from a file with float32
        points give float32 distances); float16/bfloat16 are computed in float32 and
        returned in the input dtype.

    Backends: ``"torch"`` searches on the CPU in float64 (inputs on another device make
    a round trip; results come back on the input device and dtype). An engine (``"warp"``,
    the optional extra ``pip install torchgeo_cg[fast]``) finds the closest face in
    float32, on the input's device (CUDA stays on CUDA), then checks the faces around it
    in float64. Where gradients or closest points are needed, the distance, closest point
    and sign are then computed in torch from that face; otherwise the engine's kernel
    evaluates the same formulas in float64. Either way the backends agree to rounding.
    ``"auto"`` picks the fastest installed engine, else torch.

    Args:
        verts: ``(V, 3)`` or ``(*, V, 3)`` float, finite.
        faces: ``(F, 3)`` (or ``(F, K)`` polygons padded with ``-1``) integer indices
            into ``verts``; ``F >= 1``.
        points: ``(*, N, 3)`` float query points.
        sign: ``"auto"`` (pseudo-normal if watertight, else a warning and winding
            numbers), ``"pseudonormal"``, ``"winding"`` or ``"none"`` (unsigned).
        return_closest: also return the closest points and face ids.
        backend: ``"auto"``, ``"torch"`` or an engine name (:data:`ENGINES`).
        progress: show a tqdm progress bar over the search.

    Returns:
        :class:`MeshSDFResult` ``(sdf (*, N), closest_points (*, N, 3) | None,
        face_ids (*, N) | None)``.

    Raises:
        ValueError: empty mesh, non-finite vertices, out-of-range faces, bad ``sign`` or
            ``backend``.
        ImportError: an engine named in ``backend`` is not installed.
        ShapeError: wrong shapes.
        TypeError: integer inputs.

    Example:
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        >>> tet = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
        >>> r = mesh_sdf(verts, tet, torch.tensor([[0.1, 0.2, 0.3], [0.2, 0.2, -2.0]]),
        ...              return_closest=True)
        >>> r.sdf, r.face_ids
        (tensor([-0.1000,  2.0000]), tensor([3, 0]))
    """
    tris = check_mesh(verts, faces)
    check_float(points, "points")
    check_shape(points, ["*", "N", "3"], "points")
    if working_dtype(points.dtype) != points.dtype:  # float16/bfloat16: computed in float32
        work = working_dtype(points.dtype)
        return _cast_result(mesh_sdf(verts.to(work), faces, points.to(work), sign,
                                    return_closest, backend, progress), points.dtype)
    sign = _resolve_sign(sign, tris, verts.shape[-2])
    engine = resolve_backend(backend)
    verts_bv3, points_bn3, lead = _batch_mesh_points(verts, points)
    sdf, closest, face_ids = _search_and_evaluate(verts_bv3, tris, points_bn3, engine, sign,
                                                 return_closest, -1, progress)
    return MeshSDFResult(sdf.reshape(lead), closest.reshape(*lead, 3) if return_closest else None,
                         face_ids.reshape(lead) if return_closest else None)


def _has_far_points(verts_bv3: torch.Tensor, points_bn3: torch.Tensor) -> bool:
    """Points beyond :func:`~torchgeo_cg.sdf._mesh_search.far_radius` of the mesh (relative
    to its size): the search pulls them in, so the engine's kernel would measure from the
    pulled-in point; they take the torch evaluation, which measures from the point itself
    (rare; a cheap check)."""
    if points_bn3.numel() == 0:
        return False
    scale = power_of_two_scale(verts_bv3.abs().amax((1, 2), keepdim=True)).to(torch.float64)
    top = (points_bn3.detach().abs().amax(-1) / scale[..., 0]).nan_to_num(0.0)
    try:
        return bool((top > far_radius(torch.float64)).any())
    except RuntimeError:  # no data-dependent branch possible (vmap): the torch path
        return True


def _search_and_evaluate(verts_bv3: torch.Tensor, tris_t3: torch.Tensor,
                        points_bn3: torch.Tensor, engine: str, sign: str,
                        return_closest: bool, key: int, progress: bool):
    """The closest face of every point, then the signed distance on it: ``(sdf (B, N),
    closest (B, N, 3) | None, face_ids (B, N))``.

    With an engine, a query that needs no gradient and no closest points (and signs by
    pseudo-normals or not at all) is answered by the engine's kernel alone, which
    evaluates the same formulas as :func:`_evaluate_sdf` in float64; otherwise the
    distance is evaluated in torch from the face found, where gradients flow.
    """
    needs_grad = records_graph(verts_bv3, points_bn3)
    if (engine != "torch" and sign in ("pseudonormal", "none") and not return_closest
            and not needs_grad and not _has_far_points(verts_bv3, points_bn3)):
        face_ids, sdf = engine_sdf(verts_bv3, tris_t3, points_bn3, engine,
                                   sign == "pseudonormal", key, progress)
        return sdf, None, face_ids
    face_ids = search_faces(verts_bv3, tris_t3, points_bn3, engine, key, progress)
    sdf, closest = _evaluate_sdf(verts_bv3, tris_t3, points_bn3, face_ids, sign)
    return sdf, closest, face_ids


class MeshSDF(nn.Module):
    """:func:`mesh_sdf` against a fixed mesh, its search structure (the engine's BVH or the
    torch grids) built once and reused by every query.

    The mesh is stored as buffers (``verts``, ``faces``: the triangles), so the module
    follows ``.to()``, ``state_dict`` and ``deepcopy``; the structure is rebuilt only when
    the vertices change (new data or an in-place edit) or move. Under ``torch.compile`` the
    structure is built in each call (the cache's bookkeeping is not part of a graph).

    Convention:
        As :func:`mesh_sdf` (negative inside, outward counter-clockwise faces, same
        defaults, same dtype policy: results have the dtype of the query points).
        ``verts`` may be batched ``(*, V, 3)``.

    Args:
        verts: ``(V, 3)`` or ``(*, V, 3)`` float, finite.
        faces: ``(F, K)`` integer (polygons are fan-triangulated).
        sign: as :func:`mesh_sdf` (``"auto"`` is resolved here, once).
        backend: ``"auto"``, ``"torch"`` or an engine name.

    Example:
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        >>> tet = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
        >>> MeshSDF(verts, tet, backend="torch")(torch.tensor([[0.1, 0.2, 0.3]])).sdf
        tensor([-0.1000])
    """

    def __init__(self, verts: torch.Tensor, faces: torch.Tensor, sign: str = "auto",
                 backend: str = "auto") -> None:
        super().__init__()
        tris = check_mesh(verts, faces)
        self.sign = _resolve_sign(sign, tris, verts.shape[-2])
        resolve_backend(backend)
        self.backend = backend
        self.register_buffer("verts", verts.detach().clone())
        self.register_buffer("faces", tris.clone())
        self._search_key = (None, -1)

    def _cache_key(self) -> int:
        # bookkeeping (a weakref finalizer), not part of any graph: a compiled call
        # searches without the cache (torch.compiler.disable here would import Dynamo,
        # 1.9 s, with the package)
        if torch.compiler.is_compiling():
            return -1
        if self._search_key[0] != id(self):  # first use, or a deepcopy
            self._search_key = (id(self), new_cache_key(self))
        return self._search_key[1]

    def forward(self, points: torch.Tensor, return_closest: bool = False,
                progress: bool = False) -> MeshSDFResult:
        """Signed distances of ``points (*, N, 3)``: :class:`MeshSDFResult`."""
        check_float(points, "points")
        check_shape(points, ["*", "N", "3"], "points")
        if working_dtype(points.dtype) != points.dtype:  # float16/bfloat16: in float32
            work = working_dtype(points.dtype)
            return _cast_result(mesh_sdf(self.verts.to(work), self.faces, points.to(work),
                                        self.sign, return_closest, self.backend, progress),
                               points.dtype)
        engine = resolve_backend(self.backend)
        verts_bv3, points_bn3, lead = _batch_mesh_points(self.verts, points)
        same_meshes = verts_bv3.shape[0] == self.verts.shape[:-2].numel()
        key = self._cache_key() if same_meshes else -1  # broadcast copies are not cached
        sdf, closest, face_ids = _search_and_evaluate(verts_bv3, self.faces, points_bn3, engine,
                                                     self.sign, return_closest, key, progress)
        return MeshSDFResult(sdf.reshape(lead),
                             closest.reshape(*lead, 3) if return_closest else None,
                             face_ids.reshape(lead) if return_closest else None)
