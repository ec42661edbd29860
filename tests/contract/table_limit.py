"""Contract entries of the limit surface at any (face, u, v).

The limit surface is linear in the control points: positions and derivatives are
lengths, normals unit vectors. Points (ptex ``face_ids`` and ``uv``) and the topology
are constants of each ``call``; operators are built inside it with the data's dtype.
"""

from __future__ import annotations

import torch

import torchgeo_cg.mesh as M
from tests.contract.spec import Arg, Entry
from tests.contract.table_subdivision import (
    CUBE_F,
    CUBE_V,
    GRID_F,
    GRID_V,
    NGON_F,
    NGON_V,
    OCTA_F,
    OCTA_V,
)
from torchgeo_cg.core.numerics import working_dtype

__all__ = ["ENTRIES", "EXEMPT"]

_UV = torch.tensor([[0.5, 0.5], [0.0, 0.0], [0.3, 0.9], [1.0, 0.25], [0.01, 0.6]])
_CUBE_IDS = torch.tensor([0, 1, 2, 4, 5])
_NGON_IDS = torch.tensor([0, 1, 3, 5, 8])  # the quad, the triangle's and pentagon's sub-faces
OUT4 = ("length", "length", "length", "unitless")


def _wdtype(v: torch.Tensor) -> dict:
    """Weights in the data's working dtype (float32 for half precision, as users build them)."""
    return {"dtype": working_dtype(v.dtype) if v.is_floating_point() else None}


def _sample(out) -> tuple[torch.Tensor, ...]:
    return tuple(x for x in out if x is not None)


def _surface(faces, num_vertices, ids, boundary="edge_only"):
    def call(v):
        op = M.catmull_clark_operator(faces, num_vertices, **_wdtype(v),
                                      options=M.SchemeOptions(boundary=boundary))
        uv = _UV.to(op.stencils.weights.dtype)
        return _sample(M.limit_surface(op, v, ids, uv, max_level=5))

    return call


_TRI_UV = torch.tensor([[1 / 3, 1 / 3], [0.0, 0.0], [0.3, 0.6], [1.0, 0.0], [0.01, 0.6]])


def _loop_surface(v):
    op = M.loop_operator(OCTA_F, 6, **_wdtype(v))
    uv = _TRI_UV.to(op.stencils.weights.dtype)
    return _sample(M.limit_surface(op, v, torch.tensor([0, 1, 2, 5, 7]), uv, max_level=5))


ENTRIES: list[Entry] = [
    Entry("mesh.limit_surface", _surface(CUBE_F, 8, _CUBE_IDS),
          (Arg("verts", (2, 8, 3), CUBE_V),), out=OUT4, empty=(0, 0), bad=((2, 7, 3), (3,))),
    Entry("mesh.limit_surface[boundary]", _surface(GRID_F, 9, torch.tensor([0, 1, 2, 3, 3]),
                                                   "edge_and_corner"),
          (Arg("verts", (2, 9, 3), GRID_V),), out=OUT4, empty=(0, 0), bad=((2, 8, 3),)),
    Entry("mesh.limit_surface[ngon]", _surface(NGON_F, 7, _NGON_IDS),
          (Arg("verts", (2, 7, 3), NGON_V),), out=OUT4, empty=(0, 0), bad=((2, 6, 3),)),
    Entry("mesh.limit_surface[loop]", _loop_surface,
          (Arg("verts", (2, 6, 3), OCTA_V),), out=OUT4, empty=(0, 0), bad=((2, 5, 3),)),
]

EXEMPT: dict[str, str] = {
    "mesh.LimitSurfaceSample": "result type (NamedTuple) of limit_surface",
    "mesh.LimitStencils": "result type (NamedTuple) of limit_stencils",
    "mesh.limit_stencils": "topology only (no geometry in): its stencils are under contract "
                           "through limit_surface, which applies them",
    "mesh.SurfaceSamples": "result type (NamedTuple) of sample_limit_surface",
    "mesh.sample_limit_surface": "random draws weighted by area (NaN or empty control points "
                                 "leave no area to draw from); its points are limit_surface's, "
                                 "uniformity in tests/mesh/test_limit_surface.py",
}
