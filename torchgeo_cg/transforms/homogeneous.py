"""Homogeneous transforms as batched 3x3 (2D) and 4x4 (3D) matrices (report section 2.1-2.2).

:func:`translation`, :func:`compose`, :func:`transform_points` and :func:`inverse`
take both: ``(*, 3, 3)`` matrices with ``(*, N, 2)`` points, or ``(*, 4, 4)``
matrices with ``(*, N, 3)`` points. The other builders are 2D only (3D rotations
are in :mod:`torchgeo_cg.transforms.rotations`).

Convention:
    - Column vectors: a point ``p = (x, y)`` maps to ``p' = M @ [x, y, 1]^T``
      followed by the perspective divide, as in kornia. Row-vector users multiply
      ``[x, y, 1] @ M^T``; :func:`compose_trs` builds either form.
    - Coordinates are ``(x, y)`` (``(x, y, z)`` in 3D) in that order, y pointing up; positive angles
      rotate counter-clockwise. Angles are in degrees unless ``degrees=False``.
    - ``compose(A, B, C) = A @ B @ C``: the right-most matrix acts first.
    - Every function is batched over leading dimensions ``(*)`` (broadcast between
      arguments), takes dtype and device from its tensor inputs, and is
      differentiable. Python and numpy numbers (and numpy arrays) are accepted where
      a ``(*)`` tensor is; they take the dtype of the tensor arguments, or the default
      dtype when there is none (numpy floats keep theirs).
    - dtypes: tensor arguments of one call must share one dtype and device, else a
      ``TypeError`` names both. float16/bfloat16 are computed in float32 and returned
      in the input dtype, saturating at its largest finite value (never ``inf``).
    - Scale: no absolute threshold. The perspective divide treats ``w`` as zero only
      below the rounding error of its row, ``|w| < eps_dtype (|m20| + |m21| + |m22|)``,
      and then divides by that bound (sign kept, ``+`` at exactly 0), so points at
      infinity come out huge but finite, with finite gradients (kornia instead
      leaves such points undivided). :func:`inverse` guards only ``det == 0``.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import (
    ShapeError,
    check_broadcastable,
    check_float,
    check_shape,
    check_tensor,
    format_shape,
)
from torchgeo_cg.core.coerce import as_tensor_like, check_same_dtype
from torchgeo_cg.core.numerics import cast_back, clamp_away_from_zero, working_dtype

__all__ = [
    "translation",
    "rotation",
    "scaling",
    "scale_x",
    "scale_y",
    "shear",
    "homography",
    "compose",
    "compose_trs",
    "transform_points",
    "inverse",
]


def _from_rows(m00, m01, m02, m10, m11, m12, m20, m21, m22) -> torch.Tensor:
    """Stack nine broadcastable (*) tensors into (*, 3, 3)."""
    entries = torch.broadcast_tensors(m00, m01, m02, m10, m11, m12, m20, m21, m22)
    return torch.stack(entries, dim=-1).unflatten(-1, (3, 3))


def _dim(x: torch.Tensor, name: str, allowed: tuple[int, ...], square: bool) -> int:
    """The size of ``x``'s last axis when it is one of ``allowed`` (and the matrix is
    square when ``square``), else ShapeError naming ``name`` and both patterns."""
    check_tensor(x, name)
    ok = x.ndim >= (2 if square else 1) and x.shape[-1] in allowed
    if ok and square:
        ok = x.shape[-2] == x.shape[-1]
    if not ok:
        patterns = " or ".join(format_shape(["*", a, a] if square else ["*", a])
                               for a in allowed)
        raise ShapeError(f"{name}: expected shape {patterns}, got {format_shape(tuple(x.shape))}")
    return x.shape[-1]


def translation(offset: torch.Tensor) -> torch.Tensor:
    """Translation matrix ``T(a, b) = [[1, 0, a], [0, 1, b], [0, 0, 1]]`` (report Table 1).

    A 3D offset ``(a, b, c)`` gives the ``(*, 4, 4)`` matrix ``[[I, t], [0, 1]]``.

    Convention:
        Column vectors; ``offset = (a, b)`` in (x, y) order, ``(a, b, c)`` in (x, y, z).

    Args:
        offset: ``(*, 2)`` or ``(*, 3)`` float tensor (or a numpy array / sequence of numbers).

    Returns:
        ``(*, 3, 3)`` matrices, ``(*, 4, 4)`` for a 3D offset.

    Example:
        >>> translation(torch.tensor([5.0, 1.0]))
        tensor([[1., 0., 5.],
                [0., 1., 1.],
                [0., 0., 1.]])
        >>> translation(torch.tensor([1.0, 2.0, 3.0]))[:3, 3]
        tensor([1., 2., 3.])
    """
    offset = as_tensor_like(offset, None, "offset")
    if _dim(offset, "offset", (2, 3), square=False) == 3:
        eye = torch.eye(4, dtype=offset.dtype, device=offset.device)
        out = eye.expand(*offset.shape[:-1], 4, 4).clone()
        out[..., :3, 3] = offset
        return out
    one, zero = torch.ones_like(offset[..., 0]), torch.zeros_like(offset[..., 0])
    return _from_rows(one, zero, offset[..., 0], zero, one, offset[..., 1], zero, zero, one)


def rotation(angle: torch.Tensor | float, degrees: bool = True) -> torch.Tensor:
    """Rotation about the origin, counter-clockwise for positive ``angle`` (report Table 1).

    ``R = [[cos a, -sin a, 0], [sin a, cos a, 0], [0, 0, 1]]``.

    Convention:
        Column vectors, y up, counter-clockwise positive, about the origin.
        ``degrees=True`` (the report's interface) by default. kornia works in
        pixel coordinates (y down): its ``get_rotation_matrix2d(center, angle,
        scale)`` equals ``T(c) @ R(-angle) @ S(scale) @ T(-c)`` in ours, while
        ``get_affine_matrix2d`` negates its angle again, so its rotation part is
        ``R(+angle)`` (both tested live).

    Args:
        angle: ``(*)`` angles, or a Python/numpy number.
        degrees: interpret ``angle`` in degrees (else radians).

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> rotation(torch.tensor(90.0)).round(decimals=6) + 0.0  # + 0.0 turns -0. into 0.
        tensor([[ 0., -1.,  0.],
                [ 1.,  0.,  0.],
                [ 0.,  0.,  1.]])
    """
    angle = as_tensor_like(angle, None, "angle")
    work = angle.to(working_dtype(angle.dtype))
    rad = torch.deg2rad(work) if degrees else work
    c, s = torch.cos(rad), torch.sin(rad)
    one, zero = torch.ones_like(c), torch.zeros_like(c)
    return cast_back(_from_rows(c, -s, zero, s, c, zero, zero, zero, one), angle.dtype)


def scaling(factor: torch.Tensor | float, per_axis: bool | None = None) -> torch.Tensor:
    """Scaling about the origin: uniform ``S(n)`` or per-axis ``diag(sx, sy, 1)``.

    Convention:
        Column vectors; per-axis factors in (x, y) order. ``per_axis=None`` infers
        the form: a tensor whose last dimension is 2 is read as ``(*, 2)``
        per-axis factors, anything else as ``(*)`` uniform factors. Pass
        ``per_axis=False`` for a batch of exactly two uniform factors.

    Args:
        factor: ``(*)`` uniform or ``(*, 2)`` per-axis factors, or a number.
        per_axis: force the reading of ``factor`` (see above).

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> scaling(2.0)
        tensor([[2., 0., 0.],
                [0., 2., 0.],
                [0., 0., 1.]])
        >>> scaling(torch.tensor([1.2, 0.4]))[:2, :2]
        tensor([[1.2000, 0.0000],
                [0.0000, 0.4000]])
    """
    factor = as_tensor_like(factor, None, "factor")
    if per_axis is None:
        per_axis = factor.ndim >= 1 and factor.shape[-1] == 2
    if per_axis:
        check_shape(factor, ["*", "2"], "factor")
        sx, sy = factor[..., 0], factor[..., 1]
    else:
        sx = sy = factor
    one, zero = torch.ones_like(sx), torch.zeros_like(sx)
    return _from_rows(sx, zero, zero, zero, sy, zero, zero, zero, one)


def scale_x(factor: torch.Tensor | float) -> torch.Tensor:
    """X-wise scale ``Xs(f) = diag(f, 1, 1)`` (report Table 2, ``scaleX``).

    Convention:
        Column vectors (``p' = M @ [x, y, 1]``); scales the x coordinate about the
        origin. ``f < 0`` mirrors, ``f = 0`` gives a singular matrix (allowed).

    Args:
        factor: ``(*)`` float tensor or a number.

    Returns:
        ``(*, 3, 3)``.

    Example:
        >>> scale_x(torch.tensor([2.0, 3.0]))[:, 0, 0]
        tensor([2., 3.])
    """
    factor = as_tensor_like(factor, None, "factor")
    return scaling(torch.stack([factor, torch.ones_like(factor)], dim=-1), per_axis=True)


def scale_y(factor: torch.Tensor | float) -> torch.Tensor:
    """Y-wise scale ``Ys(f) = diag(1, f, 1)`` (report Table 2, ``scaleY``).

    Convention:
        Column vectors (``p' = M @ [x, y, 1]``); scales the y coordinate about the
        origin. ``f < 0`` mirrors, ``f = 0`` gives a singular matrix (allowed).

    Args:
        factor: ``(*)`` float tensor or a number.

    Returns:
        ``(*, 3, 3)``.

    Example:
        >>> scale_y(0.5)[1, 1]
        tensor(0.5000)
    """
    factor = as_tensor_like(factor, None, "factor")
    return scaling(torch.stack([torch.ones_like(factor), factor], dim=-1), per_axis=True)


def shear(a: torch.Tensor | float, b: torch.Tensor | float) -> torch.Tensor:
    """Shear ``SH(a, b) = [[1, a, 0], [b, 1, 0], [0, 0, 1]]`` (report Table 2, ``shearAB``).

    Convention:
        Column vectors: ``x' = x + a*y``, ``y' = b*x + y``, one matrix as in the
        report. kornia's ``get_shear_matrix2d(center, sx, sy)`` differs: it takes
        angles in radians, negates their tangents and shears x first, so it equals
        ``T(c) @ SH(0, -tan sy) @ SH(-tan sx, 0) @ T(-c)`` (tested live); the two
        agree only when one factor is zero.

    Args:
        a: ``(*)`` x-shear (``x += a*y``).
        b: ``(*)`` y-shear (``y += b*x``); broadcast against ``a``.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> shear(0.5, 0.0)
        tensor([[1.0000, 0.5000, 0.0000],
                [0.0000, 1.0000, 0.0000],
                [0.0000, 0.0000, 1.0000]])
    """
    if isinstance(a, torch.Tensor) or not isinstance(b, torch.Tensor):
        a = as_tensor_like(a, None, "a")
        b = as_tensor_like(b, a, "b", like_name="a")
    else:
        b = as_tensor_like(b, None, "b")
        a = as_tensor_like(a, b, "a", like_name="b")
    check_broadcastable({"a": a.shape, "b": b.shape})
    a, b = torch.broadcast_tensors(a, b)
    one, zero = torch.ones_like(a), torch.zeros_like(a)
    return _from_rows(one, a, zero, b, one, zero, zero, zero, one)


def homography(h: torch.Tensor) -> torch.Tensor:
    """Homography from its 8 free entries, ``h33 = 1`` (report Table 2).

    Convention:
        ``h = (h11, h12, h13, h21, h22, h23, h31, h32)`` in row-major order;
        column vectors with the perspective divide (see :func:`transform_points`).

    Args:
        h: ``(*, 8)`` float tensor.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> homography(torch.tensor([0.27, 0, -0.85, -0.25, -0.2, 5.65, -0.02, -0.09]))
        tensor([[ 0.2700,  0.0000, -0.8500],
                [-0.2500, -0.2000,  5.6500],
                [-0.0200, -0.0900,  1.0000]])
    """
    h = as_tensor_like(h, None, "h")
    check_shape(h, ["*", "8"], "h")
    return torch.cat([h, torch.ones_like(h[..., :1])], dim=-1).unflatten(-1, (3, 3))


def _check_matrix(m: torch.Tensor, name: str) -> torch.Tensor:
    """A float ``(*, 3, 3)`` or ``(*, 4, 4)`` matrix, else ShapeError naming ``name``."""
    _dim(m, name, (3, 4), square=True)
    return check_float(m, name)


def compose(*matrices: torch.Tensor) -> torch.Tensor:
    """Multiply homogeneous matrices left to right: ``compose(A, B, C) = A @ B @ C``.

    Convention:
        Column vectors, so the right-most matrix acts first: the compound
        ``T·S·R`` is ``compose(T, S, R)``. Batch dims broadcast. All
        matrices share one dtype and device (else ``TypeError`` naming two of them)
        and one size: all 3x3 (2D) or all 4x4 (3D).

    Args:
        *matrices: one or more ``(*, 3, 3)`` or ``(*, 4, 4)`` tensors.

    Returns:
        ``(*, 3, 3)`` or ``(*, 4, 4)``, the broadcast product.

    Example:
        >>> m = compose(translation(torch.tensor([1.0, 0.0])), scaling(2.0))
        >>> transform_points(m, torch.tensor([[1.0, 1.0]]))
        tensor([[3., 2.]])
    """
    if len(matrices) == 0:
        raise ValueError("compose: expected at least one matrix, got none")
    named = {f"matrices[{i}]": _check_matrix(m, f"matrices[{i}]") for i, m in enumerate(matrices)}
    size = matrices[0].shape[-1]
    for name, m in named.items():
        check_shape(m, ["*", str(size), str(size)], name)  # one size for all
    check_broadcastable({name: m.shape[:-2] for name, m in named.items()})
    dtype = check_same_dtype(named).dtype
    work = working_dtype(dtype)
    out = matrices[0].to(work)
    for m in matrices[1:]:
        out = out @ m.to(work)
    return cast_back(out, dtype)


def compose_trs(
    offset: torch.Tensor,
    angle: torch.Tensor | float,
    scale: torch.Tensor | float,
    row_vectors: bool = False,
    degrees: bool = True,
) -> torch.Tensor:
    """The compound transform ``T·S·R`` (column vectors) or ``Rᵀ·Sᵀ·Tᵀ`` (row vectors).

    Convention:
        With ``row_vectors=False`` the result acts on column vectors,
        ``p' = (T·S·R) p``: rotate first, then scale, then translate. With
        ``row_vectors=True`` it is the transpose, acting on row vectors,
        ``p'ᵀ = pᵀ (Rᵀ·Sᵀ·Tᵀ)``; both give the same points.

    Args:
        offset: ``(*, 2)`` translation.
        angle: ``(*)`` rotation (degrees unless ``degrees=False``); a tensor of
            ``offset``'s dtype and device, or a number.
        scale: ``(*)`` uniform or ``(*, 2)`` per-axis scale, as in :func:`scaling`;
            same dtype rule as ``angle``.
        row_vectors: return the post-multiplied (row-vector) form.
        degrees: unit of ``angle``.

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> m = compose_trs(torch.tensor([2.0, 10.0]), 45.0, 0.5)
        >>> torch.allclose(compose_trs(torch.tensor([2.0, 10.0]), 45.0, 0.5, row_vectors=True),
        ...                m.mT)
        True
    """
    offset = as_tensor_like(offset, None, "offset")
    check_shape(offset, ["*", "2"], "offset")
    angle = as_tensor_like(angle, offset, "angle", like_name="offset")
    scale = as_tensor_like(scale, offset, "scale", like_name="offset")
    per_axis = scale.ndim >= 1 and scale.shape[-1] == 2
    check_broadcastable(
        {
            "offset": offset.shape[:-1],
            "angle": angle.shape,
            "scale": scale.shape[:-1] if per_axis else scale.shape,
        }
    )
    t, r, s = translation(offset), rotation(angle, degrees=degrees), scaling(scale)
    if row_vectors:
        return compose(r.mT, s.mT, t.mT)
    return compose(t, s, r)


def transform_points(
    matrix: torch.Tensor, points: torch.Tensor, eps: float | None = None
) -> torch.Tensor:
    """Apply homogeneous ``matrix`` to 2D or 3D ``points``, with the perspective divide.

    ``[x', y', w]ᵀ = M [x, y, 1]ᵀ`` and the result is ``(x'/w, y'/w)``; in 3D
    ``[x', y', z', w]ᵀ = M [x, y, z, 1]ᵀ`` and the result is ``(x', y', z') / w``.

    Convention:
        Column vectors as in kornia's ``transform_points(trans_01, points_1)``;
        equal to it wherever ``w`` is not numerically zero. ``w`` counts as zero
        below the rounding error of the bottom row, ``|w| < bound`` with
        ``bound = finfo(dtype).eps * (|m20| + |m21| + |m22|)`` (the bottom row's
        four entries in 3D; relative, so the
        same at every scale of the points and of the matrix); there we divide by
        ``±bound`` (sign of ``w`` kept, ``+`` at exactly 0) instead of leaving the
        point undivided as kornia does: the output is huge but finite, forward and
        backward. Batch dims of ``matrix`` and ``points`` broadcast. NaN in gives
        NaN out. float16/bfloat16 are computed in float32 and saturate on return.

    Args:
        matrix: ``(*, 3, 3)`` or ``(*, 4, 4)`` float transforms.
        points: ``(*, N, 2)`` (or ``(*, N, 3)`` with a 4x4 matrix) float points, same
            dtype and device as ``matrix``.
        eps: ``None`` (default) for the relative bound above; a number is the
            legacy absolute bound on ``|w|``.

    Returns:
        ``(*, N, 2)`` (or ``(*, N, 3)``) transformed points.

    Example:
        >>> h = homography(torch.tensor([1.0, 0, 0, 0, 1, 0, 0.5, 0]))
        >>> transform_points(h, torch.tensor([[2.0, 4.0], [-2.0, 1.0]]))
        tensor([[ 1.0000e+00,  2.0000e+00],
                [-1.1185e+07,  5.5924e+06]])
        >>> transform_points(translation(torch.tensor([1.0, 2.0, 3.0])), torch.zeros(1, 3))
        tensor([[1., 2., 3.]])
    """
    _check_matrix(matrix, "matrix")
    check_shape(points, ["*", "N", str(matrix.shape[-1] - 1)], "points")
    check_float(points, "points")
    check_broadcastable({"matrix": matrix.shape[:-2], "points": points.shape[:-2]})
    check_same_dtype({"points": points, "matrix": matrix})
    dtype = points.dtype
    work = working_dtype(dtype)
    matrix, points = matrix.to(work), points.to(work)
    if matrix.shape[-1] == 4:
        return cast_back(_transform_points_3d(matrix, points, eps, dtype), dtype)
    # Written out entry by entry: a (N,2)@(2,3) matmul is memory-bound and slower,
    # and the elementwise form keeps backward cheap. m_rc is (*, 1), x and y are (*, N).
    x, y = points[..., 0], points[..., 1]
    m = matrix[..., None]  # (*, 3, 3, 1)
    w = torch.addcmul(torch.addcmul(m[..., 2, 2, :], m[..., 2, 0, :], x), m[..., 2, 1, :], y)
    if eps is None:  # the rounding error of w = m20 x + m21 y + m22, per matrix: (*, 1)
        eps = torch.finfo(dtype).eps * m[..., 2, :, :].detach().abs().sum(-2)
    w = clamp_away_from_zero(w, eps)  # (*, N)
    x_out = torch.addcmul(torch.addcmul(m[..., 0, 2, :], m[..., 0, 0, :], x), m[..., 0, 1, :], y)
    y_out = torch.addcmul(torch.addcmul(m[..., 1, 2, :], m[..., 1, 0, :], x), m[..., 1, 1, :], y)
    if records_graph(matrix, points):
        return cast_back(torch.stack([x_out / w, y_out / w], dim=-1), dtype)
    out = w.new_empty(*w.shape, 2)  # no autograd: divide straight into the result
    torch.div(x_out, w, out=out[..., 0])
    torch.div(y_out, w, out=out[..., 1])
    return cast_back(out, dtype)


def _transform_points_3d(matrix, points, eps, dtype) -> torch.Tensor:
    """(*, 4, 4) matrices on (*, N, 3) points, the divide guarded as in 2D."""
    h = points @ matrix[..., :, :3].mT + matrix[..., None, :, 3]  # (*, N, 4)
    bottom = matrix[..., 3:, :]  # (*, 1, 4)
    if eps is None:  # the rounding error of w, per matrix: (*, 1)
        eps = torch.finfo(dtype).eps * bottom.detach().abs().sum(-1)
    w = clamp_away_from_zero(h[..., 3], eps)  # (*, N)
    return h[..., :3] / w[..., None]


def _adjugate4(m: torch.Tensor):
    """Adjugate (*, 4, 4) and determinant (*) of (*, 4, 4) by 2x2 minors (Laplace)."""
    a = [[m[..., r, c] for c in range(4)] for r in range(4)]
    s0 = a[0][0] * a[1][1] - a[1][0] * a[0][1]
    s1 = a[0][0] * a[1][2] - a[1][0] * a[0][2]
    s2 = a[0][0] * a[1][3] - a[1][0] * a[0][3]
    s3 = a[0][1] * a[1][2] - a[1][1] * a[0][2]
    s4 = a[0][1] * a[1][3] - a[1][1] * a[0][3]
    s5 = a[0][2] * a[1][3] - a[1][2] * a[0][3]
    c5 = a[2][2] * a[3][3] - a[3][2] * a[2][3]
    c4 = a[2][1] * a[3][3] - a[3][1] * a[2][3]
    c3 = a[2][1] * a[3][2] - a[3][1] * a[2][2]
    c2 = a[2][0] * a[3][3] - a[3][0] * a[2][3]
    c1 = a[2][0] * a[3][2] - a[3][0] * a[2][2]
    c0 = a[2][0] * a[3][1] - a[3][0] * a[2][1]
    det = s0 * c5 - s1 * c4 + s2 * c3 + s3 * c2 - s4 * c1 + s5 * c0
    adj = [
        a[1][1] * c5 - a[1][2] * c4 + a[1][3] * c3,
        -a[0][1] * c5 + a[0][2] * c4 - a[0][3] * c3,
        a[3][1] * s5 - a[3][2] * s4 + a[3][3] * s3,
        -a[2][1] * s5 + a[2][2] * s4 - a[2][3] * s3,
        -a[1][0] * c5 + a[1][2] * c2 - a[1][3] * c1,
        a[0][0] * c5 - a[0][2] * c2 + a[0][3] * c1,
        -a[3][0] * s5 + a[3][2] * s2 - a[3][3] * s1,
        a[2][0] * s5 - a[2][2] * s2 + a[2][3] * s1,
        a[1][0] * c4 - a[1][1] * c2 + a[1][3] * c0,
        -a[0][0] * c4 + a[0][1] * c2 - a[0][3] * c0,
        a[3][0] * s4 - a[3][1] * s2 + a[3][3] * s0,
        -a[2][0] * s4 + a[2][1] * s2 - a[2][3] * s0,
        -a[1][0] * c3 + a[1][1] * c1 - a[1][2] * c0,
        a[0][0] * c3 - a[0][1] * c1 + a[0][2] * c0,
        -a[3][0] * s3 + a[3][1] * s1 - a[3][2] * s0,
        a[2][0] * s3 - a[2][1] * s1 + a[2][2] * s0,
    ]
    return torch.stack(adj, dim=-1).unflatten(-1, (4, 4)), det


def _adjugate3(matrix: torch.Tensor):
    """Adjugate (*, 3, 3) and determinant (*) of (*, 3, 3) by cofactors."""
    a, b, c = matrix[..., 0, 0], matrix[..., 0, 1], matrix[..., 0, 2]
    d, e, f = matrix[..., 1, 0], matrix[..., 1, 1], matrix[..., 1, 2]
    g, h, i = matrix[..., 2, 0], matrix[..., 2, 1], matrix[..., 2, 2]
    # cofactors: adj(M)[r, c] = cofactor(M)[c, r]
    A, B, C = e * i - f * h, -(d * i - f * g), d * h - e * g
    D, E, F = -(b * i - c * h), a * i - c * g, -(a * h - b * g)
    G, H, I = b * f - c * e, -(a * f - c * d), a * e - b * d
    return _from_rows(A, D, G, B, E, H, C, F, I), a * A + b * B + c * C


def inverse(matrix: torch.Tensor, eps: float | None = None) -> torch.Tensor:
    """Inverse of homogeneous 3x3 or 4x4 matrices by the adjugate, ``M⁻¹ = adj(M) / det(M)``.

    Convention:
        Closed form, batched and differentiable, exact at every scale (no
        threshold: ``inverse(scaling(1e-7))`` is ``scaling(1e7)``). Only an exactly
        singular matrix (``det == 0``) is guarded: its determinant is replaced by
        ``finfo(dtype).eps * max|M| * max|adj(M)|`` (the scale of the determinant,
        as ``M adj(M) = det I``), so the result is huge but finite, never NaN;
        check ``torch.linalg.det`` yourself when singular input is possible.
        float16/bfloat16 are computed in float32 and saturate on return.

    Args:
        matrix: ``(*, 3, 3)`` or ``(*, 4, 4)`` float tensor.
        eps: ``None`` (default) as above; a number is the legacy absolute bound on
            ``|det|`` (clamped to ``±eps``).

    Returns:
        ``(*, 3, 3)`` or ``(*, 4, 4)`` inverses.

    Example:
        >>> m = compose_trs(torch.tensor([2.0, 1.0]), 30.0, 2.0)
        >>> torch.allclose(compose(m, inverse(m)), torch.eye(3), atol=1e-6)
        True
        >>> inverse(scaling(torch.tensor(1e-7, dtype=torch.float64))).diagonal()
        tensor([1.0000e+07, 1.0000e+07, 1.0000e+00], dtype=torch.float64)
    """
    _check_matrix(matrix, "matrix")
    dtype = matrix.dtype
    matrix = matrix.to(working_dtype(dtype))
    adj, det = _adjugate4(matrix) if matrix.shape[-1] == 4 else _adjugate3(matrix)
    if eps is None:
        size = matrix.detach().abs().amax((-2, -1)) * adj.detach().abs().amax((-2, -1))
        eps = torch.finfo(dtype).eps * size  # (*)
        det = torch.where(det == 0, clamp_away_from_zero(det, eps), det)
    else:
        det = clamp_away_from_zero(det, eps)
    return cast_back(adj / det[..., None, None], dtype)
