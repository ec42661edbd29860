"""3D rotations and rigid motions: conversions, quaternion algebra, SO(3) and SE(3) maps.

Every function is batched over leading dims ``(*)``, differentiable, and follows
the dtype and device of its input (float16/bfloat16 are computed in float32).

Convention:
    - Rotation matrices act on column vectors, ``p' = R @ p``; a positive angle
      about an axis turns counter-clockwise looking down the axis (right hand).
    - Quaternions are ``(w, x, y, z)``, scalar first (PyTorch3D's order; scipy and
      roma put the scalar last). Every quaternion returned has ``w >= 0``; at
      ``w = 0`` (a half-turn) the component of largest magnitude is positive.
    - Rotation vectors (the axis-angle form, ``axis * angle``) are in radians;
      :func:`matrix_to_axis_angle` returns angles in ``[0, π]``, and at exactly
      ``π`` the vector whose quaternion follows the rule above.
    - se(3) vectors are ``(v, ω)``: translation part first, rotation last (as
      PyTorch3D and Sophus). 4x4 rigid motions are ``[[R, t], [0, 1]]``.
    - Series near 0 (``sin θ / θ`` and the like) switch at a threshold relative to
      the dtype's precision, with the double-``where`` idiom: at exactly 0 the
      gradient is the analytic limit.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.check import ShapeError, check_broadcastable, check_float, check_shape
from torchgeo_cg.core.numerics import cast_back, safe_norm, working_dtype
from torchgeo_cg.transforms._so3 import (
    canonical,
    exp_map,
    hat,
    left_jacobian,
    left_jacobian_inverse,
    matrix_from_quat,
    qmul,
    quat_entries,
    quat_from_matrix,
    quat_from_rotvec,
    quat_matrix_entries,
    rodrigues_entries_lazy,
    rotvec_entries,
    rotvec_from_quat,
    sinc,
)
from torchgeo_cg.transforms._so3_blocks import blocks_apply, blockwise
from torchgeo_cg.transforms.averaging import rotation_mean
from torchgeo_cg.transforms.euler import euler_to_matrix, matrix_to_euler

__all__ = [
    "euler_to_matrix",
    "matrix_to_euler",
    "rotation_mean",
    "quaternion_to_matrix",
    "matrix_to_quaternion",
    "axis_angle_to_matrix",
    "matrix_to_axis_angle",
    "axis_angle_to_quaternion",
    "quaternion_to_axis_angle",
    "rotation_6d_to_matrix",
    "matrix_to_rotation_6d",
    "quaternion_multiply",
    "quaternion_conjugate",
    "quaternion_apply",
    "quaternion_slerp",
    "random_rotations",
    "rotation_angle",
    "so3_exp",
    "so3_log",
    "so3_hat",
    "so3_left_jacobian",
    "so3_left_jacobian_inverse",
    "se3_exp",
    "se3_log",
]


def _vec(x: torch.Tensor, size: int, name: str) -> torch.Tensor:
    check_shape(x, ["*", str(size)], name)
    check_float(x, name)
    return x.to(working_dtype(x.dtype))


def _mat(x: torch.Tensor, size: int, name: str) -> torch.Tensor:
    check_shape(x, ["*", str(size), str(size)], name)
    check_float(x, name)
    return x.to(working_dtype(x.dtype))


def _exp(w: torch.Tensor) -> torch.Tensor:
    if blocks_apply(w):
        return blockwise(rodrigues_entries_lazy, w, 9).unflatten(-1, (3, 3))
    return exp_map(w)


def _quat_of(m: torch.Tensor) -> torch.Tensor:
    if blocks_apply(m):
        return blockwise(lambda c: quat_entries(c, lazy=True), m.flatten(-2), 4)
    return quat_from_matrix(m)


def _log(m: torch.Tensor) -> torch.Tensor:
    if blocks_apply(m):
        return blockwise(rotvec_entries, m.flatten(-2), 3)
    return rotvec_from_quat(quat_from_matrix(m))


def _matrix_of(q: torch.Tensor) -> torch.Tensor:
    if blocks_apply(q):
        return blockwise(quat_matrix_entries, q, 9).unflatten(-1, (3, 3))
    return matrix_from_quat(q)


def so3_hat(omega: torch.Tensor) -> torch.Tensor:
    """The skew matrix ``[ω]×`` with ``[ω]× p = ω × p``.

    Args:
        omega: ``(*, 3)`` vectors.

    Returns:
        ``(*, 3, 3)`` skew-symmetric matrices.

    Example:
        >>> so3_hat(torch.tensor([1.0, 2.0, 3.0]))
        tensor([[ 0., -3.,  2.],
                [ 3.,  0., -1.],
                [-2.,  1.,  0.]])
    """
    check_shape(omega, ["*", "3"], "omega")
    check_float(omega, "omega")
    return hat(omega)


def so3_exp(omega: torch.Tensor) -> torch.Tensor:
    """The exponential map of so(3): rotation vector -> rotation matrix (Rodrigues).

    ``R = I + (sin θ/θ) [ω]× + ((1 - cos θ)/θ²) [ω]×²`` with ``θ = |ω|``.

    Convention:
        ``ω`` in radians, right hand. The coefficients are exact at every angle
        (``(1 - cos θ)/θ²`` is computed as ``½ sinc²(θ/2)``), and near 0 by series
        below ``eps^(1/6)``: exact to rounding at 1e-12, 1e-8 or 1e-4 rad (roma's
        first-order cut below 1e-6 is 4e-13 off at 9e-7). The gradient at 0 is
        the limit, ``dR = [δ]×``.

    Args:
        omega: ``(*, 3)`` rotation vectors.

    Returns:
        ``(*, 3, 3)`` rotation matrices.

    Example:
        >>> import math
        >>> so3_exp(torch.tensor([0.0, 0.0, math.pi / 2])).round(decimals=6) + 0.0
        tensor([[ 0., -1.,  0.],
                [ 1.,  0.,  0.],
                [ 0.,  0.,  1.]])
    """
    w = _vec(omega, 3, "omega")
    return cast_back(_exp(w), omega.dtype)


def axis_angle_to_matrix(axis_angle: torch.Tensor) -> torch.Tensor:
    """Rotation vector (``axis * angle``, radians) -> rotation matrix; :func:`so3_exp`.

    Convention:
        See :func:`so3_exp`.

    Args:
        axis_angle: ``(*, 3)`` rotation vectors.

    Returns:
        ``(*, 3, 3)`` rotation matrices.

    Example:
        >>> axis_angle_to_matrix(torch.zeros(3))
        tensor([[1., 0., 0.],
                [0., 1., 0.],
                [0., 0., 1.]])
    """
    w = _vec(axis_angle, 3, "axis_angle")
    return cast_back(_exp(w), axis_angle.dtype)


def matrix_to_quaternion(matrix: torch.Tensor) -> torch.Tensor:
    """Rotation matrix -> unit quaternion ``(w, x, y, z)``, ``w >= 0``.

    Convention:
        Shepperd's method: of the four pivots ``4w², 4x², 4y², 4z²`` the largest
        (at least 1 for a rotation) is taken by a square root and the other
        components from off-diagonal sums, so no branch divides by a small
        number. The result is normalized (a matrix a little off SO(3) gives the
        quaternion of a nearby rotation), then made canonical: ``w >= 0``, and at
        ``w = 0`` the component of largest magnitude positive. Differentiable;
        the gradient is finite at every rotation, 0 and π included.

    Args:
        matrix: ``(*, 3, 3)`` rotation matrices.

    Returns:
        ``(*, 4)`` quaternions.

    Example:
        >>> matrix_to_quaternion(torch.diag(torch.tensor([-1.0, 1.0, -1.0])))
        tensor([0., 0., 1., 0.])
    """
    m = _mat(matrix, 3, "matrix")
    return cast_back(_quat_of(m), matrix.dtype)


def quaternion_to_matrix(quaternion: torch.Tensor) -> torch.Tensor:
    """Quaternion ``(w, x, y, z)`` -> rotation matrix.

    Convention:
        ``q`` and ``-q`` give the same matrix; a non-unit quaternion is
        normalized (through ``2 / |q|²``). The zero quaternion gives NaN
        (it is no rotation).

    Args:
        quaternion: ``(*, 4)`` quaternions, scalar first.

    Returns:
        ``(*, 3, 3)`` rotation matrices.

    Example:
        >>> quaternion_to_matrix(torch.tensor([0.0, 1.0, 0.0, 0.0]))
        tensor([[ 1.,  0.,  0.],
                [ 0., -1.,  0.],
                [ 0.,  0., -1.]])
    """
    q = _vec(quaternion, 4, "quaternion")
    return cast_back(_matrix_of(q), quaternion.dtype)


def axis_angle_to_quaternion(axis_angle: torch.Tensor) -> torch.Tensor:
    """Rotation vector -> unit quaternion ``(cos θ/2, sin(θ/2) axis)``, made ``w >= 0``.

    Args:
        axis_angle: ``(*, 3)`` rotation vectors (radians).

    Returns:
        ``(*, 4)`` quaternions.

    Example:
        >>> import math
        >>> q = axis_angle_to_quaternion(torch.tensor([math.pi, 0.0, 0.0], dtype=torch.float64))
        >>> q.round(decimals=6) + 0.0
        tensor([0., 1., 0., 0.], dtype=torch.float64)
    """
    w = _vec(axis_angle, 3, "axis_angle")
    return cast_back(quat_from_rotvec(w), axis_angle.dtype)


def quaternion_to_axis_angle(quaternion: torch.Tensor) -> torch.Tensor:
    """Quaternion -> rotation vector with angle ``θ = 2 atan2(|v|, |w|)`` in ``[0, π]``.

    Convention:
        ``q`` is first made canonical (``w >= 0``). Near 0 the factor
        ``θ / |v|`` is a series in ``|v|/w`` (exact limit and gradient at 0).
        At ``w = 0`` (``θ = π``) the axis is ``v / |v|`` with the sign rule of
        the module; the gradient there is finite (one-sided, from ``w >= 0``).

    Args:
        quaternion: ``(*, 4)`` unit quaternions, scalar first.

    Returns:
        ``(*, 3)`` rotation vectors.

    Example:
        >>> quaternion_to_axis_angle(torch.tensor([0.0, 0.0, 0.0, 1.0]))
        tensor([0.0000, 0.0000, 3.1416])
    """
    q = _vec(quaternion, 4, "quaternion")
    return cast_back(rotvec_from_quat(q), quaternion.dtype)


def matrix_to_axis_angle(matrix: torch.Tensor) -> torch.Tensor:
    """Rotation matrix -> rotation vector, angle in ``[0, π]``; :func:`so3_log`.

    Convention:
        Through the Shepperd quaternion (:func:`matrix_to_quaternion`), so half-turns
        about any axis are exact (PyTorch3D's ``fast=True`` path gives NaN for
        ``diag(-1, 1, -1)``). At exactly π the vector follows the module's sign rule:
        its largest-magnitude component is positive. The gradient is finite
        everywhere; at 0 it is the limit (``d log = vee(dR)``), at π it is the
        one-sided derivative of the canonical branch.

    Args:
        matrix: ``(*, 3, 3)`` rotation matrices.

    Returns:
        ``(*, 3)`` rotation vectors.

    Example:
        >>> matrix_to_axis_angle(torch.diag(torch.tensor([-1.0, 1.0, -1.0])))
        tensor([0.0000, 3.1416, 0.0000])
    """
    m = _mat(matrix, 3, "matrix")
    return cast_back(_log(m), matrix.dtype)


def so3_log(matrix: torch.Tensor) -> torch.Tensor:
    """The logarithm of SO(3): rotation matrix -> rotation vector, ``|ω| <= π``.

    Convention:
        Identical to :func:`matrix_to_axis_angle` (same branch at π).

    Args:
        matrix: ``(*, 3, 3)`` rotation matrices.

    Returns:
        ``(*, 3)`` rotation vectors.

    Example:
        >>> so3_log(so3_exp(torch.tensor([0.1, -0.2, 0.3])))
        tensor([ 0.1000, -0.2000,  0.3000])
    """
    m = _mat(matrix, 3, "matrix")
    return cast_back(_log(m), matrix.dtype)


def rotation_6d_to_matrix(d6: torch.Tensor) -> torch.Tensor:
    """The continuous 6D representation (Zhou et al. 2019) -> rotation matrix.

    ``d6 = (a1, a2)`` are the first two **columns** of ``R`` (PyTorch3D uses rows:
    its ``rotation_6d_to_matrix`` returns the transpose of ours for the same 6
    numbers). Gram-Schmidt: ``b1 = a1/|a1|``, ``b2`` the unit part of ``a2``
    orthogonal to ``b1``, ``b3 = b1 × b2``; ``R = [b1 b2 b3]``.

    Convention:
        Degenerate input (``a1 = 0``, or ``a2`` parallel to ``a1``) gives zero
        columns where the direction is undefined (finite, not a rotation).

    Args:
        d6: ``(*, 6)`` two stacked 3-vectors.

    Returns:
        ``(*, 3, 3)`` rotation matrices.

    Example:
        >>> rotation_6d_to_matrix(torch.tensor([2.0, 0, 0, 1, 3, 0]))
        tensor([[1., 0., 0.],
                [0., 1., 0.],
                [0., 0., 1.]])
    """
    x = _vec(d6, 6, "d6")
    a1, a2 = x[..., :3], x[..., 3:]
    tiny = torch.finfo(x.dtype).tiny
    b1 = a1 / safe_norm(a1, keepdim=True).clamp_min(tiny)
    u2 = a2 - (b1 * a2).sum(-1, keepdim=True) * b1
    b2 = u2 / safe_norm(u2, keepdim=True).clamp_min(tiny)
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return cast_back(torch.stack([b1, b2, b3], -1), d6.dtype)


def matrix_to_rotation_6d(matrix: torch.Tensor) -> torch.Tensor:
    """Rotation matrix -> its first two columns ``(*, 6)``, the inverse of
    :func:`rotation_6d_to_matrix` on SO(3).

    Args:
        matrix: ``(*, 3, 3)`` rotation matrices.

    Returns:
        ``(*, 6)``: ``(R[:, 0], R[:, 1])``.

    Example:
        >>> matrix_to_rotation_6d(torch.eye(3))
        tensor([1., 0., 0., 0., 1., 0.])
    """
    check_shape(matrix, ["*", "3", "3"], "matrix")
    check_float(matrix, "matrix")
    return matrix[..., :, :2].mT.flatten(-2)


def _pair(a: torch.Tensor, b: torch.Tensor, size: int, names: tuple[str, str]):
    x, y = _vec(a, size, names[0]), _vec(b, size, names[1])
    if a.dtype != b.dtype or a.device != b.device:
        raise TypeError(f"{names[1]}: expected dtype {a.dtype} on {a.device} like "
                        f"{names[0]}, got {b.dtype} on {b.device}")
    try:
        torch.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    except RuntimeError:
        raise ShapeError(f"batch dims do not broadcast: {names[0]} {tuple(a.shape[:-1])}, "
                         f"{names[1]} {tuple(b.shape[:-1])}") from None
    return x, y


def quaternion_multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product ``a ⊗ b`` (the rotation ``b`` first, then ``a``), made ``w >= 0``.

    Convention:
        ``quaternion_to_matrix(a ⊗ b) = quaternion_to_matrix(a) @ quaternion_to_matrix(b)``.

    Args:
        a: ``(*, 4)`` quaternions ``(w, x, y, z)``.
        b: ``(*, 4)`` quaternions, batch dims broadcast with ``a``.

    Returns:
        ``(*, 4)`` products.

    Example:
        >>> i, j = torch.tensor([0.0, 1, 0, 0]), torch.tensor([0.0, 0, 1, 0])
        >>> quaternion_multiply(i, j)
        tensor([0., 0., 0., 1.])
    """
    x, y = _pair(a, b, 4, ("a", "b"))
    return cast_back(canonical(qmul(x, y)), a.dtype)


