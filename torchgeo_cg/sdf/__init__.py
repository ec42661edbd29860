"""Signed distance fields: primitives, CSG operators, grid sampling, mesh distances.

Layout (one topic per file):

- :mod:`~torchgeo_cg.sdf.primitives`: ``sphere``, ``box``, ``capsule``, ``plane``, ``torus``,
  ``gyroid`` and 2D ``circle``, ``rectangle``, ``annulus``, each with an ``nn.Module``.
- :mod:`~torchgeo_cg.sdf.operators`: ``union``, ``intersection``, ``difference``,
  ``smooth_union``, ``smooth_intersection``, ``product``, ``translate``, ``rotate``, ``scale``.
- :mod:`~torchgeo_cg.sdf.grid`: ``grid_points``, ``sample_grid``, ``grid_interpolate`` on the
  grid convention of :mod:`torchgeo_cg.core.grid` (``indexing="ij"``, index ``(i, j, k)``
  at ``origin + spacing * (i, j, k)``, ``Volume``).
- :mod:`~torchgeo_cg.sdf.level_set`: the report's ``zero_level_set``.
- :mod:`~torchgeo_cg.sdf.gradients`: ``sdf_gradient``, ``sdf_normal``, ``eikonal_loss``.
- :mod:`~torchgeo_cg.sdf.mesh_distance`: ``mesh_sdf``, ``MeshSDF`` (pseudo-normal and
  winding-number signs), exact evaluation on the closest face.
- :mod:`~torchgeo_cg.sdf._mesh_search`: the torch backend's closest-face search.
- ``torchgeo_cg.sdf._triangle``: triangle geometry shared by the distance, the searches
  and the engine (``closest_point_on_triangle``, pseudo-normals, solid angles).
- :mod:`~torchgeo_cg.sdf.engines`: backends (``"auto"``, ``"torch"``, ``"warp"`` from the
  optional extra ``fast``), ``available_engines``; :mod:`~torchgeo_cg.sdf._engine_warp`.
- :mod:`~torchgeo_cg.sdf.sampler`: ``SDFSampler`` (DeepSDF distribution), ``.npz`` I/O.

Convention: SDFs are negative inside; points are ``(*, N, 3)`` (or ``(*, N, 2)``).

Parameters against points (one rule for every primitive, operator and module here):
a shape's parameters (radii, centres, half sizes, normals, offsets, rotation matrices,
scale factors, blend widths ``k``), whether given beside the points
(``sphere(points, radius)``), when a shape is built (``translate``, ``rotate``,
``scale``) or held by a module, are numbers or tensors. Numbers, numpy values and
lists have no dtype of their own: they take the points' dtype and device at each call
(a list given to ``rotate`` is never rounded through float32). A tensor keeps its
dtype: it must have the points' dtype and device, else a ``TypeError`` names both
(float16, bfloat16 and float32 meet each other and are computed in float32). Nothing
is cast silently, so a float64 ``rotate`` never computes in float32 and a float32
pipeline never turns float64, as with the modules (``Sphere().double()(points_f32)``
raises) and peer tensors. The rule lives in ``torchgeo_cg.sdf._params``.
"""

from torchgeo_cg.sdf._triangle import TriangleClosestPoint, closest_point_on_triangle
from torchgeo_cg.sdf.engines import available_engines
from torchgeo_cg.sdf.gradients import eikonal_loss, sdf_gradient, sdf_normal
from torchgeo_cg.sdf.grid import grid_interpolate, grid_points, grid_spacing, sample_grid
from torchgeo_cg.sdf.level_set import LevelSetPoints, zero_level_set
from torchgeo_cg.sdf.mesh_distance import (
    MeshSDF,
    MeshSDFResult,
    is_watertight,
    mesh_sdf,
    winding_number,
)
from torchgeo_cg.sdf.operators import (
    Difference,
    Intersection,
    Product,
    Rotate,
    Scale,
    SmoothIntersection,
    SmoothUnion,
    Translate,
    Union,
    difference,
    intersection,
    product,
    rotate,
    scale,
    smooth_intersection,
    smooth_union,
    translate,
    union,
)
from torchgeo_cg.sdf.primitives import (
    Annulus,
    Box,
    Capsule,
    Circle,
    Gyroid,
    Plane,
    Rectangle,
    Sphere,
    Torus,
    annulus,
    box,
    capsule,
    circle,
    gyroid,
    plane,
    rectangle,
    sphere,
    torus,
)
from torchgeo_cg.sdf.sampler import (
    SDFSampler,
    SDFSamples,
    load_samples,
    sample_mesh_surface,
    save_samples,
)

__all__ = [
    # primitives
    "sphere", "box", "capsule", "plane", "torus", "gyroid", "circle", "rectangle", "annulus",
    "Sphere", "Box", "Capsule", "Plane", "Torus", "Gyroid", "Circle", "Rectangle", "Annulus",
    # operators
    "union", "intersection", "difference", "smooth_union", "smooth_intersection", "product",
    "translate", "rotate", "scale",
    "Union", "Intersection", "Difference", "SmoothUnion", "SmoothIntersection", "Product",
    "Translate", "Rotate", "Scale",
    # grid
    "grid_spacing", "grid_points", "sample_grid", "grid_interpolate",
    # level set, gradients
    "LevelSetPoints", "zero_level_set", "sdf_gradient", "sdf_normal", "eikonal_loss",
    # mesh distance
    "MeshSDFResult", "TriangleClosestPoint", "closest_point_on_triangle", "is_watertight",
    "winding_number", "mesh_sdf", "MeshSDF", "available_engines",
    # sampler
    "SDFSamples", "SDFSampler", "sample_mesh_surface", "save_samples", "load_samples",
]
