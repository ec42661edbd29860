"""Projection against OpenCV, run live: ``cv2.projectPoints`` (all five distortion lengths)
and ``cv2.fisheye.projectPoints``, to 1e-9 pixel in float64."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

import torchgeo_cg.cameras as C
from torchgeo_cg.core import ShapeError

F64 = torch.float64


def _scene(seed: int, n: int = 400):
    g = torch.Generator().manual_seed(seed)
    pts = torch.randn(n, 3, generator=g, dtype=F64)
    pts[:, 2] = pts[:, 2].abs() + 2.0
    rvec = np.array([0.1, -0.2, 0.3])
    tvec = np.array([0.1, 0.2, -0.3])
    rot, _ = cv2.Rodrigues(rvec)
    ext = torch.eye(4, dtype=F64)
    ext[:3, :3] = torch.from_numpy(rot)
    ext[:3, 3] = torch.from_numpy(tvec)
    K = torch.tensor([[1800.0, 0.0, 1919.5], [0.0, 1750.0, 1079.5], [0.0, 0.0, 1.0]], dtype=F64)
    return pts, rvec, tvec, ext, K, g


@pytest.mark.parametrize("length", [4, 5, 8, 12, 14])
def test_project_equals_cv2_project_points(length):
    pts, rvec, tvec, ext, K, g = _scene(length)
    dist = 0.02 * torch.randn(length, generator=g, dtype=F64)
    ref, _ = cv2.projectPoints(pts.numpy(), rvec, tvec, K.numpy(), dist.numpy())
    got = C.project_points(pts, K, dist, ext)
    assert np.abs(got.numpy() - ref[:, 0]).max() <= 1e-9
    cam = C.OpenCVCamera(K, dist, ext)
    assert torch.equal(cam.project(pts), got)


def test_project_pinhole_equals_cv2():
    pts, rvec, tvec, ext, K, _ = _scene(0)
    ref, _ = cv2.projectPoints(pts.numpy(), rvec, tvec, K.numpy(), None)
    got = C.PinholeCamera(K, ext).project(pts)
    assert np.abs(got.numpy() - ref[:, 0]).max() <= 1e-9


def test_project_equals_cv2_fisheye():
    pts, rvec, tvec, ext, K, _ = _scene(1)
    dist = torch.tensor([0.05, -0.02, 0.003, -5e-4], dtype=F64)
    ref, _ = cv2.fisheye.projectPoints(pts.numpy()[:, None], rvec, tvec, K.numpy(),
                                       dist.numpy())
    got = C.FisheyeCamera(K, dist, ext).project(pts)
    assert np.abs(got.numpy() - ref[:, 0]).max() <= 1e-9


def test_distort_equals_cv2_fisheye_distort_points():
    g = torch.Generator().manual_seed(3)
    xy = 0.8 * torch.randn(200, 2, generator=g, dtype=F64)
    dist = torch.tensor([0.05, -0.02, 0.003, -5e-4], dtype=F64)
    ref = cv2.fisheye.distortPoints(xy.numpy()[:, None], np.eye(3), dist.numpy())[:, 0]
    assert np.abs(C.fisheye_distort_points(xy, dist).numpy() - ref).max() <= 1e-12


def test_batched_cameras_match_one_by_one():
    g = torch.Generator().manual_seed(4)
    pts = torch.randn(3, 50, 3, generator=g, dtype=F64)
    pts[..., 2] = pts[..., 2].abs() + 1
    K = torch.eye(3, dtype=F64).repeat(3, 1, 1)
    K[:, 0, 0], K[:, 1, 1] = torch.tensor([500.0, 600, 700]), 550.0
    dist = 0.05 * torch.randn(3, 8, generator=g, dtype=F64)
    batched = C.project_points(pts, K, dist)
    for i in range(3):
        assert torch.equal(batched[i], C.project_points(pts[i], K[i], dist[i]))


def test_behind_the_camera_and_depth():
    K = torch.eye(3, dtype=F64)
    cam = C.PinholeCamera(K, torch.eye(4, dtype=F64))
    pts = torch.tensor([[1.0, 2.0, -2.0], [1.0, 1.0, 0.0]], dtype=F64)
    assert torch.equal(cam.depth(pts), torch.tensor([-2.0, 0.0], dtype=F64))
    px = cam.project(pts)
    assert px.isfinite().all()
    assert torch.equal(px[0], torch.tensor([-0.5, -1.0], dtype=F64))  # as OpenCV's x / z


@pytest.mark.parametrize("bad, name", [
    (lambda p, K, d: (p, K[:2], d), "K"),
    (lambda p, K, d: (p, K, d[:3]), "distortion"),
    (lambda p, K, d: (p, K, torch.zeros(6, dtype=F64)), "distortion"),
    (lambda p, K, d: (p[:, :2], K, d), "points"),
])
def test_bad_shapes_name_the_argument(bad, name):
    pts, _, _, _, K, _ = _scene(5, 4)
    args = bad(pts, K, torch.zeros(5, dtype=F64))
    with pytest.raises(ShapeError, match=name):
        C.project_points(*args)
    with pytest.raises(ShapeError, match="pixels"):
        C.unproject_points(torch.zeros(4, 3, dtype=F64), torch.ones(4, dtype=F64), K)
    with pytest.raises(ShapeError, match="distortion"):
        C.OpenCVCamera(K, torch.zeros(6, dtype=F64))
    with pytest.raises(ShapeError, match="distortion"):
        C.FisheyeCamera(K, torch.zeros(5, dtype=F64))
    with pytest.raises(ShapeError, match="K"):
        C.PinholeCamera(torch.eye(4, dtype=F64))


def test_nan_in_nan_out_and_empty():
    pts, _, _, ext, K, _ = _scene(6, 5)
    pts[2, 0] = float("nan")
    cam = C.OpenCVCamera(K, torch.tensor([-0.2, 0.05, 1e-3, 0, 0], dtype=F64), ext)
    px = cam.project(pts)
    assert px[2].isnan().any() and px[[0, 1, 3, 4]].isfinite().all()
    out = cam.unproject(px, torch.ones(5, dtype=F64))
    assert out.points[2].isnan().all() and not out.valid[2]
    assert out.points[[0, 1, 3, 4]].isfinite().all()
    empty = cam.project(pts[:0])
    assert empty.shape == (0, 2)
    assert cam.unproject(empty, torch.ones(0, dtype=F64)).points.shape == (0, 3)
    assert cam.undistort(empty).points.shape == (0, 2)
