"""Gallery figures for image registration and robust (RANSAC) homography fits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from torchgeo_cg.transforms import (
    RobustFit,
    find_transform_ransac,
    register_images,
    warp_image,
)
from torchgeo_cg.viz._style import plt, save
from torchgeo_cg.viz.registry import figure

__all__: list[str] = []


def _plot_registration(source: torch.Tensor, target: torch.Tensor, matrix: torch.Tensor,
                      path: str | Path) -> None:
    """Source, target and ``|target(M p) - source(p)|`` before (M = I) and after, to ``path``.

    The differences are taken after a least-squares gain and offset (so a
    brightness change does not show) and are 0 where ``M p`` leaves the target.

    Args:
        source: ``(H, W)`` gray image.
        target: ``(H2, W2)`` gray image.
        matrix: ``(3, 3)`` ``target_from_source`` (pixels, x right, y down).
        path: the image file to write.

    Example:
        >>> import pathlib, tempfile
        >>> out = pathlib.Path(tempfile.mkdtemp()) / "reg.png"
        >>> img = torch.rand(32, 32)
        >>> _plot_registration(img, img, torch.eye(3), out)
        >>> out.stat().st_size > 5_000
        True
    """
    src, tgt = source.detach().cpu().float(), target.detach().cpu().float()
    panels = [("source", src), ("target", tgt)]
    for label, m in (("before: |target - source|", torch.eye(3)),
                     ("after: |target(M p) - source(p)|", matrix.detach().cpu().float())):
        out = warp_image(tgt[None, None], m, tuple(src.shape))
        warped, valid = out.image[0, 0], out.valid[0, 0]
        # undo a global gain and offset (least squares on the valid pixels), as loss="ncc"
        a = torch.stack([src[valid], torch.ones_like(src[valid])], -1)
        gain, offset = torch.linalg.lstsq(a, warped[valid, None]).solution[:, 0]
        gain = gain if gain != 0 else torch.ones_like(gain)
        panels.append((label, torch.where(valid, ((warped - offset) / gain - src).abs(), 0.0)))
    fig, axes = plt.subplots(1, 4, figsize=(16, 4.4), constrained_layout=True)
    vmax = float(panels[2][1].max()) or 1.0
    for ax, (label, img) in zip(axes, panels):
        diff = label.startswith(("before", "after"))
        ax.imshow(img.numpy(), cmap="magma" if diff else "gray",
                  vmin=0, vmax=vmax if diff else None)
        ax.set_title(label, fontsize=9)
        ax.set_axis_off()
    save(fig, Path(path))


def _plot_robust_fit(image0: np.ndarray, image1: np.ndarray, src: torch.Tensor,
                    dst: torch.Tensor, fit: RobustFit, path: str | Path) -> None:
    """Two views side by side with their matches: inliers green, outliers red, to ``path``.

    Args:
        image0: ``(H, W)`` first view.
        image1: ``(H, W)`` second view.
        src: ``(N, 2)`` matched points in ``image0`` (x, y pixels).
        dst: ``(N, 2)`` matched points in ``image1``.
        fit: a single-problem :class:`~torchgeo_cg.transforms.RobustFit`.
        path: the image file to write.

    Example:
        >>> import pathlib, tempfile
        >>> out = pathlib.Path(tempfile.mkdtemp()) / "ransac.png"
        >>> pts = torch.rand(30, 2) * 31
        >>> fit = find_transform_ransac(pts, pts + 1.0, generator=torch.Generator().manual_seed(0))
        >>> _plot_robust_fit(np.zeros((32, 32)), np.zeros((32, 32)), pts, pts + 1.0, fit, out)
        >>> out.stat().st_size > 5_000
        True
    """
    width = image0.shape[1]
    fig, ax = plt.subplots(figsize=(12, 6.2), constrained_layout=True)
    ax.imshow(np.concatenate([image0, image1], axis=1), cmap="gray")
    s, d = src.detach().cpu().numpy(), dst.detach().cpu().numpy()
    inl = fit.inliers.detach().cpu().numpy()
    for mask, color, label in ((~inl, "tab:red", "outliers"), (inl, "lime", "inliers")):
        xs = np.stack([s[mask, 0], d[mask, 0] + width])
        ys = np.stack([s[mask, 1], d[mask, 1]])
        ax.plot(xs, ys, "-", color=color, lw=0.7, alpha=0.8)
        ax.plot([], [], "-", color=color, label=f"{label} ({int(mask.sum())})")
    ax.legend(loc="lower right", fontsize=9)
    ax.set_axis_off()
    save(fig, Path(path))


def _camera_pair(size: int = 256, off: int = 128):
    from skimage.data import camera

    big = torch.from_numpy(camera()).float()[None, None] / 255
    source = big[0, 0, off:off + size, off:off + size]
    truth = torch.tensor([[1.02, 0.03, -4.0], [-0.02, 0.99, 6.0], [2e-5, -3e-5, 1.0]])
    t_off = torch.tensor([[1.0, 0.0, off], [0.0, 1.0, off], [0.0, 0.0, 1.0]])
    target = warp_image(big, t_off @ torch.linalg.inv(truth), (size, size)).image[0, 0]
    gen = torch.Generator().manual_seed(0)
    return source, 0.8 * target + 0.1 + 0.02 * torch.randn(target.shape, generator=gen)


@figure(
    "estimation",
    "registration_before_after.png",
    "Image registration by inverse-compositional Lucas-Kanade",
    "skimage's camera (256 px crop, left) and a view of it through a homography moving the "
    "corners by ~6 px, with 20% less contrast, +0.1 brightness and noise (second). "
    "register_images(loss='ncc', 3 pyramid levels) fits target(M p) ≈ source(p) in 9 steps; "
    "the difference images before (M = I) and after registration (after a global gain and "
    "offset, 0 where M p leaves the target) share one colour scale: only the noise is left "
    "(corner error 0.03 px).",
)
def _registration(path: Path) -> None:
    source, target = _camera_pair()
    fit = register_images(source[None, None], target[None, None], loss="ncc")
    _plot_registration(source, target, fit.matrix[0], path)


@figure(
    "estimation",
    "registration_ransac_matches.png",
    "RANSAC on ORB matches: inliers and outliers",
    "ORB features (scikit-image) matched between skimage's astronaut and a view of it through "
    "a known homography; find_transform_ransac (LO-RANSAC, MSAC scoring, 2 px threshold) "
    "separates the consistent matches (green) from the wrong ones (red).",
)
def _ransac(path: Path) -> None:
    from skimage.color import rgb2gray
    from skimage.data import astronaut
    from skimage.feature import ORB, match_descriptors

    image = rgb2gray(astronaut())
    truth = torch.tensor([[0.9, 0.1, 30.0], [-0.08, 0.95, 20.0], [1e-4, 5e-5, 1.0]])
    view = warp_image(torch.from_numpy(image).float()[None, None],
                      torch.linalg.inv(truth)).image[0, 0].numpy()
    found = []
    for img in (image, view):
        orb = ORB(n_keypoints=400, fast_threshold=0.05)
        orb.detect_and_extract(img)
        found.append((orb.keypoints[:, ::-1].copy(), orb.descriptors))
    pairs = match_descriptors(found[0][1], found[1][1], cross_check=True)
    src = torch.tensor(found[0][0][pairs[:, 0]], dtype=torch.float32)
    dst = torch.tensor(found[1][0][pairs[:, 1]], dtype=torch.float32)
    fit = find_transform_ransac(src, dst, threshold=2.0, generator=torch.Generator().manual_seed(0))
    _plot_robust_fit(image, view, src, dst, fit, path)
