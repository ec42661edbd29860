"""Marching cubes on sampled volumes.

Layout (as scikit-image separates its wrapper from its implementation):

- :mod:`.dense`: the public wrapper, :func:`marching_cubes` on a sampled volume, its
  module form :class:`MarchingCubes` and the result type;
- ``_args``: argument parsing; ``_steps``: classify, weld, triangulate, interpolate,
  soft weights; ``_decider``: the asymptotic decider and the interior test;
- ``_tables``: the triangulation tables, generated in code.
"""

from torchgeo_cg.mesh.marching_cubes.dense import (
    AMBIGUITY_RULES,
    MarchingCubes,
    MarchingCubesResult,
    marching_cubes,
)

__all__ = ["AMBIGUITY_RULES", "MarchingCubes", "MarchingCubesResult", "marching_cubes"]
