"""Rays: exact ray casting on meshes, sphere tracing of SDFs, depth rendering.

Layout (one topic per file):

- :mod:`~torchgeo_cg.rays.mesh_intersect`: ``ray_mesh_intersect`` (first hit, ``RayHits``)
  and ``ray_mesh_crossings`` (parity), watertight and exact in float64, differentiable.
- :mod:`~torchgeo_cg.rays.sphere_tracing`: ``sphere_trace`` of any SDF callable, with
  implicit-function gradients.
- :mod:`~torchgeo_cg.rays.render`: ``render_depth`` (``RenderResult``): depth, normals and
  mask of a mesh or an SDF in the shape of the ray bundle.

Convention: rays are ``origins + t * directions`` with ``origins, directions (*, R, 3)``;
``t`` is in units of ``|direction|``; faces are wound counter-clockwise seen from
outside; SDFs are negative inside.
"""

from torchgeo_cg.rays.mesh_intersect import RayHits, ray_mesh_crossings, ray_mesh_intersect
from torchgeo_cg.rays.render import RenderResult, render_depth
from torchgeo_cg.rays.sphere_tracing import sphere_trace

__all__ = ["RayHits", "ray_mesh_intersect", "ray_mesh_crossings", "sphere_trace",
           "RenderResult", "render_depth"]
