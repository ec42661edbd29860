"""Contract entries of the 3D point-cloud ops: sampling, normals, ICP, radius search, voxel
downsampling and outlier removal (their radius and voxel size are lengths taken from the
data, so they scale with it).

``ENTRIES`` join ``table.TABLE``. ICP's transform is split into its rotation (scale-free,
law ``"unitless"``) and translation (x s); the source is the target moved by a fixed
small rigid motion, so every seed converges to the exact answer (the RMSE is then
rounding noise, so it is left out; tests/points/test_icp.py checks its scaling).
"""

from __future__ import annotations

import math

import torch

import torchgeo_cg.points as P
from tests.contract.spec import Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]

_C, _S = math.cos(0.05), math.sin(0.05)
_ROT = torch.tensor([[_C, -_S, 0.0], [_S, _C, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)


def _icp(method, model="euclidean", loss="l2"):
    def call(source):
        if source.shape[-1] != 3 or not source.is_floating_point():
            return P.icp(source, source)  # the errors name the source
        rot = _ROT.to(source.dtype)
        target = source @ rot.T + 0.02 * source.abs().sum() / max(1, source.numel())
        out = P.icp(source, target, method=method, model=model, robust=P.ICPRobust(loss),
                    convergence=P.ICPConvergence(60, tol=1e-9))
        return out.transform[..., :3, :3], out.transform[..., :3, 3], out.inlier_fraction
    return call


def _length(*clouds: torch.Tensor, share: float = 0.5) -> float:
    """``share`` of the largest finite coordinate of the clouds: a length of the data."""
    vals = torch.cat([c.detach().reshape(-1).double() for c in clouds])
    vals = vals[torch.isfinite(vals)]
    return share * float(vals.abs().max()) if vals.numel() and vals.abs().max() > 0 else 1.0


def _radius(q, r):
    return tuple(P.radius_search(q, r, _length(q, r), max_neighbors=4))


def _voxels(p):
    out = P.voxel_downsample(p, _length(p, share=1.0))  # few voxel walls: low-precision safe
    return out.points, out.lengths


CLOUD = Arg("source", (2, 40, 3))
POINTS = Arg("points", (2, 12, 3))
ICP_OUT = ("unitless", "length", "unitless")  # rmse ~ 0 here: relative error undefined

ENTRIES: list[Entry] = [
    Entry("points.farthest_point_sampling", lambda p: P.farthest_point_sampling(p, 5),
          (POINTS,), out=("length", "index"), empty=(0, 0), bad=((3,),)),
    Entry("points.farthest_point_sampling[ragged]",
          lambda p: P.farthest_point_sampling(p, 5, torch.tensor([12, 4])),
          (POINTS,), out=("length", "index"), empty=None, bad=((3,),),
          cross="the call makes lengths for the unbatched points"),
    Entry("points.estimate_normals", lambda p: P.estimate_normals(p, 6),
          (Arg("points", (2, 30, 3)),), out="unitless", bad=((2, 30, 1), (1,)), rtol32=100.0),
    *[Entry(f"points.icp[{method},{model},{loss}]", _icp(method, model, loss), (CLOUD,),
            out=ICP_OUT, empty=(0, 0), bad=((2, 40, 2), (3,)), rtol=1e-8, rtol32=10.0)
      for method, model, loss in (("point_to_point", "euclidean", "l2"),
                                  ("point_to_plane", "euclidean", "l2"),
                                  ("point_to_point", "similarity", "cauchy"),
                                  ("point_to_plane", "euclidean", "huber"))],
]

ENTRIES += [
    Entry("points.radius_search", _radius, (Arg("query", (2, 6, 3)), Arg("ref", (2, 9, 3))),
          out=("index", "area", "index", "index"), bad=((2, 9, 2), (3,)), bad_arg=1),
    Entry("points.voxel_downsample", _voxels, (Arg("points", (2, 30, 3)),),
          out=("length", "index"), bad=((3,),), nan="skip", rtol32=10.0,
          cross="one cloud argument"),
    Entry("points.remove_statistical_outliers",
          lambda p: P.remove_statistical_outliers(p, 4, 1.0), (Arg("points", (2, 30, 3)),),
          out="index", bad=((3,),), nan="skip", cross="one cloud argument"),
    Entry("points.remove_radius_outliers",
          lambda p: P.remove_radius_outliers(p, _length(p), 3), (Arg("points", (2, 30, 3)),),
          out="index", bad=((3,),), nan="skip", cross="one cloud argument"),
]

EXEMPT: dict[str, str] = {
    "points.ICPResult": "NamedTuple result type",
    "points.RadiusResult": "NamedTuple result type",
    "points.VoxelResult": "NamedTuple result type",
    "points.ICPConvergence": "option bundle of icp, no tensor input",
    "points.ICPRobust": "option bundle of icp, no tensor input",
    "points.SampleResult": "NamedTuple result type",
}
