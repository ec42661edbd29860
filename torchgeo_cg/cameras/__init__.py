"""Cameras: pinhole, OpenCV and fisheye models; projection, unprojection, rays,
distortion with an exact inverse, and pose conventions.

Frame: OpenCV's camera frame (x right, y down, z forward); pixel ``(u, v)`` with
integer coordinates at pixel centres; extrinsics world-to-camera ``(*, 4, 4)``
``[[R, t], [0, 1]]`` acting on column vectors.
"""

from torchgeo_cg.cameras.conventions import (
    PyTorch3DCameras,
    convert_pose,
    from_pytorch3d,
    to_pytorch3d,
)
from torchgeo_cg.cameras.distortion import (
    UndistortResult,
    distort_points,
    fisheye_distort_points,
    fisheye_undistort_points,
    undistort_points,
)
from torchgeo_cg.cameras.models import FisheyeCamera, OpenCVCamera, PinholeCamera
from torchgeo_cg.cameras.projection import (
    RayBundle,
    UnprojectResult,
    pixel_rays,
    project_points,
    unproject_points,
)

__all__ = [
    "FisheyeCamera",
    "OpenCVCamera",
    "PinholeCamera",
    "PyTorch3DCameras",
    "convert_pose",
    "from_pytorch3d",
    "to_pytorch3d",
    "RayBundle",
    "UnprojectResult",
    "pixel_rays",
    "project_points",
    "unproject_points",
    "UndistortResult",
    "distort_points",
    "fisheye_distort_points",
    "fisheye_undistort_points",
    "undistort_points",
]
