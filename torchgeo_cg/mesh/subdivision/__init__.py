"""torchgeo_cg.mesh.subdivision: subdivision surfaces as sparse operators built once.

Layout:
    - :mod:`~torchgeo_cg.mesh.subdivision.options`: :class:`SchemeOptions`, the rules
      (boundary, crease method, triangle rule, face-varying interpolation) every builder
      and module takes as ``options=``, documented once.
    - :mod:`~torchgeo_cg.mesh.subdivision.operator`: the scheme-neutral
      :class:`SubdivisionOperator` and :func:`apply_operator`.
    - :mod:`~torchgeo_cg.mesh.subdivision.catmark`, :mod:`~torchgeo_cg.mesh.subdivision.loop`,
      :mod:`~torchgeo_cg.mesh.subdivision.bilinear`: one module per scheme.
    - :mod:`~torchgeo_cg.mesh.subdivision.tags`: creases, corners and holes
      (OpenSubdiv's tags); :mod:`~torchgeo_cg.mesh.subdivision.face_varying`: UV channels.
    - :mod:`~torchgeo_cg.mesh.subdivision.limit`: limit positions and frames at the vertices;
      :mod:`~torchgeo_cg.mesh.subdivision.surface`: the limit at any (face, u, v).
    - :mod:`~torchgeo_cg.mesh.subdivision.stencils`: the CSR stencil matrices all of these use.
"""

from torchgeo_cg.mesh.subdivision.bilinear import bilinear_operator
from torchgeo_cg.mesh.subdivision.catmark import CatmullClark, catmull_clark, catmull_clark_operator
from torchgeo_cg.mesh.subdivision.face_varying import (
    FaceVaryingSubdivision,
    face_varying_operator,
    face_varying_subdivide,
)
from torchgeo_cg.mesh.subdivision.limit import LimitFrames, limit_frames, limit_positions
from torchgeo_cg.mesh.subdivision.loop import LoopSubdivision, loop_operator, loop_subdivide
from torchgeo_cg.mesh.subdivision.operator import SubdivisionOperator, apply_operator
from torchgeo_cg.mesh.subdivision.options import FVAR_INTERPOLATIONS, SchemeOptions
from torchgeo_cg.mesh.subdivision.stencils import StencilMatrix, apply_stencils
from torchgeo_cg.mesh.subdivision.surface import (
    LimitStencils,
    LimitSurfaceSample,
    SurfaceSamples,
    limit_stencils,
    limit_surface,
    sample_limit_surface,
)
from torchgeo_cg.mesh.subdivision.tags import INFINITELY_SHARP, SubdivisionTags

__all__ = [
    "SchemeOptions",
    "SubdivisionOperator",
    "apply_operator",
    "catmull_clark_operator",
    "catmull_clark",
    "CatmullClark",
    "loop_operator",
    "loop_subdivide",
    "LoopSubdivision",
    "bilinear_operator",
    "SubdivisionTags",
    "INFINITELY_SHARP",
    "limit_positions",
    "limit_frames",
    "LimitFrames",
    "limit_surface",
    "limit_stencils",
    "sample_limit_surface",
    "LimitSurfaceSample",
    "LimitStencils",
    "SurfaceSamples",
    "StencilMatrix",
    "apply_stencils",
    "FVAR_INTERPOLATIONS",
    "face_varying_operator",
    "FaceVaryingSubdivision",
    "face_varying_subdivide",
]
