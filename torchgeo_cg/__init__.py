"""torchgeo_cg: batched, differentiable geometry for PyTorch learning pipelines.

Subpackages, one per area:

- :mod:`torchgeo_cg.core`: the validation helper and NaN-free numerics;
- :mod:`torchgeo_cg.transforms`: homogeneous 2D transforms, scene graphs, estimation;
- :mod:`torchgeo_cg.curves`: Bezier, B-spline/NURBS, Hermite/PCHIP, parametric and 2D curves;
- :mod:`torchgeo_cg.surfaces`: Bezier, B-spline and NURBS patches, surface fits and grid meshes;
- :mod:`torchgeo_cg.sdf`: signed distance fields, grids and samplers;
- :mod:`torchgeo_cg.mesh`: marching cubes, Catmull-Clark subdivision, mesh I/O;
- :mod:`torchgeo_cg.engine`: the compiled kernel layer (NVIDIA Warp, loaded at first use);
- :mod:`torchgeo_cg.points`: exact k nearest neighbours and the Chamfer distance;
- :mod:`torchgeo_cg.rays`: exact ray casting on meshes, sphere tracing, depth images;
- :mod:`torchgeo_cg.viz` and :mod:`torchgeo_cg.cli`: the gallery and ``torchgeo-cg``.
"""

from torchgeo_cg import core, curves, engine, mesh, points, rays, sdf, surfaces, transforms
from torchgeo_cg.core import ShapeError

__version__ = "0.1.0"

__all__ = ["ShapeError", "core", "curves", "engine", "mesh", "points", "rays", "sdf",
           "surfaces", "transforms", "__version__"]
