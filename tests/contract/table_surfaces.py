"""Contract entries of tensor-product patches, their fits and grid meshes.

``ENTRIES`` join ``table.TABLE``;
``EXEMPT`` names have no geometry (result types).
"""

from __future__ import annotations

import torch

import torchgeo_cg.surfaces as S
from tests.contract.spec import Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]


def _weights(shape, g, dtype):
    return 0.5 + torch.rand(shape, generator=g, dtype=torch.float64)


def _derivs(d):
    return d.points, d.du, d.dv, d.normals


GRID = Arg("control_grid", (2, 4, 5, 3))
U = Arg("u", (6,), "inside", "unitless")
V = Arg("v", (6,), "inside", "unitless")
W = Arg("weights", (2, 4, 5), _weights, "unitless")
BAD = ((4, 5), (2, 4))
PATCH = dict(empty=((1, -1), (2, -1)), mixed="promote", low="reject", bad=BAD)
NURBS = dict(empty=((2, -1), (3, -1)), mixed="promote", low="reject", bad=BAD)
DERIVS = ("length", "length", "length", "unitless")

ENTRIES: list[Entry] = [
    Entry("surfaces.bezier_surface", S.bezier_surface, (GRID, U, V), **PATCH),
    Entry("surfaces.bezier_surface_derivatives", lambda g, u, v: _derivs(
        S.bezier_surface_derivatives(g, u, v)), (GRID, U, V), out=DERIVS, **PATCH, rtol=1e-8),
    Entry("surfaces.bspline_surface", lambda g, u, v: S.bspline_surface(g, u, v, (2, 3)),
          (GRID, U, V), **PATCH),
    Entry("surfaces.bspline_surface_derivatives", lambda g, u, v: _derivs(
        S.bspline_surface_derivatives(g, u, v, (2, 3))), (GRID, U, V), out=DERIVS, **PATCH,
          rtol=1e-8),
    Entry("surfaces.nurbs_surface", lambda g, w, u, v: S.nurbs_surface(g, w, u, v, 2),
          (GRID, W, U, V), **NURBS),
    Entry("surfaces.nurbs_surface_derivatives", lambda g, w, u, v: _derivs(
        S.nurbs_surface_derivatives(g, w, u, v, 2)), (GRID, W, U, V), out=DERIVS, **NURBS,
          rtol=1e-8),
    Entry("surfaces.BezierSurface", lambda g, u, v: S.BezierSurface(g)(u, v), (GRID, U, V),
          **{**PATCH, "mixed": "raise"}),
    Entry("surfaces.BSplineSurface", lambda g, u, v: S.BSplineSurface(g, 2)(u, v), (GRID, U, V),
          **{**PATCH, "mixed": "raise"}),
    Entry("surfaces.NURBSSurface", lambda g, w, u, v: S.NURBSSurface(g, w, 2)(u, v),
          (GRID, W, U, V), **NURBS),
    Entry("surfaces.fit_bspline_surface", lambda p: tuple(S.fit_bspline_surface(p, 2, (4, 3))),
          (Arg("points", (2, 6, 5, 3)),),
          out=("length", "unitless", "unitless", "unitless", "unitless", "length"),
          empty=(0, 0), mixed=None, low="reject", bad=((6, 5),), rtol=1e-8),
    Entry("surfaces.surface_mesh", lambda g: tuple(S.surface_mesh(S.BSplineSurface(
        g, 2, learnable=False), (4, 3))), (GRID,), out=("length", "index"), empty=(0, 0),
          mixed=None, low="reject", bad=BAD),
]

EXEMPT: dict[str, str] = {
    "surfaces.SurfaceDerivatives": "NamedTuple result type",
    "surfaces.SurfaceFit": "NamedTuple result type",
    "surfaces.SurfaceMesh": "NamedTuple result type",
}
