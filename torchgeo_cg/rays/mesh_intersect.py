"""Exact, watertight, batched and differentiable ray casting on triangle meshes.

``ray_mesh_intersect`` finds the first face each ray hits; ``ray_mesh_crossings`` counts
the crossings (parity: inside or outside a closed mesh). The search decides in float64
with the watertight ray-triangle test of Woop, Benthin and Wald (2013), after an exact
power-of-two scaling (as :func:`torchgeo_cg.sdf.mesh_sdf` does), with exact signs and one
symbolic tie rule; torch then computes the hit on the chosen face, closed-form in its
corners, so gradients flow to the vertices, the origins and the directions.

Convention:
    - Rays are ``origins + t * directions``, ``t`` in units of ``|direction|`` (a
      distance for unit directions); directions need not be unit.
    - Faces are wound counter-clockwise seen from outside; ``normals`` are the unit
      geometric normals ``(v1 - v0) x (v2 - v0)`` of that winding, *not* flipped toward
      the ray: ``normals . direction < 0`` on a front face (outward normals, rays from
      outside), ``> 0`` on a back face.
    - ``bary`` are the weights of the face's corners ``(v0, v1, v2)``: the point is
      ``bary @ corners``.
    - A ray that crosses a closed mesh exactly through an edge or a vertex hits one of
      the faces that meet there (it never falls through); a ray that only touches the
      surface there may miss. Ties in ``t`` (under the test's arithmetic) go to the
      smaller face index; the result does not depend on the order of the rays.
    - No hit: ``hit`` False, ``t = inf``, ``face = -1``, zeros elsewhere. A ray with a
      zero direction hits nothing; a NaN or inf in a ray gives ``t``, ``points`` NaN.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.engine import resolve_backend
from torchgeo_cg.rays._evaluate import hit_geometry
from torchgeo_cg.rays._prepare import RayProblem, check_limits, prepare
from torchgeo_cg.rays._search import crossings, first_hits

__all__ = ["RayHits", "ray_mesh_intersect", "ray_mesh_crossings"]


class RayHits(NamedTuple):
    """First hits of a ray bundle (:func:`~torchgeo_cg.rays.ray_mesh_intersect`,
    :func:`~torchgeo_cg.rays.sphere_trace`).

    Attributes:
        hit: ``(*, R)`` bool, a hit in ``[t_min, t_max]``.
        t: ``(*, R)`` ray parameter of the hit (``inf`` without hit, NaN for a NaN ray).
        face: ``(*, R)`` long index of the face hit, ``-1`` without hit (always ``-1``
            for :func:`~torchgeo_cg.rays.sphere_trace`).
        bary: ``(*, R, 3)`` barycentric weights of the face's corners (0 without hit).
        points: ``(*, R, 3)`` the hit points ``origins + t * directions`` (0 without hit).
        normals: ``(*, R, 3)`` unit normals at the hits (0 without hit); see each
            function's convention for their orientation.
    """

    hit: torch.Tensor
    t: torch.Tensor
    face: torch.Tensor
    bary: torch.Tensor
    points: torch.Tensor
    normals: torch.Tensor


def _gather_corners(verts_bv3: torch.Tensor, tris: torch.Tensor, face_br: torch.Tensor
                    ) -> torch.Tensor:
    """``(B, R, 3, 3)`` corners of the faces ``face_br`` (differentiable)."""
    B, R = face_br.shape
    idx = tris[face_br].reshape(B, R * 3, 1).expand(-1, -1, 3)
    return torch.gather(verts_bv3, 1, idx).reshape(B, R, 3, 3)


def _evaluate(prob: RayProblem, face: torch.Tensor, t_scaled: torch.Tensor) -> RayHits:
    """The differentiable hits of the chosen faces (see ``torchgeo_cg.rays._evaluate``)."""
    dtype = prob.origins.dtype
    work = working_dtype(dtype)
    hit = face >= 0
    s, sd = prob.scale.to(work), prob.dscale.to(work)
    tri = _gather_corners(prob.verts.to(work), prob.tris, torch.where(hit, face, 0)) / s[..., None]
    o, d = prob.origins.to(work), prob.directions.to(work)
    t1, b1, b2, normals = hit_geometry(tri, o / s, d / sd, hit, t_scaled.to(work))
    ratio = (prob.scale / prob.dscale).squeeze(-1).to(work)  # t = t' s / s_d, exact
    t = torch.where(hit, t1 * ratio, torch.inf)
    t = torch.where(prob.bad, torch.nan, t)
    points = torch.where(hit[..., None], o + t1[..., None] * ratio[..., None] * d, 0.0)
    points = torch.where(prob.bad[..., None], torch.nan, points)
    bary = torch.where(hit[..., None], torch.stack([1 - b1 - b2, b1, b2], -1), 0.0)
    lead = prob.lead
    return RayHits(hit.reshape(lead), cast_back(t, dtype).reshape(lead), face.reshape(lead),
                   cast_back(bary, dtype).reshape(*lead, 3),
                   cast_back(points, dtype).reshape(*lead, 3),
                   cast_back(normals, dtype).reshape(*lead, 3))


def ray_mesh_intersect(verts: torch.Tensor, faces, origins: torch.Tensor,
                       directions: torch.Tensor, *, t_min: float = 0.0,
                       t_max: float = math.inf, backend: str = "auto") -> RayHits:
    """The first hit of every ray on a triangle mesh, exact and watertight.

    Convention:
        See :mod:`torchgeo_cg.rays.mesh_intersect`: ``t`` in units of ``|direction|``;
        ``normals`` are the unit normals of the faces' winding (outward for a closed,
        outward-wound mesh), not flipped toward the ray; ties go to the smaller face
        index. Batched meshes ``(*, V, 3)`` share ``faces`` and broadcast their batch
        dims against the rays' ``(*, R)``; unbatched vertices serve every ray.

    Args:
        verts: ``(V, 3)`` or ``(*, V, 3)`` vertices (differentiable).
        faces: ``(F, K)`` integer faces, ``K >= 3`` (polygons fan-triangulated, padded
            with ``-1``; face ids index the triangles).
        origins: ``(*, R, 3)`` ray origins (differentiable; broadcasts with directions).
        directions: ``(*, R, 3)`` ray directions, any nonzero length (differentiable).
        t_min: smallest ``t`` of a hit (finite).
        t_max: largest ``t`` of a hit.
        backend: the search: ``"torch"``, ``"warp"`` (one compiled kernel, the same
            float64 arithmetic, identical results) or ``"auto"`` (Warp when it loads).

    Returns:
        :class:`~torchgeo_cg.rays.RayHits` ``(hit, t, face, bary, points, normals)``,
        shapes ``(*, R)`` and ``(*, R, 3)``, dtype of the inputs (float16/bfloat16 evaluated
        in float32).

    Raises:
        ShapeError: an argument of the wrong shape (named), or batches that do not
            broadcast.
        TypeError: non-float or mixed dtypes.
        ValueError: ``t_min`` not finite or above ``t_max``; a bad mesh, or NaN or inf
            vertex coordinates (which face a ray would hit is then unknown).

    Example:
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        >>> tet = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
        >>> o = torch.tensor([[0.2, 0.2, 2.0], [0.2, 0.2, 0.2], [5.0, 5.0, 5.0]])
        >>> d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
        >>> hits = ray_mesh_intersect(verts, tet, o, d)
        >>> hits.hit, hits.t, hits.face
        (tensor([ True,  True, False]), tensor([1.4000, 0.4000,    inf]), tensor([ 2,  2, -1]))
        >>> hits.normals[0]
        tensor([0.5774, 0.5774, 0.5774])
    """
    check_limits(t_min, t_max)
    prob = prepare(verts, faces, origins, directions)
    resolve_backend(backend, prob.origins.device)  # validated before any work
    face, t_scaled = first_hits(prob, t_min, t_max, backend)
    return _evaluate(prob, face, t_scaled)


def ray_mesh_crossings(verts: torch.Tensor, faces, origins: torch.Tensor,
                       directions: torch.Tensor, *, t_min: float = 0.0,
                       t_max: float = math.inf) -> torch.Tensor:
    """How many times each ray crosses the mesh in ``[t_min, t_max]``.

    Each crossing is counted once, however many faces meet at the crossing point: the
    test's symbolic perturbation of the ray (see :mod:`torchgeo_cg.rays.mesh_intersect`)
    gives a shared edge or vertex to exactly one of the faces a ray crosses there, and
    to none or two of those it only touches. For a closed mesh the count is even from a
    point outside and odd from a point inside.

    Convention:
        As :func:`~torchgeo_cg.rays.ray_mesh_intersect`; not differentiable (integers).

    Args:
        verts: ``(V, 3)`` or ``(*, V, 3)`` vertices.
        faces: ``(F, K)`` integer faces.
        origins: ``(*, R, 3)`` ray origins.
        directions: ``(*, R, 3)`` ray directions.
        t_min: smallest ``t`` counted (finite).
        t_max: largest ``t`` counted.

    Returns:
        ``(*, R)`` long counts (0 for zero, NaN or inf rays).

    Raises:
        As :func:`~torchgeo_cg.rays.ray_mesh_intersect`.

    Example:
        >>> verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        >>> tet = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
        >>> d = torch.tensor([[1.0, 1.0, 1.0]])
        >>> ray_mesh_crossings(verts, tet, torch.tensor([[-1.0, -1.0, -1.0]]), d)
        tensor([2])
        >>> ray_mesh_crossings(verts, tet, torch.tensor([[0.1, 0.1, 0.1]]), d)
        tensor([1])
    """
    check_limits(t_min, t_max)
    prob = prepare(verts, faces, origins, directions)
    return crossings(prob, t_min, t_max).reshape(prob.lead)
