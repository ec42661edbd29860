"""Marching cubes on sampled volumes.

Layout (as scikit-image separates its wrapper from its implementation):

- :mod:`.sparse`: :func:`sparse_marching_cubes` on a field (a callable), sampling only
  the blocks that can hold the surface, and :func:`lipschitz_bound` for MLPs; its
  internals ``_field`` (grid, chunked evaluation), ``_blocks`` (pruning) and
  ``_extract`` (marching cubes over blocks, welded by global edge keys);
- :mod:`.dense`: the public wrapper, :func:`marching_cubes` on a sampled volume, its
  module form :class:`MarchingCubes` and the result type;
- ``_args``: argument parsing; ``_slabs``: large volumes slab by slab; ``_steps``:
  classify, weld, triangulate, interpolate, soft weights; ``_decider``: the asymptotic
  decider and the interior test;
- ``_tables``: the triangulation tables, generated in code.
"""

from torchgeo_cg.mesh.marching_cubes.dense import (
    AMBIGUITY_RULES,
    AMBIGUOUS_CASES,
    MarchingCubes,
    MarchingCubesResult,
    marching_cubes,
)
from torchgeo_cg.mesh.marching_cubes.sparse import lipschitz_bound, sparse_marching_cubes

__all__ = ["AMBIGUITY_RULES", "AMBIGUOUS_CASES", "MarchingCubes", "MarchingCubesResult",
           "marching_cubes"]
__all__ += ["sparse_marching_cubes", "lipschitz_bound"]
