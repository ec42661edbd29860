"""torchgeo_cg.mesh: marching cubes, Catmull-Clark, Loop and bilinear subdivision, mesh I/O."""

from torchgeo_cg.mesh.faces import (
    check_faces,
    check_mesh,
    face_sizes,
    pad_faces,
    triangulate_faces,
    unpad_faces,
)
from torchgeo_cg.mesh.io import Mesh, from_trimesh, load_mesh, save_mesh, to_trimesh
from torchgeo_cg.mesh.marching_cubes import (
    MarchingCubes,
    MarchingCubesResult,
    lipschitz_bound,
    marching_cubes,
    sparse_marching_cubes,
)
from torchgeo_cg.mesh.regularizers import (
    MeshEdges,
    edge_length_loss,
    laplacian_smoothing_loss,
    mesh_edges,
    mesh_laplacian,
    normal_consistency_loss,
)
from torchgeo_cg.mesh.subdivision import (
    FVAR_INTERPOLATIONS,
    INFINITELY_SHARP,
    CatmullClark,
    FaceVaryingSubdivision,
    LimitFrames,
    LimitStencils,
    LimitSurfaceSample,
    LoopSubdivision,
    SchemeOptions,
    StencilMatrix,
    SubdivisionOperator,
    SubdivisionTags,
    SurfaceSamples,
    apply_operator,
    apply_stencils,
    bilinear_operator,
    catmull_clark,
    catmull_clark_operator,
    face_varying_operator,
    face_varying_subdivide,
    limit_frames,
    limit_positions,
    limit_stencils,
    limit_surface,
    loop_operator,
    loop_subdivide,
    sample_limit_surface,
)

__all__: list[str] = ["marching_cubes", "MarchingCubes", "MarchingCubesResult"]
__all__ += ["sparse_marching_cubes", "lipschitz_bound"]
__all__ += ["Mesh", "load_mesh", "save_mesh", "from_trimesh", "to_trimesh"]
__all__ += [
    "pad_faces", "face_sizes", "check_faces", "check_mesh", "triangulate_faces", "unpad_faces"
]
__all__ += [
    "SchemeOptions",
    "SubdivisionOperator",
    "catmull_clark_operator",
    "apply_operator",
    "catmull_clark",
    "CatmullClark",
    "limit_positions",
]
__all__ += ["loop_operator", "loop_subdivide", "LoopSubdivision"]
__all__ += ["SubdivisionTags", "INFINITELY_SHARP", "bilinear_operator"]
__all__ += ["limit_frames", "LimitFrames"]
__all__ += ["limit_surface", "limit_stencils", "sample_limit_surface", "LimitSurfaceSample",
            "LimitStencils", "SurfaceSamples", "StencilMatrix", "apply_stencils"]
__all__ += [
    "MeshEdges",
    "mesh_edges",
    "mesh_laplacian",
    "laplacian_smoothing_loss",
    "normal_consistency_loss",
    "edge_length_loss",
]
__all__ += [
    "FVAR_INTERPOLATIONS",
    "face_varying_operator",
    "FaceVaryingSubdivision",
    "face_varying_subdivide",
]
