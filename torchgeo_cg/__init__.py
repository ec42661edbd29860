"""torchgeo_cg: batched, differentiable geometry for PyTorch learning pipelines.

Subpackages, one per area:

- :mod:`torchgeo_cg.core`: the validation helper and NaN-free numerics;
- :mod:`torchgeo_cg.transforms`: 2D and 3D transforms, rotations, scene graphs, estimation
  and registration;
- :mod:`torchgeo_cg.curves`: Bezier, B-spline/NURBS, Hermite/PCHIP, parametric and 2D curves;
- :mod:`torchgeo_cg.surfaces`: Bezier, B-spline and NURBS patches, surface fits and grid meshes;
- :mod:`torchgeo_cg.sdf`: signed distance fields, grids and samplers;
- :mod:`torchgeo_cg.mesh`: dense and sparse marching cubes, Catmull-Clark, Loop and bilinear
  subdivision, limit surfaces, mesh I/O;
- :mod:`torchgeo_cg.engine`: the compiled kernel layer (NVIDIA Warp, loaded at first use);
- :mod:`torchgeo_cg.points`: nearest neighbours, Chamfer distance, normals, radius search,
  voxel downsampling, outlier removal, sampling, ICP;
- :mod:`torchgeo_cg.cameras`: camera models, lens distortion with an exact inverse, pose
  conventions;
- :mod:`torchgeo_cg.rays`: exact ray casting on meshes, sphere tracing, depth images;
- :mod:`torchgeo_cg.viz` and :mod:`torchgeo_cg.cli`: the gallery and ``torchgeo-cg``.
"""

from torchgeo_cg import (
    cameras,
    core,
    curves,
    engine,
    mesh,
    points,
    rays,
    sdf,
    surfaces,
    transforms,
)
from torchgeo_cg.core import ShapeError

__version__ = "0.1.0"

__all__ = ["ShapeError", "cameras", "core", "curves", "engine", "mesh", "points", "rays",
           "sdf", "surfaces", "transforms", "__version__"]
