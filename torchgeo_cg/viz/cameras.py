"""Gallery figure for cameras: a distorted checkerboard, its undistortion, and the
invalid region of a folding lens."""

from __future__ import annotations

from pathlib import Path

import torch

from torchgeo_cg.cameras import OpenCVCamera
from torchgeo_cg.viz._style import plt, save
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []

_F64 = torch.float64
_H, _W = 240, 320


def _camera(lens: list[float]) -> OpenCVCamera:
    K = torch.tensor([[150.0, 0.0, (_W - 1) / 2], [0.0, 150.0, (_H - 1) / 2],
                      [0.0, 0.0, 1.0]], dtype=_F64)
    return OpenCVCamera(K, torch.tensor(lens, dtype=_F64), image_size=(_H, _W))


def _checker(xy: torch.Tensor, size: float = 0.25) -> torch.Tensor:
    """A checkerboard on the plane z = 1 (squares of ``size``), at normalised points."""
    cells = torch.floor(xy / size).long()
    return ((cells[..., 0] + cells[..., 1]) % 2).to(_F64)


def _seen(cam: OpenCVCamera):
    """What the camera sees of the checkerboard: each pixel's undistorted point's colour."""
    rays = cam.pixel_rays()
    xy = rays.directions[..., :2] / rays.directions[..., 2:]
    return _checker(xy), rays.valid


def _undistorted(cam: OpenCVCamera, image: torch.Tensor) -> torch.Tensor:
    """Resample ``image`` onto the pinhole camera with the same K (nearest pixel)."""
    K = cam.K
    v, u = torch.meshgrid(torch.arange(_H, dtype=_F64), torch.arange(_W, dtype=_F64),
                          indexing="ij")
    xy = torch.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]], -1).reshape(-1, 2)
    src = cam.distort(xy)
    col = (src[:, 0] * K[0, 0] + K[0, 2]).round().long()
    row = (src[:, 1] * K[1, 1] + K[1, 2]).round().long()
    inside = (col >= 0) & (col < _W) & (row >= 0) & (row < _H)
    out = torch.full((_H * _W,), 0.5, dtype=_F64)
    out[inside] = image[row[inside], col[inside]]
    return out.reshape(_H, _W)


@figure(
    "cameras",
    "cameras_undistortion.png",
    "Lens distortion, its exact inverse, and where a lens folds",
    "Left: a flat checkerboard seen through an OpenCVCamera with barrel distortion "
    "(k1 = -0.3, k2 = 0.08, p1 = 1e-3, p2 = -5e-4), each pixel coloured by its "
    "undistorted point (pixel_rays). Middle: the same image resampled onto the pinhole "
    "camera with distort: the lines are straight again. Right: a lens that folds inside "
    "the image (k1 = -0.45, k2 = 0.05: the radial map r -> r (1 + k1 r^2 + k2 r^4) stops "
    "increasing at r = 0.941); undistort marks the pixels beyond the fold invalid (red), "
    "where no point of the monotone domain maps.",
)
def _undistortion(path: Path) -> None:
    barrel = _camera([-0.3, 0.08, 1e-3, -5e-4])
    image, _ = _seen(barrel)
    fold = _camera([-0.45, 0.05, 0.0, 0.0])
    folded, valid = _seen(fold)
    rgb = torch.stack([folded] * 3, -1) * 0.8 + 0.1
    rgb[~valid] = torch.tensor([0.85, 0.25, 0.2], dtype=_F64)

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    axes[0].imshow(image.numpy(), cmap="gray", vmin=-0.2, vmax=1.2)
    axes[0].set_title("distorted (OpenCVCamera, barrel)", fontsize=10)
    axes[1].imshow(_undistorted(barrel, image).numpy(), cmap="gray", vmin=-0.2, vmax=1.2)
    axes[1].set_title("undistorted: resampled with distort", fontsize=10)
    axes[2].imshow(rgb.numpy())
    axes[2].set_title("folding lens: invalid beyond the fold (red)", fontsize=10)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    save(fig, path)
