"""Projection, unprojection and pixel rays as pure functions on tensors.

Convention:
    OpenCV's camera frame: x right, y down, z forward. Pixel ``(u, v)``: ``u`` along the
    image row (right), ``v`` down, integer coordinates at pixel centres (OpenCV's rule:
    the top-left pixel's centre is ``(0, 0)``, its corner ``(-0.5, -0.5)``).
    ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` maps normalised coordinates to pixels,
    ``u = fx x + s y + cx``, ``v = fy y + cy`` (its last row is not read).
    ``extrinsics`` is world-to-camera ``[[R, t], [0, 1]]`` (``R`` a rotation) acting on
    column vectors, ``p_cam = R p_world + t``; ``None`` is the identity.
    ``model``: ``"opencv"`` (pinhole when ``distortion`` is ``None``; the model of
    ``cv2.projectPoints``) or ``"fisheye"`` (Kannala-Brandt, ``cv2.fisheye``).

Every function computes in float64 and returns the input's dtype (see
:mod:`torchgeo_cg.cameras.distortion` on precision).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.cameras._fisheye import fisheye_angle
from torchgeo_cg.cameras.distortion import distort_points, undistort_points
from torchgeo_cg.core.check import (
    ShapeError,
    check_broadcastable,
    check_choice,
    check_float,
    check_shape,
)
from torchgeo_cg.core.coerce import check_same_dtype
from torchgeo_cg.core.numerics import cast_back

__all__ = ["UnprojectResult", "RayBundle", "project_points", "unproject_points", "pixel_rays"]

_MODELS = ("opencv", "fisheye")


class UnprojectResult(NamedTuple):
    """The result of :func:`unproject_points`.

    Attributes:
        points: ``(*, N, 3)`` world points.
        valid: ``(*, N)`` bool: the pixel has a preimage in the lens's invertible domain
            and the depth is positive (and, for the fisheye's z-depth, the ray points
            forward).
    """

    points: torch.Tensor
    valid: torch.Tensor


class RayBundle(NamedTuple):
    """The result of :func:`pixel_rays`.

    Attributes:
        origins: ``(*, N, 3)`` the camera centre in world coordinates, per ray.
        directions: ``(*, N, 3)`` unit directions in world coordinates.
        valid: ``(*, N)`` bool: the pixel has a preimage in the lens's invertible domain.
    """

    origins: torch.Tensor
    directions: torch.Tensor
    valid: torch.Tensor


def _check_camera(K, distortion, extrinsics, model, tensors: dict, batches: dict) -> None:
    """Validate the camera's tensors; ``tensors``/``batches`` already hold the data's."""
    check_choice(model, _MODELS, "model")
    check_float(K, "K")
    check_shape(K, ["*", "3", "3"], "K")
    tensors["K"], batches["K"] = K, K.shape[:-2]
    if model == "fisheye" and distortion is None:
        raise ValueError("distortion: the fisheye model needs its (*, 4) coefficients")
    if distortion is not None:
        check_float(distortion, "distortion")
        p = check_shape(distortion, ["*", "P"], "distortion")["P"]
        lengths = (4,) if model == "fisheye" else (4, 5, 8, 12, 14)
        if p not in lengths:
            raise ShapeError(f"distortion: expected shape (*, P) with P in "
                             f"{{{', '.join(map(str, lengths))}}}, got "
                             f"{tuple(distortion.shape)}")
        tensors["distortion"], batches["distortion"] = distortion, distortion.shape[:-1]
    if extrinsics is not None:
        check_float(extrinsics, "extrinsics")
        check_shape(extrinsics, ["*", "4", "4"], "extrinsics")
        tensors["extrinsics"], batches["extrinsics"] = extrinsics, extrinsics.shape[:-2]
    check_same_dtype(tensors)
    check_broadcastable(batches)


def _work(*tensors):
    """The tensors in float64, the computing dtype (see the module's note on precision)."""
    return [None if t is None else t.to(torch.float64) for t in tensors]


def _to_camera(points: torch.Tensor, extrinsics: torch.Tensor | None) -> torch.Tensor:
    if extrinsics is None:
        return points
    return points @ extrinsics[..., :3, :3].mT + extrinsics[..., None, :3, 3]


def _to_world(points: torch.Tensor, extrinsics: torch.Tensor | None) -> torch.Tensor:
    if extrinsics is None:
        return points
    return (points - extrinsics[..., None, :3, 3]) @ extrinsics[..., :3, :3]


def _centre(extrinsics: torch.Tensor | None, like: torch.Tensor) -> torch.Tensor:
    """The camera centre ``-R^T t`` in world coordinates, ``(*, 1, 3)``."""
    if extrinsics is None:
        return like.new_zeros(1, 3)
    return -(extrinsics[..., None, :3, 3] @ extrinsics[..., :3, :3])


def _inv(x: torch.Tensor) -> torch.Tensor:
    """``1 / x``, and 0 where ``x`` is 0 (with a zero gradient there)."""
    ok = x != 0
    return torch.where(ok, 1 / torch.where(ok, x, torch.ones_like(x)), 0.0)


def _to_pixels(xy: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    x, y = xy[..., 0], xy[..., 1]
    u = K[..., 0, 0, None] * x + K[..., 0, 1, None] * y + K[..., 0, 2, None]
    v = K[..., 1, 1, None] * y + K[..., 1, 2, None]
    return torch.stack([u, v], -1)


def _from_pixels(pixels: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    y = (pixels[..., 1] - K[..., 1, 2, None]) * _inv(K[..., 1, 1, None])
    x = (pixels[..., 0] - K[..., 0, 2, None] - K[..., 0, 1, None] * y) * _inv(K[..., 0, 0, None])
    return torch.stack([x, y], -1)


def _fisheye_normalised(cam: torch.Tensor, distortion: torch.Tensor) -> torch.Tensor:
    """Distorted fisheye coordinates ``theta_d (X, Y) / rho``, ``theta = atan2(rho, Z)``."""
    xy, z = cam[..., :2], cam[..., 2]
    sq = (xy * xy).sum(-1)
    ok = sq > 0
    rho = torch.where(ok, torch.sqrt(torch.where(ok, sq, torch.ones_like(sq))), 0.0)
    theta = torch.atan2(rho, z)
    k1, k2, k3, k4 = (distortion[..., i, None] for i in range(4))
    t2 = theta * theta
    theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    scale = torch.where(ok, theta_d * _inv(rho), _inv(z))
    return xy * scale[..., None]


def project_points(points: torch.Tensor, K: torch.Tensor, distortion: torch.Tensor | None = None,
                   extrinsics: torch.Tensor | None = None, model: str = "opencv") -> torch.Tensor:
    """Project world points to pixels.

    Convention:
        See :mod:`torchgeo_cg.cameras.projection`. ``"opencv"``: ``(x, y) = (X / Z, Y / Z)``
        (``1 / Z`` read as 1 where ``Z = 0``, as OpenCV does), then
        :func:`~torchgeo_cg.cameras.distort_points`, then ``K``: ``cv2.projectPoints``.
        ``"fisheye"``: the incidence angle ``theta = atan2(|(X, Y)|, Z)`` (points behind
        the camera included), then Kannala-Brandt: ``cv2.fisheye.projectPoints`` for
        ``Z > 0``.

    Args:
        points: ``(*, N, 3)`` world points.
        K: ``(*, 3, 3)`` intrinsics.
        distortion: ``(*, P)`` or ``None`` (pinhole).
        extrinsics: ``(*, 4, 4)`` world-to-camera or ``None``.
        model: ``"opencv"`` or ``"fisheye"``.

    Returns:
        ``(*, N, 2)`` pixels; differentiable in every tensor.

    Example:
        >>> K = torch.tensor([[100.0, 0.0, 64.0], [0.0, 100.0, 48.0], [0.0, 0.0, 1.0]])
        >>> project_points(torch.tensor([[0.1, -0.2, 2.0]]), K)
        tensor([[69., 38.]])
    """
    tensors, batches = {"points": points}, {"points": points.shape[:-2]}
    check_float(points, "points")
    check_shape(points, ["*", "N", "3"], "points")
    _check_camera(K, distortion, extrinsics, model, tensors, batches)
    dtype = points.dtype
    points, K, distortion, extrinsics = _work(points, K, distortion, extrinsics)
    cam = _to_camera(points, extrinsics)
    if model == "fisheye":
        xy = _fisheye_normalised(cam, distortion)
    else:
        z = cam[..., 2]
        xy = cam[..., :2] * torch.where(z != 0, _inv(z), 1.0)[..., None]
        if distortion is not None:
            xy = distort_points(xy, distortion)
    return cast_back(_to_pixels(xy, K), dtype)


def _check_pixels(pixels: torch.Tensor, depth: torch.Tensor | None, tensors, batches) -> None:
    check_float(pixels, "pixels")
    sizes = check_shape(pixels, ["*", "N", "2"], "pixels")
    tensors["pixels"], batches["pixels"] = pixels, pixels.shape[:-2]
    if depth is not None:
        check_float(depth, "depth")
        check_shape(depth, ["*", "N"], "depth", {"N": sizes["N"]})
        tensors["depth"], batches["depth"] = depth, depth.shape[:-1]


def _camera_rays(pixels, K, distortion, model, cap: float):
    """Camera-frame ``(direction, valid)``: unit directions for ``"opencv"``/``"fisheye"``."""
    xy = _from_pixels(pixels, K)
    if model == "fisheye":
        sq = (xy * xy).sum(-1)
        ok = sq > 0
        rd = torch.where(ok, torch.sqrt(torch.where(ok, sq, torch.ones_like(sq))), 0.0)
        theta, valid = fisheye_angle(rd, distortion, cap)
        side = torch.where(ok, torch.sin(theta) * _inv(rd), 1.0)
        direction = torch.cat([xy * side[..., None], torch.cos(theta)[..., None]], -1)
        return direction, valid
    valid = torch.ones_like(xy[..., 0], dtype=torch.bool)
    if distortion is not None:
        xy, valid = undistort_points(xy, distortion)
    ray = torch.cat([xy, torch.ones_like(xy[..., :1])], -1)
    return ray * torch.rsqrt((ray * ray).sum(-1, keepdim=True)), valid


def unproject_points(pixels: torch.Tensor, depth: torch.Tensor, K: torch.Tensor,
                     distortion: torch.Tensor | None = None,
                     extrinsics: torch.Tensor | None = None, model: str = "opencv",
                     ray_distance: bool = False) -> UnprojectResult:
    """Lift pixels with their depth back to world points; the inverse of :func:`project_points`.

    Convention:
        As :func:`project_points`. ``depth`` is the camera-frame ``z``; with
        ``ray_distance=True`` (fisheye only) it is the distance from the camera centre
        along the ray, which also covers the rays beyond 90 degrees. The lens is inverted
        exactly (:func:`~torchgeo_cg.cameras.undistort_points`); ``depth <= 0`` is
        computed and flagged in ``valid``.

    Args:
        pixels: ``(*, N, 2)``.
        depth: ``(*, N)``.
        K, distortion, extrinsics, model: as :func:`project_points`.
        ray_distance: ``depth`` is the distance along the ray (``"fisheye"`` only).

    Returns:
        :class:`UnprojectResult` ``(points (*, N, 3), valid (*, N))``.

    Example:
        >>> K = torch.tensor([[100.0, 0.0, 64.0], [0.0, 100.0, 48.0], [0.0, 0.0, 1.0]])
        >>> unproject_points(torch.tensor([[69.0, 38.0]]), torch.tensor([2.0]), K)
        UnprojectResult(points=tensor([[ 0.1000, -0.2000,  2.0000]]), valid=tensor([True]))
    """
    tensors, batches = {}, {}
    _check_pixels(pixels, depth, tensors, batches)
    _check_camera(K, distortion, extrinsics, model, tensors, batches)
    if ray_distance and model != "fisheye":
        raise ValueError("ray_distance: only the fisheye model takes distances along rays")
    dtype = pixels.dtype
    pixels, depth, K, distortion, extrinsics = _work(pixels, depth, K, distortion,
                                                     extrinsics)
    if model == "fisheye":
        direction, valid = _camera_rays(pixels, K, distortion, model, math.pi)
        if ray_distance:
            cam = direction * depth[..., None]
        else:
            forward = direction[..., 2]
            valid = valid & (forward > 0)
            cam = direction * (depth * _inv(forward))[..., None]
    else:
        xy = _from_pixels(pixels, K)
        valid = torch.ones_like(xy[..., 0], dtype=torch.bool)
        if distortion is not None:
            xy, valid = undistort_points(xy, distortion)
        cam = torch.cat([xy, torch.ones_like(xy[..., :1])], -1) * depth[..., None]
    world = _to_world(cam, extrinsics)
    return UnprojectResult(cast_back(world, dtype), valid & (depth > 0))


def pixel_rays(pixels: torch.Tensor, K: torch.Tensor, distortion: torch.Tensor | None = None,
               extrinsics: torch.Tensor | None = None, model: str = "opencv") -> RayBundle:
    """One ray per pixel: the camera centre and the unit direction, in world coordinates.

    Convention:
        As :func:`project_points`; ``project_points(origin + d * direction)`` is the pixel
        for every ``d > 0``. The fisheye's rays cover incidence angles in ``[0, pi)``.

    Args:
        pixels: ``(*, N, 2)``.
        K, distortion, extrinsics, model: as :func:`project_points`.

    Returns:
        :class:`RayBundle` ``(origins (*, N, 3), directions (*, N, 3), valid (*, N))``.

    Example:
        >>> K = torch.tensor([[100.0, 0.0, 64.0], [0.0, 100.0, 48.0], [0.0, 0.0, 1.0]])
        >>> pixel_rays(torch.tensor([[64.0, 48.0]]), K).directions
        tensor([[0., 0., 1.]])
    """
    tensors, batches = {}, {}
    _check_pixels(pixels, None, tensors, batches)
    _check_camera(K, distortion, extrinsics, model, tensors, batches)
    dtype = pixels.dtype
    pixels, K, distortion, extrinsics = _work(pixels, K, distortion, extrinsics)
    direction, valid = _camera_rays(pixels, K, distortion, model, math.pi)
    if extrinsics is not None:
        direction = direction @ extrinsics[..., :3, :3]
    origins = _centre(extrinsics, pixels).expand_as(direction)
    return RayBundle(cast_back(origins, dtype), cast_back(direction, dtype), valid)
