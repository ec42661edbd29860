"""Pose conventions round-trip to 1e-12; to_pytorch3d reproduces PyTorch3D's documented
screen-space projection of ``PerspectiveCameras(in_ndc=False)``, non-square images included.

PyTorch3D is not installed; its documented formulas are written out here as the reference
(docs/notes/cameras.md): row vectors ``X_view = X_world R + T``; NDC ``x_ndc = f_ndc X / Z +
p_ndc`` (camera x left, y up); screen ``x_screen = W / 2 - s x_ndc``, ``y_screen = H / 2 -
s y_ndc`` with ``s = min(H, W) / 2``; and ``f_screen = s f_ndc``, ``p_screen = W / 2 - s
p_ndc`` (y alike). Screen space has the top-left pixel's corner at 0.
"""

from __future__ import annotations

import itertools

import pytest
import torch

import torchgeo_cg.cameras as C
from tests.cameras.lenses import pose

F64 = torch.float64


def _poses(count: int = 6) -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    out = []
    for _ in range(count):
        q = torch.nn.functional.normalize(torch.randn(4, generator=g, dtype=F64), dim=0)
        w, x, y, z = q
        rot = torch.tensor([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]],
                           dtype=F64)
        m = torch.eye(4, dtype=F64)
        m[:3, :3], m[:3, 3] = rot, torch.randn(3, generator=g, dtype=F64)
        out.append(m)
    return torch.stack(out)


def _close(a, b):
    if isinstance(a, tuple):
        return all(_close(x, y) for x, y in zip(a, b))
    return float((a - b).abs().max()) <= 1e-12


KINDS = ("opencv", "opengl", "pytorch3d")


@pytest.mark.parametrize("src, dst", list(itertools.permutations(KINDS, 2)))
def test_every_pair_round_trips(src, dst):
    cv = _poses()
    start = C.convert_pose(cv, "opencv", src)
    there = C.convert_pose(start, src, dst)
    back = C.convert_pose(there, dst, src)
    assert _close(back, start)
    assert _close(C.convert_pose(there, dst, "opencv"), cv)


def test_opengl_is_camera_to_world_with_y_up_z_back():
    cv = _poses(1)[0]
    gl = C.convert_pose(cv, "opencv", "opengl")
    centre = -cv[:3, :3].T @ cv[:3, 3]
    assert _close(gl[:3, 3], centre)  # camera-to-world: the camera centre
    forward_cv = cv[2, :3]  # the camera's +z in world coordinates
    assert _close(gl[:3, 2], -forward_cv)  # OpenGL looks down -z
    assert _close(gl[:3, 1], -cv[1, :3])  # y up = -(y down)


def _pytorch3d_screen(points, R, T, focal, principal, image_size):
    """PyTorch3D's documented screen projection, via NDC (see the module docstring)."""
    h, w = image_size
    s = min(h, w) / 2
    view = points @ R + T  # row vectors
    f_ndc, p_ndc = focal / s, torch.stack([(w / 2 - principal[0]) / s,
                                           (h / 2 - principal[1]) / s])
    x_ndc = f_ndc[0] * view[:, 0] / view[:, 2] + p_ndc[0]
    y_ndc = f_ndc[1] * view[:, 1] / view[:, 2] + p_ndc[1]
    return torch.stack([w / 2 - s * x_ndc, h / 2 - s * y_ndc], -1)


@pytest.mark.parametrize("image_size", [(480, 640), (640, 480), (300, 300)])
def test_to_pytorch3d_reproduces_its_screen_projection(image_size):
    K = torch.tensor([[520.0, 0.0, 300.25], [0.0, 505.0, 250.75], [0.0, 0.0, 1.0]], dtype=F64)
    cam = C.PinholeCamera(K, pose(), image_size)
    g = torch.Generator().manual_seed(1)
    pts = torch.randn(50, 3, generator=g, dtype=F64) + torch.tensor([0.0, 0.0, 4.0], dtype=F64)
    p3d = C.to_pytorch3d(cam)
    screen = _pytorch3d_screen(pts, p3d.R, p3d.T, p3d.focal_length, p3d.principal_point,
                               image_size)
    # our pixel centre u is PyTorch3D's screen u - 0.5
    assert float((cam.project(pts) - (screen - 0.5)).abs().max()) <= 1e-9
    assert p3d.image_size.tolist() == list(image_size)
    back = C.from_pytorch3d(*p3d)
    assert _close(back.K, K) and _close(back.extrinsics, cam.extrinsics)
    assert back.image_size == image_size


def test_to_pytorch3d_refuses_what_it_cannot_express():
    K = torch.eye(3, dtype=F64)
    with pytest.raises(ValueError, match="image_size"):
        C.to_pytorch3d(C.PinholeCamera(K))
    K[0, 1] = 0.1
    with pytest.raises(ValueError, match="skew"):
        C.to_pytorch3d(C.PinholeCamera(K, image_size=(2, 2)))
    with pytest.raises(TypeError, match="PinholeCamera"):
        C.to_pytorch3d(C.OpenCVCamera(torch.eye(3, dtype=F64), torch.zeros(4, dtype=F64)))
    with pytest.raises(ValueError, match="dst"):
        C.convert_pose(torch.eye(4), "opencv", "blender")
    with pytest.raises(TypeError, match="pose"):
        C.convert_pose(torch.eye(4), "pytorch3d", "opencv")
