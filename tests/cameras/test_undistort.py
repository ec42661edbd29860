"""The exact inverse: round trips at every pixel of a 4K image for five lenses, ``valid``
against a dense scan of the radial map, and OpenCV's iterative undistortion as a peer."""

from __future__ import annotations

import math

import cv2
import pytest
import torch

import torchgeo_cg.cameras as C
from tests.cameras.lenses import LENSES, make_camera, pixels, pose

F64, F32 = torch.float64, torch.float32
TOL = {F64: 1e-9, F32: 1e-3}


def _round_trip(name: str, dtype, step: int, chunk: int = 1 << 20):
    """``(valid, error in pixels)`` of ``project(unproject(p, d))`` at every ``step``-th
    pixel, in chunks of ``chunk`` pixels (the whole 4K image is 8.3M pixels)."""
    cam = make_camera(name, dtype, pose(dtype))
    px_all = pixels(step, dtype)
    g = torch.Generator().manual_seed(0)
    depth_all = (0.5 + 9.5 * torch.rand(px_all.shape[0], generator=g, dtype=F64)).to(dtype)
    kwargs = {"ray_distance": True} if LENSES[name][0] == "fisheye" else {}
    valid, err = [], []
    for px, depth in zip(px_all.split(chunk), depth_all.split(chunk)):
        out = cam.unproject(px, depth, **kwargs)
        assert out.points.dtype == dtype and out.points.isfinite().all()
        valid.append(out.valid)
        err.append((cam.project(out.points) - px).abs().amax(-1))
    return torch.cat(valid), torch.cat(err)


@pytest.mark.parametrize("dtype", [F64, F32], ids=["float64", "float32"])
@pytest.mark.parametrize("name", list(LENSES))
def test_round_trip_where_valid_strided(name, dtype):
    valid, err = _round_trip(name, dtype, 29)
    assert valid.float().mean() > 0.5
    assert float(err[valid].max()) <= TOL[dtype]


@pytest.mark.slow
@pytest.mark.parametrize("dtype", [F64, F32], ids=["float64", "float32"])
@pytest.mark.parametrize("name", list(LENSES))
def test_round_trip_where_valid_every_pixel(name, dtype):
    valid, err = _round_trip(name, dtype, 1)
    assert valid.numel() == 3840 * 2160
    assert float(err[valid].max()) <= TOL[dtype]


def test_newton_physics_lens_has_the_true_inverse():
    # a fixed-point iteration cycles between 1.042 and 1.406 here; the inverse is 1.2498
    lens = torch.tensor(LENSES["newton_physics"][2], dtype=F64)
    out = C.undistort_points(torch.tensor([[1.1336, 0.0]], dtype=F64), lens)
    assert bool(out.valid[0])
    assert abs(float(out.points[0, 0]) - 1.2498) < 1e-4
    assert float((C.distort_points(out.points, lens) - 1.1336)[0, 0].abs()) < 1e-15


def _scan_domain(radial, top: float, count: int = 2_000_001):
    """Dense scan of a radial map on [0, top]: the largest image value before its first
    decrease (the end of the invertible domain), and the scan's step."""
    r = torch.linspace(0.0, top, count, dtype=F64)
    m = radial(r)
    falls = (m[1:] <= m[:-1]).nonzero()
    end = int(falls[0]) if falls.numel() else count - 1
    return float(m[: end + 1].max()), float(m[end + 1] - m[end]) if end + 1 < count else 0.0


