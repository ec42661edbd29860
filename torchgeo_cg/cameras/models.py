"""Camera models as thin modules: :class:`PinholeCamera`, :class:`OpenCVCamera`,
:class:`FisheyeCamera`.

Each holds its tensors as buffers (``K``, ``distortion``, ``extrinsics``; they survive
``.to()``, ``deepcopy`` and ``state_dict``) and calls the pure functions of
:mod:`torchgeo_cg.cameras.projection` and :mod:`torchgeo_cg.cameras.distortion`, so
the module and the function always agree. Buffers may require grad (calibration).
"""

from __future__ import annotations

import torch
from torch import nn

from torchgeo_cg.cameras.distortion import (
    UndistortResult,
    distort_points,
    fisheye_distort_points,
    fisheye_undistort_points,
    undistort_points,
)
from torchgeo_cg.cameras.projection import (
    RayBundle,
    UnprojectResult,
    pixel_rays,
    project_points,
    unproject_points,
)
from torchgeo_cg.core.check import ShapeError, check_broadcastable, check_float, check_shape
from torchgeo_cg.core.coerce import check_module_dtype, check_same_dtype

__all__ = ["PinholeCamera", "OpenCVCamera", "FisheyeCamera"]


def _image_size(image_size) -> tuple[int, int] | None:
    if image_size is None:
        return None
    size = tuple(int(s) for s in image_size)
    if len(size) != 2 or min(size) < 0:
        raise ValueError(f"image_size: expected (H, W) with H, W >= 0, got {image_size}")
    return size


