"""Contract entries of :func:`torchgeo_cg.mesh.sparse_marching_cubes`.

The one tensor input is ``bounds``; the field is a sphere placed in the bounds, so
scaling the bounds by ``s`` scales the exact SDF, and with it the vertices, by ``s``.
"""

from __future__ import annotations

import torchgeo_cg.mesh as M
from tests.contract.spec import Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]


def _sparse(**kw):
    def call(bounds):
        lo, hi = bounds[0], bounds[1]
        radius, centre = 0.35 * (hi - lo).amin(), 0.5 * (lo + hi)
        field = lambda p: (p - centre).norm(dim=1) - radius  # noqa: E731
        return tuple(M.sparse_marching_cubes(field, bounds, 9, block=2, **kw))

    return call


OUT = ("length", "index", "unitless", "unitless", "index", "index")
BOUNDS = Arg("bounds", (2, 3), "bounds")
BAD = ((3, 3), (2, 4), (2, 3, 1))
NO_BATCH = "bounds take no batch, and the call reads its rows"

ENTRIES: list[Entry] = [
    Entry("mesh.sparse_marching_cubes", _sparse(), (BOUNDS,), out=OUT, empty=None, bad=BAD,
          mixed=None, low="reject", nan="raise", cross=NO_BATCH),
    Entry("mesh.sparse_marching_cubes[band]", _sparse(lipschitz=None, band=1), (BOUNDS,),
          out=OUT, empty=None, bad=BAD, mixed=None, low="reject", nan="raise", cross=NO_BATCH),
    Entry("mesh.sparse_marching_cubes[separate]", _sparse(ambiguity="separate"), (BOUNDS,),
          out=OUT, empty=None, bad=BAD, mixed=None, low="reject", nan="raise", cross=NO_BATCH),
]

EXEMPT: dict[str, str] = {
    "mesh.lipschitz_bound": "takes an nn.Module and returns a float (no tensor input); "
    "tests/mesh/test_sparse_marching_cubes.py checks it against sampled slopes and SVDs",
}