@pytest.mark.parametrize("name", ["newton_physics", "folding", "rational8"])
def test_valid_is_exactly_the_monotone_domain_opencv(name):
    k = torch.tensor(LENSES[name][2], dtype=F64)
    k8 = torch.nn.functional.pad(k, (0, 8 - k.numel()))
    radial_only = torch.cat([k8[:2], k8.new_zeros(2), k8[4:]])

    def radial(r):
        s = r * r
        num = 1 + s * (k8[0] + s * (k8[1] + s * k8[4]))
        den = 1 + s * (k8[5] + s * (k8[6] + s * k8[7]))
        return r * num / den

    top, _ = _scan_domain(radial, 4.0)
    rd = torch.linspace(0.0, min(2.5 * top, 6.0), 200_001, dtype=F64)
    out = C.undistort_points(torch.stack([rd, torch.zeros_like(rd)], -1), radial_only)
    near = (rd - top).abs() <= 1e-9 * top
    want = rd < top
    assert torch.equal(out.valid[~near], want[~near])
    ok = out.valid
    back = C.distort_points(out.points[ok], radial_only)[:, 0]
    assert float((back - rd[ok]).abs().max()) <= 1e-14 * max(1.0, top)
    if name == "folding":  # this lens folds at r = 0.941
        assert 0.60 < top < 0.61
        last = out.points[ok][:, 0].max()
        assert abs(float(last) - 0.9414) < 1e-3


def test_valid_is_exactly_the_monotone_domain_fisheye():
    k = torch.tensor(LENSES["strong_fisheye"][2], dtype=F64)

    def angle(t):
        t2 = t * t
        return t * (1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))

    top, _ = _scan_domain(angle, math.pi, 1_000_001)
    top_half, _ = _scan_domain(angle, math.pi / 2, 1_000_001)
    rd = torch.linspace(0.0, 1.5 * top, 20_001, dtype=F64)
    xy = torch.stack([rd, torch.zeros_like(rd)], -1)
    K = torch.eye(3, dtype=F64)
    rays = C.FisheyeCamera(K, k).pixel_rays(xy)
    near = (rd - top).abs() <= 1e-9 * top
    assert torch.equal(rays.valid[~near], (rd < top)[~near])
    # the pinhole-normalised inverse stops at 90 degrees (or the fold, if earlier)
    out = C.fisheye_undistort_points(xy, k)
    near = (rd - top_half).abs() <= 1e-9 * top_half
    assert torch.equal(out.valid[~near], (rd < top_half)[~near])
    # the rays project back to their pixels
    ok = rays.valid & (rd > 0)
    back = C.FisheyeCamera(K, k).project(rays.directions[ok])
    assert float((back - xy[ok]).abs().max()) <= 1e-12


def test_more_exact_than_opencv_iterative_undistortion():
    cam = make_camera("rational8")
    px = pixels(37)
    K = cam.K.numpy()
    dist = cam.distortion.numpy()
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    # OpenCV 5: the criteria of the old undistortPointsIter are undistortPoints' own
    ref = cv2.undistortPoints(px.numpy()[:, None], K, dist, criteria=crit)[:, 0]
    ours = cam.undistort(_normalised(cam, px))
    ok = ours.valid
    ref_t = torch.from_numpy(ref)
    ours_err = (C.distort_points(ours.points, cam.distortion) - _normalised(cam, px))[ok]
    cv_err = (C.distort_points(ref_t, cam.distortion) - _normalised(cam, px))[ok]
    assert float(ours_err.abs().max()) <= 1e-13
    assert float(ours_err.abs().max()) <= float(cv_err.abs().max())


def _normalised(cam, px):
    K = cam.K
    y = (px[:, 1] - K[1, 2]) / K[1, 1]
    x = (px[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    return torch.stack([x, y], -1)


def test_scale_free_and_nan_and_empty():
    lens = torch.tensor(LENSES["full14"][2], dtype=F64)
    g = torch.Generator().manual_seed(2)
    xy = 0.6 * torch.rand(100, 2, generator=g, dtype=F64)
    out = C.undistort_points(xy, lens)
    assert out.valid.all()
    xy[3, 1] = float("nan")
    bad = C.undistort_points(xy, lens)
    assert bad.points[3].isnan().all() and not bad.valid[3]
    assert torch.equal(bad.points[:3], out.points[:3])
    empty = C.undistort_points(xy[:0], lens)
    assert empty.points.shape == (0, 2) and empty.valid.shape == (0,)
    assert C.fisheye_undistort_points(xy[:0], lens[:4]).points.shape == (0, 2)
