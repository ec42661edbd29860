"""torchgeo_cg.points: exact k nearest neighbours and the Chamfer distance, batched and ragged."""

from torchgeo_cg.points.chamfer import ChamferDistance, ChamferResult, chamfer_distance
from torchgeo_cg.points.icp import ICPResult, icp
from torchgeo_cg.points.nearest_neighbors import KNNResult, knn
from torchgeo_cg.points.normals import estimate_normals
from torchgeo_cg.points.sampling import SampleResult, farthest_point_sampling

__all__ = ["KNNResult", "knn", "ChamferResult", "chamfer_distance", "ChamferDistance",
           "SampleResult", "farthest_point_sampling", "estimate_normals",
           "ICPResult", "icp"]
