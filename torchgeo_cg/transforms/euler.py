"""Euler angles: the 12 axis sequences, intrinsic (uppercase) and extrinsic (lowercase).

Convention:
    - Sequences as scipy names them: three letters from ``xyz``, consecutive
      letters different; lowercase ``"xyz"`` is *extrinsic* (rotations about the
      fixed axes x, then y, then z: ``R = Rz(γ) Ry(β) Rx(α)``), uppercase ``"XYZ"``
      is *intrinsic* (about the moving axes: ``R = Rx(α) Ry(β) Rz(γ)``).
    - Angles in degrees unless ``degrees=False`` (the 2D angle convention);
      positive angles turn counter-clockwise looking down the axis.
    - :func:`matrix_to_euler` returns the first and third angles in ``(-180, 180]``,
      the second in ``[0, 180]`` for proper sequences (``"zxz"``) and in
      ``[-90, 90]`` for Tait-Bryan ones (``"xyz"``).
    - Gimbal lock (second angle at 0 or 180 for proper sequences, ±90 for
      Tait-Bryan ones, where the first and third axes coincide): only their sum
      or difference is defined. As scipy does, the third angle is set to 0 and
      the first carries the rotation. Lock is decided relative to the dtype's
      precision (``|sin|`` of the half-angle below ``eps`` times the other),
      not at scipy's absolute 1e-7 rad; gradients stay finite there. Setting the
      third angle to 0 moves the rebuilt matrix by about the middle angle's distance
      from the lock, so that distance is kept within ``eps``: the returned angles
      rebuild the matrix to the dtype's accuracy (1e-6 in float32) on both sides of
      every lock, for all 24 sequences.
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.core.numerics import cast_back, hypot, working_dtype
from torchgeo_cg.transforms._so3 import quat_from_matrix

__all__ = ["euler_to_matrix", "matrix_to_euler"]

_AXES = "xyz"


def _check_seq(seq: str) -> tuple[list[int], bool]:
    """Axis indices and ``extrinsic`` of a scipy-style sequence, or ValueError naming ``seq``."""
    ok = (isinstance(seq, str) and len(seq) == 3 and (seq.islower() or seq.isupper())
          and all(c in _AXES for c in seq.lower()) and seq[0] != seq[1] and seq[1] != seq[2])
    if not ok:
        raise ValueError("seq: expected three axes from 'xyz' (extrinsic) or 'XYZ' "
                         f"(intrinsic), no two consecutive alike, e.g. 'xyz', 'ZXZ'; got {seq!r}")
    return [_AXES.index(c) for c in seq.lower()], seq.islower()


def _elemental(axis: int, angle: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(angle), torch.sin(angle)
    one, zero = torch.ones_like(c), torch.zeros_like(c)
    rows = {0: [one, zero, zero, zero, c, -s, zero, s, c],
            1: [c, zero, s, zero, one, zero, -s, zero, c],
            2: [c, -s, zero, s, c, zero, zero, zero, one]}[axis]
    return torch.stack(rows, -1).unflatten(-1, (3, 3))


def euler_to_matrix(angles: torch.Tensor, seq: str, degrees: bool = True) -> torch.Tensor:
    """Euler angles -> rotation matrix for one of the 12 sequences, as scipy's ``from_euler``.

    Convention:
        See the module: lowercase extrinsic, uppercase intrinsic; degrees unless
        ``degrees=False``.

    Args:
        angles: ``(*, 3)`` the angles, in the order of ``seq``.
        seq: e.g. ``"xyz"`` (extrinsic) or ``"ZYX"`` (intrinsic).
        degrees: unit of ``angles``.

    Returns:
        ``(*, 3, 3)`` rotation matrices.

    Example:
        >>> euler_to_matrix(torch.tensor([90.0, 0.0, 0.0]), "xyz").round(decimals=6) + 0.0
        tensor([[ 1.,  0.,  0.],
                [ 0.,  0., -1.],
                [ 0.,  1.,  0.]])
    """
    axes, extrinsic = _check_seq(seq)
    check_shape(angles, ["*", "3"], "angles")
    check_float(angles, "angles")
    a = angles.to(working_dtype(angles.dtype))
    if degrees:
        a = torch.deg2rad(a)
    r = [_elemental(axis, a[..., i]) for i, axis in enumerate(axes)]
    out = r[2] @ r[1] @ r[0] if extrinsic else r[0] @ r[1] @ r[2]
    return cast_back(out, angles.dtype)


def _wrap(angle: torch.Tensor) -> torch.Tensor:
    """Angles to (-π, π], gradient 1."""
    return math.pi - torch.remainder(math.pi - angle, 2 * math.pi)


def _safe_atan2(y, x, use):
    """``atan2(y, x)`` where ``use``, else 0 with a zero gradient (double ``where``)."""
    y_s = torch.where(use, y, torch.zeros_like(y))
    x_s = torch.where(use, x, torch.ones_like(x))
    return torch.where(use, torch.atan2(y_s, x_s), torch.zeros_like(y))


def _angles_from_quat(q: torch.Tensor, axes: list[int], extrinsic: bool) -> torch.Tensor:
    """Bernardes & Viollet (2022): Euler angles of any sequence straight from the quaternion."""
    i, j, k = axes if extrinsic else axes[::-1]
    proper = i == k
    if proper:
        k = 3 - i - j
    sign = (i - j) * (j - k) * (k - i) // 2
    w, v = q[..., 0], q[..., 1:]
    if proper:
        a, b, c, d = w, v[..., i], v[..., j], v[..., k] * sign
    else:
        a, b = w - v[..., j], v[..., i] + v[..., k] * sign
        c, d = v[..., j] + w, v[..., k] * sign - v[..., i]
    n_ab, n_cd = hypot(a, b), hypot(c, d)
    middle = 2 * torch.atan2(n_cd, n_ab)
    # lock only where dropping the third angle is below rounding (see the module)
    tol = torch.finfo(q.dtype).eps
    lock0, lock_pi = n_cd <= tol * n_ab, n_ab <= tol * n_cd
    half_sum = _safe_atan2(b, a, ~lock_pi)
    half_diff = _safe_atan2(d, c, ~lock0)
    first, third = half_sum - half_diff, half_sum + half_diff
    # at lock the third angle of the returned sequence is 0, the first takes the rotation
    if extrinsic:
        first = torch.where(lock0, 2 * half_sum, torch.where(lock_pi, -2 * half_diff, first))
        third = torch.where(lock0 | lock_pi, torch.zeros_like(third), third)
    else:
        third = torch.where(lock0, 2 * half_sum, torch.where(lock_pi, 2 * half_diff, third))
        first = torch.where(lock0 | lock_pi, torch.zeros_like(first), first)
    if not proper:
        third = third * sign
        middle = middle - math.pi / 2
    out = torch.stack([_wrap(first), middle, _wrap(third)], -1)
    return out if extrinsic else out.flip(-1)


def matrix_to_euler(matrix: torch.Tensor, seq: str, degrees: bool = True) -> torch.Tensor:
    """Rotation matrix -> Euler angles of ``seq``, as scipy's ``as_euler``.

    Through the Shepperd quaternion and the direct method of Bernardes &
    Viollet (2022), which scipy uses too: no ``acos`` clamp, every sequence by
    one formula.

    Convention:
        See the module (ranges, gimbal lock). The gradient is finite
        everywhere; at lock the angle set to 0 has zero gradient.

    Args:
        matrix: ``(*, 3, 3)`` rotation matrices.
        seq: one of the 12 sequences, lowercase extrinsic or uppercase intrinsic.
        degrees: unit of the result.

    Returns:
        ``(*, 3)`` angles in the order of ``seq``.

    Example:
        >>> m = euler_to_matrix(torch.tensor([10.0, 20.0, 30.0], dtype=torch.float64), "ZYX")
        >>> matrix_to_euler(m, "ZYX")
        tensor([10.0000, 20.0000, 30.0000], dtype=torch.float64)
        >>> matrix_to_euler(euler_to_matrix(torch.tensor([30.0, 90.0, 0.0]), "xyz"), "xyz")
        tensor([30.0000, 90.0000,  0.0000])
    """
    axes, extrinsic = _check_seq(seq)
    check_shape(matrix, ["*", "3", "3"], "matrix")
    check_float(matrix, "matrix")
    m = matrix.to(working_dtype(matrix.dtype))
    out = _angles_from_quat(quat_from_matrix(m), axes, extrinsic)
    return cast_back(torch.rad2deg(out) if degrees else out, matrix.dtype)