class _Camera(nn.Module):
    """The shared machinery: buffers, checks and the methods over the pure functions."""

    _model = "opencv"

    def __init__(self, K: torch.Tensor, distortion: torch.Tensor | None,
                 extrinsics: torch.Tensor | None, image_size) -> None:
        super().__init__()
        check_float(K, "K")
        check_shape(K, ["*", "3", "3"], "K")
        if extrinsics is not None:
            check_float(extrinsics, "extrinsics")
            check_shape(extrinsics, ["*", "4", "4"], "extrinsics")
        named = {"K": K, "distortion": distortion, "extrinsics": extrinsics}
        check_same_dtype({k: v for k, v in named.items() if v is not None})
        dims = {"K": 2, "distortion": 1, "extrinsics": 2}
        check_broadcastable({k: v.shape[: v.dim() - dims[k]] for k, v in named.items()
                             if v is not None})
        self.register_buffer("K", K)
        self.register_buffer("distortion", distortion)
        self.register_buffer("extrinsics", extrinsics)
        self.image_size = _image_size(image_size)

    def _check(self, x: torch.Tensor, name: str) -> None:
        check_module_dtype(self, x, name)

    def project(self, points: torch.Tensor) -> torch.Tensor:
        """Pixels ``(*, N, 2)`` of world points ``(*, N, 3)``
        (:func:`~torchgeo_cg.cameras.project_points`)."""
        self._check(points, "points")
        return project_points(points, self.K, self.distortion, self.extrinsics, self._model)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """Same as ``project``."""
        return self.project(points)

    def depth(self, points: torch.Tensor) -> torch.Tensor:
        """Camera-frame ``z`` ``(*, N)`` of world points ``(*, N, 3)``."""
        self._check(points, "points")
        check_float(points, "points")
        check_shape(points, ["*", "N", "3"], "points")
        if self.extrinsics is None:
            return points[..., 2]
        e = self.extrinsics
        return (points * e[..., None, 2, :3]).sum(-1) + e[..., None, 2, 3]

    def unproject(self, pixels: torch.Tensor, depth: torch.Tensor) -> UnprojectResult:
        """World points from pixels ``(*, N, 2)`` and camera-frame ``z`` ``(*, N)``
        (:func:`~torchgeo_cg.cameras.unproject_points`)."""
        self._check(pixels, "pixels")
        return unproject_points(pixels, depth, self.K, self.distortion, self.extrinsics,
                                self._model)

    def pixel_grid(self) -> torch.Tensor:
        """Every pixel centre of ``image_size (H, W)``, ``(H, W, 2)`` as ``(u, v)``."""
        if self.image_size is None:
            raise ValueError("image_size: needed for the pixel grid, got None")
        h, w = self.image_size
        v, u = torch.meshgrid(torch.arange(h, dtype=self.K.dtype, device=self.K.device),
                              torch.arange(w, dtype=self.K.dtype, device=self.K.device),
                              indexing="ij")
        return torch.stack([u, v], -1)

    def pixel_rays(self, pixels: torch.Tensor | None = None) -> RayBundle:
        """Rays through pixels ``(*, N, 2)``, or through every pixel centre of
        ``image_size`` (then shaped ``(*, H, W, 3)``) (:func:`~torchgeo_cg.cameras.pixel_rays`)."""
        if pixels is not None:
            self._check(pixels, "pixels")
            return pixel_rays(pixels, self.K, self.distortion, self.extrinsics, self._model)
        grid = self.pixel_grid()
        h, w = grid.shape[:2]
        rays = pixel_rays(grid.reshape(h * w, 2), self.K, self.distortion, self.extrinsics,
                          self._model)
        return RayBundle(*(x.reshape(*x.shape[:-2], h, w, *x.shape[-1:]) for x in rays[:2]),
                         rays.valid.reshape(*rays.valid.shape[:-1], h, w))

    def distort(self, xy: torch.Tensor) -> torch.Tensor:
        """Distorted normalised coordinates ``(*, N, 2)`` (the identity for a pinhole)."""
        self._check(xy, "xy")
        if self.distortion is None:
            check_float(xy, "xy")
            check_shape(xy, ["*", "N", "2"], "xy")
            return xy
        if self._model == "fisheye":
            return fisheye_distort_points(xy, self.distortion)
        return distort_points(xy, self.distortion)

    def undistort(self, xy: torch.Tensor) -> UndistortResult:
        """The exact inverse of ``distort``, with ``valid``."""
        self._check(xy, "xy")
        if self.distortion is None:
            check_float(xy, "xy")
            check_shape(xy, ["*", "N", "2"], "xy")
            return UndistortResult(xy, torch.ones_like(xy[..., 0], dtype=torch.bool))
        if self._model == "fisheye":
            return fisheye_undistort_points(xy, self.distortion)
        return undistort_points(xy, self.distortion)


class PinholeCamera(_Camera):
    """A pinhole camera: intrinsics, optional extrinsics and image size.

    Convention:
        OpenCV's camera frame (x right, y down, z forward); pixel centres at integer
        ``(u, v)``; ``extrinsics`` world-to-camera ``[[R, t], [0, 1]]`` on column
        vectors (``None``: the identity). See :mod:`torchgeo_cg.cameras.projection`.

    Args:
        K: ``(*, 3, 3)`` intrinsics ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``.
        extrinsics: ``(*, 4, 4)`` or ``None``.
        image_size: ``(H, W)`` or ``None`` (needed by ``pixel_rays()`` without pixels).

    Example:
        >>> K = torch.tensor([[100.0, 0.0, 1.5], [0.0, 100.0, 0.5], [0.0, 0.0, 1.0]])
        >>> cam = PinholeCamera(K, image_size=(2, 4))
        >>> cam.project(torch.tensor([[0.01, 0.0, 1.0]]))
        tensor([[2.5000, 0.5000]])
        >>> cam.pixel_rays().directions.shape
        torch.Size([2, 4, 3])
    """

    def __init__(self, K: torch.Tensor, extrinsics: torch.Tensor | None = None,
                 image_size=None) -> None:
        super().__init__(K, None, extrinsics, image_size)


