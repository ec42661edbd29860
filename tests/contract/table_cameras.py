"""Contract entries of cameras: projection, unprojection, rays, distortion and conventions.

Pixels, intrinsics and distortion are scale-free (``"unitless"``); world points, depths and
the extrinsics' translation scale by ``s`` (``"length"``, ``"matrix"``), so a scene scaled
by ``s`` projects to the same pixels.
"""

from __future__ import annotations

import torch

import torchgeo_cg.cameras as C
from tests.contract.spec import GENERATORS, Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]

F64 = torch.float64


def _seeded(g: torch.Generator, offset: int) -> torch.Generator:
    return torch.Generator().manual_seed(g.initial_seed() * 13 + offset)


def _intrinsics(shape, g, dtype):
    K = torch.zeros(shape, dtype=F64)
    sub = _seeded(g, 0)
    K[..., 0, 0] = 400 + 200 * torch.rand(shape[:-2], generator=sub, dtype=F64)
    K[..., 1, 1] = 400 + 200 * torch.rand(shape[:-2], generator=sub, dtype=F64)
    K[..., 0, 2] = 320 + 10 * torch.randn(shape[:-2], generator=sub, dtype=F64)
    K[..., 1, 2] = 240 + 10 * torch.randn(shape[:-2], generator=sub, dtype=F64)
    K[..., 2, 2] = 1.0
    return K


def _rigid(shape, g, dtype):
    sub = _seeded(g, 1)
    m = torch.eye(4, dtype=F64).expand(shape).clone()
    m[..., :3, :3] = GENERATORS["rotation"]((*shape[:-2], 3, 3), sub, F64)
    m[..., :3, 3] = 0.5 * torch.randn(*shape[:-2], 3, generator=sub, dtype=F64)
    return m


def _lens(scale: float):
    def gen(shape, g, dtype):
        return scale * torch.randn(shape, generator=_seeded(g, 2), dtype=F64)
    return gen


def _camera_points(shape, g):
    """Camera-frame points 2..4 ahead, within a 30 degree cone."""
    sub = _seeded(g, 3)
    p = torch.empty(shape, dtype=F64)
    p[..., 2] = 2 + 2 * torch.rand(shape[:-1], generator=sub, dtype=F64)
    p[..., :2] = 0.5 * p[..., 2:] * (2 * torch.rand(*shape[:-1], 2, generator=sub, dtype=F64)
                                     - 1)
    return p


def _world_points(shape, g, dtype):
    """Points ahead of the camera of :func:`_rigid` (same seed), in world coordinates."""
    cam = _camera_points(shape, g)
    e = _rigid((4, 4), g, dtype)
    return (cam - e[:3, 3]) @ e[:3, :3]


def _pixels(shape, g, dtype):
    return torch.tensor([320.0, 240.0], dtype=F64) + 150 * (
        2 * torch.rand(shape, generator=_seeded(g, 4), dtype=F64) - 1)


def _normalised(shape, g, dtype):
    return 0.5 * (2 * torch.rand(shape, generator=_seeded(g, 5), dtype=F64) - 1)


POINTS = Arg("points", (2, 6, 3), _world_points)
K = Arg("K", (3, 3), _intrinsics, "unitless")
EXT = Arg("extrinsics", (4, 4), _rigid, "matrix")
PIXELS = Arg("pixels", (2, 6, 2), _pixels, "unitless")
DEPTH = Arg("depth", (2, 6), "positive", "length")
XY = Arg("xy", (2, 6, 2), _normalised, "unitless")


def _dist(p: int) -> Arg:
    return Arg("distortion", (p,), _lens(0.02), "unitless")


def _models():
    yield "pinhole", None
    for p in (4, 5, 8, 12, 14):
        yield f"opencv{p}", p
    yield "fisheye", 4


