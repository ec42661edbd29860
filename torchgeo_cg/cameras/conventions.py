"""Pose conventions: OpenCV, OpenGL (Blender, nerfstudio) and PyTorch3D, and PyTorch3D's
screen-space cameras.

Convention:
    - ``"opencv"``: world-to-camera ``(*, 4, 4)`` ``[[R, t], [0, 1]]`` on column vectors,
      camera axes x right, y down, z forward (this package's extrinsics).
    - ``"opengl"``: camera-to-world ``(*, 4, 4)``, camera axes x right, y up, z backward
      (the poses Blender and nerfstudio store).
    - ``"pytorch3d"``: the pair ``(R (*, 3, 3), T (*, 3))`` of ``PerspectiveCameras``,
      row vectors ``X_view = X_world R + T``, camera axes x left, y up, z forward.

    PyTorch3D's screen space (``in_ndc=False``) puts the corner of the top-left pixel at
    ``(0, 0)``; ours puts its centre there, so our pixel ``u`` is PyTorch3D's ``u - 0.5``:
    the principal point moves by ``+0.5`` on the way to PyTorch3D.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.cameras.models import PinholeCamera
from torchgeo_cg.core.check import check_broadcastable, check_choice, check_float, check_shape
from torchgeo_cg.core.coerce import check_same_dtype

__all__ = ["PyTorch3DCameras", "convert_pose", "to_pytorch3d", "from_pytorch3d"]

_KINDS = ("opencv", "opengl", "pytorch3d")


class PyTorch3DCameras(NamedTuple):
    """The arguments of ``PerspectiveCameras(..., in_ndc=False)``.

    Attributes:
        R: ``(*, 3, 3)``, row-vector rotation.
        T: ``(*, 3)``, translation.
        focal_length: ``(*, 2)`` ``(fx, fy)`` in pixels.
        principal_point: ``(*, 2)`` in PyTorch3D's screen space (pixel corner at 0).
        image_size: ``(*, 2)`` ``(H, W)``.
    """

    R: torch.Tensor
    T: torch.Tensor
    focal_length: torch.Tensor
    principal_point: torch.Tensor
    image_size: torch.Tensor


def _flip(like: torch.Tensor, *signs: float) -> torch.Tensor:
    return torch.diag(like.new_tensor(signs))


def _rigid_inverse(m: torch.Tensor) -> torch.Tensor:
    rot, t = m[..., :3, :3], m[..., :3, 3:]
    top = torch.cat([rot.mT, -(rot.mT @ t)], -1)
    return torch.cat([top, m[..., 3:, :]], -2)


def _to_opencv(pose, src: str) -> torch.Tensor:
    if src == "pytorch3d":
        rot, t = pose
        batch = torch.broadcast_shapes(rot.shape[:-2], t.shape[:-1])
        rot, t = rot.expand(*batch, 3, 3), t.expand(*batch, 3)
        flip = _flip(rot, -1.0, -1.0, 1.0)
        rot_cv = flip @ rot.mT  # R_p3d = R_cv^T F  =>  R_cv = F R_p3d^T
        t_cv = t @ flip
        top = torch.cat([rot_cv, t_cv[..., None]], -1)
        bottom = torch.zeros_like(top[..., :1, :])
        bottom[..., 0, 3] = 1
        return torch.cat([top, bottom], -2)
    if src == "opengl":  # camera-to-world, camera y up, z back
        return _rigid_inverse(pose @ _flip(pose, 1.0, -1.0, -1.0, 1.0))
    return pose


def _check_pose(pose, kind: str, name: str):
    if kind == "pytorch3d":
        if not isinstance(pose, (tuple, list)) or len(pose) != 2:
            raise TypeError(f"{name}: a 'pytorch3d' pose is the pair (R, T), got "
                            f"{type(pose).__name__}")
        rot, t = pose
        check_float(rot, "R")
        check_float(t, "T")
        check_shape(rot, ["*", "3", "3"], "R")
        check_shape(t, ["*", "3"], "T")
        check_same_dtype({"R": rot, "T": t})
        check_broadcastable({"R": rot.shape[:-2], "T": t.shape[:-1]})
        return
    check_float(pose, name)
    check_shape(pose, ["*", "4", "4"], name)


def convert_pose(pose, src: str, dst: str):
    """Convert a camera pose between the OpenCV, OpenGL and PyTorch3D conventions.

    Convention:
        See :mod:`torchgeo_cg.cameras.conventions`: ``"opencv"`` world-to-camera 4x4,
        ``"opengl"`` camera-to-world 4x4 (y up, z back), ``"pytorch3d"`` the row-vector
        pair ``(R, T)``. Rigid poses only (``R`` a rotation).

    Args:
        pose: ``(*, 4, 4)``, or ``(R (*, 3, 3), T (*, 3))`` for ``"pytorch3d"``.
        src: its convention.
        dst: the convention wanted.

    Returns:
        The pose in ``dst``'s form (a tensor, or the pair ``(R, T)``).

    Example:
        >>> pose = torch.eye(4)
        >>> pose[:3, 3] = torch.tensor([0.0, 0.0, 2.0])  # the world origin 2 ahead
        >>> convert_pose(pose, "opencv", "opengl")[:3, 3]  # the camera at z = -2
        tensor([ 0.,  0., -2.])
        >>> R, T = convert_pose(pose, "opencv", "pytorch3d")
        >>> T
        tensor([-0., -0., 2.])
    """
    check_choice(src, _KINDS, "src")
    check_choice(dst, _KINDS, "dst")
    _check_pose(pose, src, "pose")
    cv = _to_opencv(pose, src)
    if dst == "opencv":
        return cv
    if dst == "opengl":
        return _rigid_inverse(cv) @ _flip(cv, 1.0, -1.0, -1.0, 1.0)
    flip = _flip(cv, -1.0, -1.0, 1.0)
    return cv[..., :3, :3].mT @ flip, cv[..., :3, 3] @ flip


def to_pytorch3d(camera: PinholeCamera) -> PyTorch3DCameras:
    """The arguments of an equivalent ``PerspectiveCameras(in_ndc=False)``.

    Convention:
        PyTorch3D's screen-space projection: ``X_view = X_world R + T``, then (its
        documented screen formula, camera x left, y up) ``u_screen = -fx X_view / Z +
        px``, ``v_screen = -fy Y_view / Z + py``, pixel corner at 0: our pixel centre
        ``u`` is ``u_screen - 0.5``. Non-square images need nothing more in screen space.
        Skew and lens distortion have no PyTorch3D counterpart (``ValueError``).

    Args:
        camera: a :class:`~torchgeo_cg.cameras.PinholeCamera` with ``image_size``.

    Returns:
        :class:`PyTorch3DCameras` ``(R, T, focal_length, principal_point, image_size)``.

    Example:
        >>> K = torch.tensor([[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]])
        >>> to_pytorch3d(PinholeCamera(K, image_size=(480, 640))).principal_point
        tensor([320., 240.])
    """
    if not isinstance(camera, PinholeCamera):
        raise TypeError(f"camera: expected a PinholeCamera (PyTorch3D has no lens "
                        f"distortion), got {type(camera).__name__}")
    if camera.image_size is None:
        raise ValueError("camera: image_size is needed by PyTorch3D's screen space, got None")
    K = camera.K
    if bool((K[..., 0, 1] != 0).any()):
        raise ValueError("camera: K has a skew, which PerspectiveCameras cannot express")
    extrinsics = camera.extrinsics
    if extrinsics is None:
        extrinsics = torch.eye(4, dtype=K.dtype, device=K.device).expand(*K.shape[:-2], 4, 4)
    rot, t = convert_pose(extrinsics, "opencv", "pytorch3d")
    focal = torch.stack([K[..., 0, 0], K[..., 1, 1]], -1)
    principal = torch.stack([K[..., 0, 2], K[..., 1, 2]], -1) + 0.5
    size = K.new_tensor(camera.image_size).expand(*focal.shape[:-1], 2)
    return PyTorch3DCameras(rot, t, focal, principal, size)


def from_pytorch3d(R: torch.Tensor, T: torch.Tensor, focal_length: torch.Tensor,
                   principal_point: torch.Tensor, image_size) -> PinholeCamera:
    """A :class:`~torchgeo_cg.cameras.PinholeCamera` equal to ``PerspectiveCameras(in_ndc=False)``.

    Convention:
        The inverse of :func:`to_pytorch3d`: the principal point moves by ``-0.5``.

    Args:
        R: ``(*, 3, 3)``, PyTorch3D's rotation (row vectors).
        T: ``(*, 3)``, PyTorch3D's translation.
        focal_length: ``(*, 2)`` ``(fx, fy)`` in pixels.
        principal_point: ``(*, 2)`` in screen space (pixel corner at 0).
        image_size: ``(H, W)``: numbers, or a tensor whose rows all hold the same size.

    Returns:
        The camera, with extrinsics and image size.

    Example:
        >>> cam = from_pytorch3d(torch.eye(3), torch.zeros(3), torch.tensor([500.0, 500.0]),
        ...                      torch.tensor([320.0, 240.0]), (480, 640))
        >>> cam.K[:2]
        tensor([[500.0000,   0.0000, 319.5000],
                [  0.0000, 500.0000, 239.5000]])
    """
    _check_pose((R, T), "pytorch3d", "pose")
    check_float(focal_length, "focal_length")
    check_float(principal_point, "principal_point")
    check_shape(focal_length, ["*", "2"], "focal_length")
    check_shape(principal_point, ["*", "2"], "principal_point")
    check_same_dtype({"R": R, "focal_length": focal_length, "principal_point": principal_point})
    check_broadcastable({"R": R.shape[:-2], "T": T.shape[:-1],
                         "focal_length": focal_length.shape[:-1],
                         "principal_point": principal_point.shape[:-1]})
    if isinstance(image_size, torch.Tensor):
        image_size = image_size.reshape(-1, 2)[0].tolist()
    extrinsics = convert_pose((R, T), "pytorch3d", "opencv")
    focal_length, principal_point = torch.broadcast_tensors(focal_length, principal_point)
    fx, fy = focal_length[..., 0], focal_length[..., 1]
    cx, cy = principal_point[..., 0] - 0.5, principal_point[..., 1] - 0.5
    zero, one = torch.zeros_like(fx), torch.ones_like(fx)
    K = torch.stack([torch.stack([fx, zero, cx], -1), torch.stack([zero, fy, cy], -1),
                     torch.stack([zero, zero, one], -1)], -2)
    return PinholeCamera(K, extrinsics, image_size)