class OpenCVCamera(_Camera):
    """A camera with OpenCV's lens distortion, the model of ``cv2.projectPoints``.

    Convention:
        As :class:`PinholeCamera`; ``distortion`` in OpenCV's order ``k1, k2, p1, p2[, k3[,
        k4, k5, k6[, s1, s2, s3, s4[, tx, ty]]]]`` (:func:`~torchgeo_cg.cameras.distort_points`).

    Args:
        K: ``(*, 3, 3)``.
        distortion: ``(*, P)``, ``P`` in ``{4, 5, 8, 12, 14}``.
        extrinsics: ``(*, 4, 4)`` or ``None``.
        image_size: ``(H, W)`` or ``None``.

    Example:
        >>> K = torch.tensor([[100.0, 0.0, 50.0], [0.0, 100.0, 50.0], [0.0, 0.0, 1.0]])
        >>> cam = OpenCVCamera(K, torch.tensor([-0.2, 0.0, 0.0, 0.0]))
        >>> px = cam.project(torch.tensor([[0.5, 0.0, 1.0]]))
        >>> px
        tensor([[97.5000, 50.0000]])
        >>> cam.unproject(px, torch.tensor([1.0])).points
        tensor([[0.5000, 0.0000, 1.0000]])
    """

    def __init__(self, K: torch.Tensor, distortion: torch.Tensor,
                 extrinsics: torch.Tensor | None = None, image_size=None) -> None:
        check_float(distortion, "distortion")
        p = check_shape(distortion, ["*", "P"], "distortion")["P"]
        if p not in (4, 5, 8, 12, 14):
            raise _length_error(tuple(distortion.shape), (4, 5, 8, 12, 14))
        super().__init__(K, distortion, extrinsics, image_size)


class FisheyeCamera(_Camera):
    """A Kannala-Brandt fisheye camera, the model of ``cv2.fisheye.projectPoints``.

    Convention:
        As :class:`PinholeCamera`, with the incidence angle ``theta = atan2(|(X, Y)|, Z)``
        distorted to ``theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``.
        ``pixel_rays`` covers ``[0, pi)``; ``undistort`` returns
        pinhole-normalised points (``[0, pi/2)``); ``unproject`` takes the
        camera-frame ``z`` or, with ``ray_distance=True``, the distance along the ray.

    Args:
        K: ``(*, 3, 3)``.
        distortion: ``(*, 4)`` ``k1, k2, k3, k4``.
        extrinsics: ``(*, 4, 4)`` or ``None``.
        image_size: ``(H, W)`` or ``None``.

    Example:
        >>> K = torch.tensor([[100.0, 0.0, 50.0], [0.0, 100.0, 50.0], [0.0, 0.0, 1.0]])
        >>> cam = FisheyeCamera(K, torch.zeros(4))
        >>> d = cam.pixel_rays(torch.tensor([[50.0 + 100 * 2.0, 50.0]])).directions
        >>> round(float(torch.rad2deg(torch.acos(d[0, 2]))), 3)  # 2 rad off the axis
        114.592
    """

    _model = "fisheye"

    def __init__(self, K: torch.Tensor, distortion: torch.Tensor,
                 extrinsics: torch.Tensor | None = None, image_size=None) -> None:
        check_float(distortion, "distortion")
        if check_shape(distortion, ["*", "P"], "distortion")["P"] != 4:
            raise _length_error(tuple(distortion.shape), (4,))
        super().__init__(K, distortion, extrinsics, image_size)

    def unproject(self, pixels: torch.Tensor, depth: torch.Tensor,
                  ray_distance: bool = False) -> UnprojectResult:
        """World points from pixels and depth (camera ``z``, or the distance along the ray)."""
        self._check(pixels, "pixels")
        return unproject_points(pixels, depth, self.K, self.distortion, self.extrinsics,
                                "fisheye", ray_distance=ray_distance)


def _length_error(shape: tuple, lengths: tuple[int, ...]) -> ShapeError:
    return ShapeError(f"distortion: expected shape (*, P) with P in "
                       f"{{{', '.join(map(str, lengths))}}}, got {shape}")
