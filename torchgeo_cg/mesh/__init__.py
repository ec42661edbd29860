"""torchgeo_cg.mesh (being built)."""

from torchgeo_cg.mesh.marching_cubes import MarchingCubes, MarchingCubesResult, marching_cubes

__all__: list[str] = ["marching_cubes", "MarchingCubes", "MarchingCubesResult"]
