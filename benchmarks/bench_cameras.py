"""Cameras against OpenCV (which computes in double): projection of 1M points with the
8-parameter rational model, and undistortion of every pixel of a 1920 x 1080 image.

The targets hold at 1 thread; the 2-thread rows are reported (OpenCV gets
``cv2.setNumThreads`` of the same count). Targets: ``project_points`` <= 1.0x
``cv2.projectPoints``; ``undistort_points`` to rounding level (~1e-16, "to 1e-12") <= 2.0x
OpenCV's iterative undistortion run to convergence with criteria
``(COUNT + EPS, 100, 1e-12)`` (OpenCV 5: the criteria of the
former ``undistortPointsIter`` are ``undistortPoints``' own). Each undistortion row
reports both errors: the largest residual ``|distort(x) - x_d|`` of the points each
returns, in pixels (over the points ours marks valid: the whole image for this lens).

Where the time goes (undistortion): the monotone-domain search (Bernstein isolation of
the derivative's first root) is a few milliseconds per call whatever the point count. The
points are solved in blocks of 32768 that stay in cache: the bracketed radial Newton
(a fixed-point first guess, then 3-4 steps to half precision, as it only starts the 2D
solve), then the 2D trust-region Newton for the tangential terms (2-3 steps to rounding
level); converged points leave both loops. Each step is a few dozen elementwise torch
passes over the block. OpenCV runs its fixed-point iteration per point in C++ (about 10
iterations at 1e-12 for this mild lens; more for strong ones, where it also stops short
of the inverse).
"""

from __future__ import annotations

import numpy as np
import torch

from benchmarks.harness import Case
from torchgeo_cg.cameras import distort_points, project_points, undistort_points

#: a wide-angle rational lens, k1, k2, p1, p2, k3, k4, k5, k6; its radial map is monotone
#: up to r = 2.38 (distorted 1.50), beyond the image's corners (1.27)
_LENS = [-0.12, 0.03, 1e-3, -5e-4, -2e-3, 0.02, 5e-3, 1e-3]


def _camera(width: int, height: int):
    f = 0.9 * width / 2
    K = torch.tensor([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2],
                      [0.0, 0.0, 1.0]], dtype=torch.float64)
    return K, torch.tensor(_LENS, dtype=torch.float64)


def _threaded(call):
    """``call`` with OpenCV's thread count set to the harness's (torch's) count."""
    import cv2

    def run():
        cv2.setNumThreads(torch.get_num_threads())
        return call()

    return run


def _residual_px(xy: torch.Tensor, target: torch.Tensor, dist: torch.Tensor, f: float) -> float:
    return float((distort_points(xy, dist) - target).abs().max()) * f


def cases(quick: bool = False) -> list[Case]:
    import cv2

    peer = f"OpenCV {cv2.__version__}"
    gen = torch.Generator().manual_seed(0)
    n = 100_000 if quick else 1_000_000
    K, dist = _camera(1920, 1080)
    pts = torch.randn(n, 3, generator=gen, dtype=torch.float64)
    pts[:, 2] = pts[:, 2].abs() + 2
    rvec, tvec = np.array([0.1, -0.2, 0.3]), np.array([0.1, 0.2, -0.3])
    rot, _ = cv2.Rodrigues(rvec)
    ext = torch.eye(4, dtype=torch.float64)
    ext[:3, :3], ext[:3, 3] = torch.from_numpy(rot), torch.from_numpy(tvec)
    pts_np, K_np, dist_np = pts.numpy(), K.numpy(), dist.numpy()
    ref = cv2.projectPoints(pts_np, rvec, tvec, K_np, dist_np)[0][:, 0]
    diff = float(np.abs(project_points(pts, K, dist, ext).numpy() - ref).max())
    out = [Case(f"project_points {n} pts, 8-param f64", lambda: project_points(pts, K, dist, ext),
                _threaded(lambda: cv2.projectPoints(pts_np, rvec, tvec, K_np, dist_np)), peer,
                target=1.0, threads=(1, 2), target_threads=(1,),
                extra={"max_px_diff_vs_opencv": diff})]

    w, h = (480, 270) if quick else (1920, 1080)
    K, dist = _camera(w, h)
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64),
                          torch.arange(w, dtype=torch.float64), indexing="ij")
    pixels = torch.stack([u, v], -1).reshape(-1, 2)
    pixels_np, K_np, dist_np = pixels.numpy()[:, None], K.numpy(), dist.numpy()
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]

    def ours():
        xy = torch.stack([(pixels[:, 0] - cx) / fx, (pixels[:, 1] - cy) / fy], -1)
        return undistort_points(xy, dist)

    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)

    def theirs():
        return cv2.undistortPoints(pixels_np, K_np, dist_np, criteria=crit)

    target = torch.stack([(pixels[:, 0] - cx) / fx, (pixels[:, 1] - cy) / fy], -1)
    mine = ours()
    cv = torch.from_numpy(theirs()[:, 0])
    ok = mine.valid
    extra = {"valid_fraction": float(ok.double().mean()),
             "ours_max_residual_px": _residual_px(mine.points[ok], target[ok], dist, float(fx)),
             "opencv_max_residual_px": _residual_px(cv[ok], target[ok], dist, float(fx))}
    out.append(Case(f"undistort_points {w}x{h} px, 8-param f64", ours, _threaded(theirs),
                    f"{peer} (COUNT+EPS, 100, 1e-12)", target=2.0, threads=(1, 2),
                    target_threads=(1,), extra=extra))
    return out
