"""torchgeo_cg.points: exact neighbourhoods (k nearest, radius), the Chamfer distance,
farthest point sampling, voxel downsampling, outlier removal, normals and ICP; batched
and ragged, with compiled (Warp) and torch search paths that agree exactly."""

from torchgeo_cg.points.chamfer import ChamferDistance, ChamferResult, chamfer_distance
from torchgeo_cg.points.icp import ICPConvergence, ICPResult, ICPRobust, icp
from torchgeo_cg.points.nearest_neighbors import KNNResult, knn
from torchgeo_cg.points.normals import estimate_normals
from torchgeo_cg.points.outliers import remove_radius_outliers, remove_statistical_outliers
from torchgeo_cg.points.radius import RadiusResult, radius_search
from torchgeo_cg.points.sampling import SampleResult, farthest_point_sampling
from torchgeo_cg.points.voxels import VoxelResult, voxel_downsample

__all__ = ["KNNResult", "knn", "ChamferResult", "chamfer_distance", "ChamferDistance",
           "SampleResult", "farthest_point_sampling", "estimate_normals",
           "ICPResult", "ICPConvergence", "ICPRobust", "icp", "RadiusResult",
           "radius_search", "VoxelResult", "voxel_downsample", "remove_statistical_outliers",
           "remove_radius_outliers"]