def quaternion_conjugate(quaternion: torch.Tensor) -> torch.Tensor:
    """``(w, -x, -y, -z)``: the inverse rotation of a unit quaternion.

    Args:
        quaternion: ``(*, 4)`` quaternions.

    Returns:
        ``(*, 4)`` conjugates.

    Example:
        >>> quaternion_conjugate(torch.tensor([1.0, 2, 3, 4]))
        tensor([ 1., -2., -3., -4.])
    """
    check_shape(quaternion, ["*", "4"], "quaternion")
    check_float(quaternion, "quaternion")
    sign = torch.tensor([1.0, -1.0, -1.0, -1.0], dtype=quaternion.dtype,
                        device=quaternion.device)
    return quaternion * sign


def quaternion_apply(quaternion: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Rotate ``points`` by ``quaternion``: ``q ⊗ (0, p) ⊗ q*``, batched.

    Convention:
        ``p' = p + (2/|q|²) (w (v × p) + v × (v × p))``; equal to
        ``quaternion_to_matrix(q) @ p``. Non-unit quaternions are normalized.

    Args:
        quaternion: ``(*, 4)`` quaternions.
        points: ``(*, 3)`` points, batch dims broadcast with ``quaternion``.

    Returns:
        ``(*, 3)`` rotated points.

    Example:
        >>> import math
        >>> q = torch.tensor([math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)])
        >>> quaternion_apply(q, torch.tensor([1.0, 0, 0])).round(decimals=6) + 0.0
        tensor([0., 1., 0.])
    """
    check_shape(points, ["*", "3"], "points")
    check_float(points, "points")
    check_shape(quaternion, ["*", "4"], "quaternion")
    q, p = _pair(quaternion, points.new_zeros(*points.shape[:-1], 4), 4,
                 ("quaternion", "points"))
    p = points.to(q.dtype)
    w, v = q[..., :1], q[..., 1:]
    two_s = 2.0 / (q * q).sum(-1, keepdim=True)
    uv = torch.linalg.cross(v.expand_as(p) if v.shape != p.shape else v, p, dim=-1) \
        if v.shape == p.shape else torch.linalg.cross(*torch.broadcast_tensors(v, p), dim=-1)
    uuv = torch.linalg.cross(*torch.broadcast_tensors(v, uv), dim=-1)
    return cast_back(p + two_s * (w * uv + uuv), points.dtype)


def quaternion_slerp(q0: torch.Tensor, q1: torch.Tensor, t: torch.Tensor | float
                     ) -> torch.Tensor:
    """Spherical linear interpolation along the shortest arc, ``w >= 0`` on output.

    ``slerp(t) = (sin((1-t)θ) q0 + sin(tθ) q1') / sin θ`` where ``q1' = ±q1`` has
    ``q0·q1' >= 0`` and ``θ = 2 atan2(|q0 - q1'|, |q0 + q1'|)`` is the angle
    between them (``<= π/2``, half the rotation angle), computed without a clamp.

    Convention:
        ``t`` in ``[0, 1]`` (extrapolates outside); ``t = 0`` gives ``q0`` and
        ``t = 1`` gives ``q1`` (as a rotation). ``sin(tθ)/sin θ`` is written with
        ``sinc`` so nearly equal quaternions (θ → 0) give the linear limit with
        finite gradients; nearly antipodal ones are the same rotation and are
        flipped first. Inputs should be unit; the result is normalized.

    Args:
        q0: ``(*, 4)`` start quaternions.
        q1: ``(*, 4)`` end quaternions.
        t: ``(*)`` interpolation parameters (or a number); batch dims broadcast.

    Returns:
        ``(*, 4)`` quaternions.

    Example:
        >>> import math
        >>> q1 = torch.tensor([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])
        >>> quaternion_slerp(torch.tensor([1.0, 0, 0, 0]), q1, 0.5)
        tensor([0.9239, 0.0000, 0.0000, 0.3827])
    """
    a, b = _pair(q0, q1, 4, ("q0", "q1"))
    t = torch.as_tensor(t, dtype=a.dtype, device=a.device)
    check_float(t, "t")
    check_broadcastable({"q0": a.shape[:-1], "q1": b.shape[:-1], "t": t.shape})
    b = torch.where(((a * b).sum(-1, keepdim=True) < 0), -b, b)
    theta = 2 * torch.atan2(safe_norm(a - b, keepdim=True), safe_norm(a + b, keepdim=True))
    t = t.to(a.dtype)[..., None]
    den = sinc(theta)
    out = ((1 - t) * sinc((1 - t) * theta) * a + t * sinc(t * theta) * b) / den
    out = out / safe_norm(out, keepdim=True).clamp_min(torch.finfo(out.dtype).tiny)
    return cast_back(canonical(out), q0.dtype)


def random_rotations(
    n: int,
    generator: torch.Generator | None = None,
    dtype: torch.dtype | None = None,
    device: torch.device | str | None = None,
) -> torch.Tensor:
    """``n`` rotation matrices drawn uniformly (Haar measure) on SO(3).

    A normalized 4D Gaussian is a uniform unit quaternion (Shoemake 1992), and
    the double cover maps it to the Haar measure of SO(3).

    Args:
        n: number of rotations, ``>= 0``.
        generator: optional ``torch.Generator`` for reproducible draws.
        dtype: float dtype (default: torch's default dtype).
        device: device (default: the generator's, else CPU).

    Returns:
        ``(n, 3, 3)`` rotation matrices.

    Example:
        >>> r = random_rotations(2, generator=torch.Generator().manual_seed(0))
        >>> r.shape, torch.allclose(r @ r.mT, torch.eye(3).expand(2, 3, 3), atol=1e-6)
        (torch.Size([2, 3, 3]), True)
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise ValueError(f"n: expected a non-negative int, got {n!r}")
    dtype = dtype or torch.get_default_dtype()
    if device is None and generator is not None:
        device = generator.device
    q = torch.randn(n, 4, generator=generator, dtype=dtype, device=device)
    return matrix_from_quat(q)


def rotation_angle(r1: torch.Tensor, r2: torch.Tensor) -> torch.Tensor:
    """The geodesic angle between rotations, ``|log(R1ᵀ R2)|`` in ``[0, π]``, radians.

    Convention:
        Computed from the quaternions ``q1, q2`` (sign-aligned) as
        ``4 atan2(|q1 - q2|, |q1 + q2|)``, accurate at every angle: at 1e-8 rad
        it is exact to rounding of the given matrices (PyTorch3D's
        ``so3_relative_angle`` has about 7e-3 absolute error at small angles,
        roma's ``rotmat_geodesic_distance`` 1.3e-8 relative). Two rotations
        differing by δ carry, in their entries, an absolute uncertainty of
        ``eps``: the angle is as accurate as that. The gradient is finite
        everywhere: at equal rotations and at exactly π the norm that vanishes
        gets a zero gradient (a subgradient of the kink).

    Args:
        r1: ``(*, 3, 3)`` rotation matrices.
        r2: ``(*, 3, 3)`` rotation matrices, batch dims broadcast with ``r1``.

    Returns:
        ``(*)`` angles.

    Example:
        >>> rotation_angle(torch.eye(3), so3_exp(torch.tensor([0.0, 0.3, 0.4])))
        tensor(0.5000)
    """
    a, b = _mat(r1, 3, "r1"), _mat(r2, 3, "r2")
    if r1.dtype != r2.dtype or r1.device != r2.device:
        raise TypeError(f"r2: expected dtype {r1.dtype} on {r1.device} like r1, "
                        f"got {r2.dtype} on {r2.device}")
    try:
        torch.broadcast_shapes(r1.shape[:-2], r2.shape[:-2])
    except RuntimeError:
        raise ShapeError(f"batch dims do not broadcast: r1 {tuple(r1.shape[:-2])}, "
                         f"r2 {tuple(r2.shape[:-2])}") from None
    q1, q2 = quat_from_matrix(a), quat_from_matrix(b)
    q2 = torch.where((q1 * q2).sum(-1, keepdim=True) < 0, -q2, q2)
    angle = 4 * torch.atan2(safe_norm(q1 - q2), safe_norm(q1 + q2))  # 2x the angle of q1, q2
    return cast_back(angle, r1.dtype)


def so3_left_jacobian(omega: torch.Tensor) -> torch.Tensor:
    """The left Jacobian of SO(3), ``J(ω) = I + ((1 - cos θ)/θ²) [ω]× + ((θ - sin θ)/θ³) [ω]×²``.

    ``exp(ω + δ) ≈ exp(J(ω) δ) exp(ω)``; it also maps ``v`` to the translation
    of :func:`se3_exp`.

    Convention:
        ``(θ - sin θ)/θ³`` is a Taylor series (exact in float64) below θ = 1.

    Args:
        omega: ``(*, 3)`` rotation vectors.

    Returns:
        ``(*, 3, 3)`` Jacobians.

    Example:
        >>> so3_left_jacobian(torch.zeros(3))
        tensor([[1., 0., 0.],
                [0., 1., 0.],
                [0., 0., 1.]])
    """
    w = _vec(omega, 3, "omega")
    return cast_back(left_jacobian(w), omega.dtype)


def so3_left_jacobian_inverse(omega: torch.Tensor) -> torch.Tensor:
    """The inverse of :func:`so3_left_jacobian`:
    ``I - ½ [ω]× + (1/θ²)(1 - (θ/2) cot(θ/2)) [ω]×²``.

    Convention:
        Defined for ``|ω| < 2π`` (the cotangent's pole); below θ = 0.5 the last
        coefficient is its Taylor series.

    Args:
        omega: ``(*, 3)`` rotation vectors.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> w = torch.tensor([0.3, -0.1, 0.2], dtype=torch.float64)
        >>> torch.allclose(so3_left_jacobian_inverse(w) @ so3_left_jacobian(w),
        ...                torch.eye(3, dtype=torch.float64))
        True
    """
    w = _vec(omega, 3, "omega")
    return cast_back(left_jacobian_inverse(w), omega.dtype)


def se3_exp(xi: torch.Tensor) -> torch.Tensor:
    """The exponential map of se(3): ``ξ = (v, ω)`` -> rigid motion ``[[R, J v], [0, 1]]``.

    Convention:
        ``R = so3_exp(ω)`` and ``J`` the left Jacobian: the closed form, exact to
        rounding (PyTorch3D's ``se3_exp_map`` is 8.2e-9 off in float64).

    Args:
        xi: ``(*, 6)`` twists, translation part first.

    Returns:
        ``(*, 4, 4)`` matrices.

    Example:
        >>> se3_exp(torch.tensor([1.0, 2.0, 3.0, 0.0, 0.0, 0.0]))[:3, 3]
        tensor([1., 2., 3.])
    """
    x = _vec(xi, 6, "xi")
    v, w = x[..., :3], x[..., 3:]
    rot = exp_map(w)
    t = (left_jacobian(w) @ v[..., None])[..., 0]
    top = torch.cat([rot, t[..., None]], -1)
    bottom = torch.zeros_like(top[..., :1, :])
    bottom[..., 0, 3] = 1.0
    return cast_back(torch.cat([top, bottom], -2), xi.dtype)


def se3_log(matrix: torch.Tensor) -> torch.Tensor:
    """The logarithm of SE(3): rigid motion ``[[R, t], [0, 1]]`` -> ``(v, ω)``, ``|ω| <= π``.

    Convention:
        ``ω = so3_log(R)`` and ``v = J(ω)⁻¹ t``; the bottom row is not read.
        At ``|ω| = π`` the inverse Jacobian is finite (its pole is at 2π).

    Args:
        matrix: ``(*, 4, 4)`` rigid motions.

    Returns:
        ``(*, 6)`` twists.

    Example:
        >>> xi = torch.tensor([0.5, -1.0, 2.0, 0.1, 0.2, -0.3], dtype=torch.float64)
        >>> torch.allclose(se3_log(se3_exp(xi)), xi)
        True
    """
    m = _mat(matrix, 4, "matrix")
    w = rotvec_from_quat(quat_from_matrix(m[..., :3, :3]))
    v = (left_jacobian_inverse(w) @ m[..., :3, 3:])[..., 0]
    return cast_back(torch.cat([v, w], -1), matrix.dtype)
