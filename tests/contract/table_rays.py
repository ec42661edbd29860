"""Contract entries of rays: ray casting on meshes, sphere tracing, depth rendering.

The mesh is a jittered octahedron (fixed topology ``OCTA``, a closed surface) and the
ray origins lie near its centre, inside it, so every ray hits (finite outputs) whatever
its direction; the same holds for the sphere of the traced entries.
"""

from __future__ import annotations

import torch

import torchgeo_cg.rays as Y
from tests.contract.spec import Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]

#: Octahedron on the axes (0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z), counter-clockwise outside.
OCTA = torch.tensor([[0, 2, 4], [1, 4, 2], [0, 4, 3], [1, 3, 4],
                     [0, 5, 2], [1, 2, 5], [0, 3, 5], [1, 5, 3]])
_AXES = torch.tensor([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                     dtype=torch.float64)


def _octahedron(shape, g, dtype):
    radius = 0.8 + 0.4 * torch.rand(*shape[:-1], 1, generator=g, dtype=torch.float64)
    return _AXES * radius + 0.05 * torch.randn(shape, generator=g, dtype=torch.float64)


def _inside(shape, g, dtype):
    """Origins within 0.25 of the centre: inside the octahedra and the unit sphere."""
    return 0.1 * torch.randn(shape, generator=g, dtype=torch.float64).clamp(-2.5, 2.5)


ORIGINS = Arg("origins", (2, 5, 3), _inside)
DIRECTIONS = Arg("directions", (2, 5, 3))
VERTS = Arg("verts", (2, 6, 3), _octahedron)
BAD_RAYS = ((2, 5, 2), (3, 5, 4))
_EMPTY = ((0, -2), (1, -2))
_FIELD = "the SDF is a callable closing over the radius; the rays' batch is tested by " \
         "ray_mesh_intersect's entries"


def _intersect(backend: str):
    def call(origins, directions, verts):
        h = Y.ray_mesh_intersect(verts, OCTA, origins, directions, backend=backend)
        return h.t, h.bary, h.points, h.normals

    return call


def _crossings(origins, directions, verts):
    return Y.ray_mesh_crossings(verts, OCTA, origins, directions)


def _trace(origins, directions, radius):
    h = Y.sphere_trace(lambda p: (p * p).sum(-1).sqrt() - radius, origins, directions,
                       t_max=10.0)
    return h.t, h.points, h.normals


def _render(origins, directions, verts):
    r = Y.render_depth((verts, OCTA), origins, directions)
    return r.depth, r.normals


ENTRIES = [
    Entry("rays.ray_mesh_intersect", _intersect("torch"), (ORIGINS, DIRECTIONS, VERTS),
          out=("unitless", "unitless", "length", "unitless"), empty=_EMPTY, bad=BAD_RAYS,
          bad_arg=1, rtol=1e-9),
    # "auto": the Warp kernel when Warp loads (the same decisions), else torch
    Entry("rays.ray_mesh_intersect[auto]", _intersect("auto"), (ORIGINS, DIRECTIONS, VERTS),
          out=("unitless", "unitless", "length", "unitless"), empty=_EMPTY, bad=BAD_RAYS,
          bad_arg=1, rtol=1e-9),
    # integer counts: a NaN ray crosses nothing (0, documented), there is no NaN to return
    Entry("rays.ray_mesh_crossings", _crossings, (ORIGINS, DIRECTIONS, VERTS), out="index",
          empty=_EMPTY, bad=BAD_RAYS, bad_arg=1, nan="skip"),
    Entry("rays.sphere_trace", _trace,
          (Arg("origins", (5, 3), _inside), Arg("directions", (5, 3)),
           Arg("radius", (1,), "positive")),
          out=("unitless", "length", "unitless"), empty=_EMPTY, bad=((5, 2), (4, 3)),
          bad_arg=1, cross=_FIELD, rtol=1e-9),
    Entry("rays.render_depth", _render, (ORIGINS, DIRECTIONS, VERTS),
          out=("unitless", "unitless"), empty=_EMPTY, bad=BAD_RAYS, bad_arg=1),
]

EXEMPT: dict[str, str] = {
    "rays.RayHits": "NamedTuple result type",
    "rays.RenderResult": "NamedTuple result type",
}