ENTRIES: list[Entry] = []
for tag, p in _models():
    model = "fisheye" if tag == "fisheye" else "opencv"
    if p is None:
        ENTRIES += [
            Entry("cameras.project_points[pinhole]",
                  lambda x, k, e: C.project_points(x, k, None, e),
                  (POINTS, K, EXT), out="unitless", bad=((2, 6, 2), (6,))),
            Entry("cameras.unproject_points[pinhole]",
                  lambda x, z, k, e: tuple(C.unproject_points(x, z, k, None, e)),
                  (PIXELS, DEPTH, K, EXT), out=("length", "index"), bad=((2, 6, 3), (6,)),
                  empty=((0, -2), (1, -1))),
            Entry("cameras.pixel_rays[pinhole]",
                  lambda x, k, e: tuple(C.pixel_rays(x, k, None, e)),
                  (PIXELS, K, EXT), out=("length", "unitless", "index"), bad=((2, 6, 3), (6,))),
        ]
        continue
    D = _dist(p)
    ENTRIES += [
        Entry(f"cameras.project_points[{tag}]",
              lambda x, k, d, e, m=model: C.project_points(x, k, d, e, m),
              (POINTS, K, D, EXT), out="unitless", bad=((2, 6, 2), (6,))),
        Entry(f"cameras.unproject_points[{tag}]",
              lambda x, z, k, d, e, m=model: tuple(C.unproject_points(x, z, k, d, e, m)),
              (PIXELS, DEPTH, K, D, EXT), out=("length", "index"), bad=((2, 6, 3), (6,)),
              empty=((0, -2), (1, -1))),
        Entry(f"cameras.pixel_rays[{tag}]",
              lambda x, k, d, e, m=model: tuple(C.pixel_rays(x, k, d, e, m)),
              (PIXELS, K, D, EXT), out=("length", "unitless", "index"), bad=((2, 6, 3), (6,))),
    ]
    if model == "opencv":
        ENTRIES += [
            Entry(f"cameras.distort_points[{tag}]", C.distort_points, (XY, D), out="unitless",
                  bad=((2, 6, 3), (6,))),
            Entry(f"cameras.undistort_points[{tag}]",
                  lambda x, d: tuple(C.undistort_points(x, d)), (XY, D),
                  out=("unitless", "index"), bad=((2, 6, 3), (6,))),
            Entry(f"cameras.OpenCVCamera[{tag}]",
                  lambda x, k, d, e: C.OpenCVCamera(k, d, e).project(x),
                  (POINTS, K, D, EXT), out="unitless", bad=((2, 6, 2), (6,))),
        ]

ENTRIES += [
    Entry("cameras.unproject_points[fisheye,ray_distance]",
          lambda x, z, k, d, e: tuple(C.unproject_points(x, z, k, d, e, "fisheye", True)),
          (PIXELS, DEPTH, K, _dist(4), EXT), out=("length", "index"), bad=((2, 6, 3), (6,)),
          empty=((0, -2), (1, -1))),
    Entry("cameras.fisheye_distort_points", C.fisheye_distort_points, (XY, _dist(4)),
          out="unitless", bad=((2, 6, 3), (6,))),
    Entry("cameras.fisheye_undistort_points",
          lambda x, d: tuple(C.fisheye_undistort_points(x, d)), (XY, _dist(4)),
          out=("unitless", "index"), bad=((2, 6, 3), (6,))),
    Entry("cameras.PinholeCamera", lambda x, k, e: C.PinholeCamera(k, e).project(x),
          (POINTS, K, EXT), out="unitless", bad=((2, 6, 2), (6,))),
    Entry("cameras.FisheyeCamera",
          lambda x, k, d, e: C.FisheyeCamera(k, d, e).project(x),
          (POINTS, K, _dist(4), EXT), out="unitless", bad=((2, 6, 2), (6,))),
    Entry("cameras.convert_pose[opengl]", lambda e: C.convert_pose(e, "opencv", "opengl"),
          (Arg("pose", (3, 4, 4), _rigid, "matrix"),), out="matrix", empty=(0, 0),
          bad=((3, 4, 3), (4,))),
    Entry("cameras.convert_pose[pytorch3d]",
          lambda e: tuple(C.convert_pose(e, "opencv", "pytorch3d")),
          (Arg("pose", (3, 4, 4), _rigid, "matrix"),), out=("unitless", "length"),
          empty=(0, 0), bad=((3, 4, 3), (4,))),
    Entry("cameras.to_pytorch3d",
          lambda k, e: tuple(C.to_pytorch3d(C.PinholeCamera(k, e, (480, 640)))),
          (Arg("K", (2, 3, 3), _intrinsics, "unitless"), Arg("extrinsics", (2, 4, 4), _rigid,
                                                             "matrix")),
          out=("unitless", "length", "unitless", "unitless", "unitless"),
          empty=((0, 0), (1, 0)),
          bad=((2, 3, 4), (3,))),
    Entry("cameras.from_pytorch3d",
          lambda r, t, f, c: (lambda cam: (cam.K, cam.extrinsics))(
              C.from_pytorch3d(r, t, f, c, (480, 640))),
          (Arg("R", (2, 3, 3), "rotation", "unitless"), Arg("T", (2, 3)),
           Arg("focal_length", (2, 2), "positive", "unitless"),
           Arg("principal_point", (2, 2), "positive", "unitless")),
          out=("unitless", "matrix"), empty=((0, 0), (1, 0), (2, 0), (3, 0)),
          bad=((2, 3, 4), (3,))),
]

EXEMPT: dict[str, str] = {
    "cameras.UndistortResult": "a result type",
    "cameras.UnprojectResult": "a result type",
    "cameras.RayBundle": "a result type",
    "cameras.PyTorch3DCameras": "a result type",
}
