"""Rays: exact ray casting on meshes, sphere tracing of SDFs, depth rendering.

Layout (one topic per file):

- :mod:`~torchgeo_cg.rays.mesh_intersect`: ``ray_mesh_intersect`` (first hit, ``RayHits``)
  and ``ray_mesh_crossings`` (parity), watertight and exact in float64, differentiable.

Convention: rays are ``origins + t * directions`` with ``origins, directions (*, R, 3)``;
``t`` is in units of ``|direction|``; faces are wound counter-clockwise seen from
outside; SDFs are negative inside.
"""

from torchgeo_cg.rays.mesh_intersect import RayHits, ray_mesh_crossings, ray_mesh_intersect

__all__ = ["RayHits", "ray_mesh_intersect", "ray_mesh_crossings"]
