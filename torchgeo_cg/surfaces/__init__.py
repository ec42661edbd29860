"""Surfaces: tensor-product Bezier, B-spline and NURBS patches, their fits and grid meshes.

Built on :mod:`torchgeo_cg.curves` (the B-spline basis). Every function is batched over
leading dimensions, differentiable, and takes dtype and device from its inputs.
"""

from torchgeo_cg.surfaces.fitting import SurfaceFit, fit_bspline_surface
from torchgeo_cg.surfaces.modules import BezierSurface, BSplineSurface, NURBSSurface
from torchgeo_cg.surfaces.patches import (
    SurfaceDerivatives,
    bezier_surface,
    bezier_surface_derivatives,
    bspline_surface,
    bspline_surface_derivatives,
    nurbs_surface,
    nurbs_surface_derivatives,
)
from torchgeo_cg.surfaces.tessellation import SurfaceMesh, surface_mesh

__all__ = [
    "BezierSurface",
    "BSplineSurface",
    "NURBSSurface",
    "SurfaceDerivatives",
    "SurfaceFit",
    "SurfaceMesh",
    "bezier_surface",
    "bezier_surface_derivatives",
    "bspline_surface",
    "bspline_surface_derivatives",
    "fit_bspline_surface",
    "nurbs_surface",
    "nurbs_surface_derivatives",
    "surface_mesh",
]
