"""torchgeo_cg.points: exact k nearest neighbours and the Chamfer distance, batched and ragged."""

from torchgeo_cg.points.chamfer import ChamferDistance, ChamferResult, chamfer_distance
from torchgeo_cg.points.nearest_neighbors import KNNResult, knn

__all__ = ["KNNResult", "knn", "ChamferResult", "chamfer_distance", "ChamferDistance"]
