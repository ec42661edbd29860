"""Decomposition of affine matrices into the report's terms T, R, SH and S.

Convention:
    ``M = T(offset) · R(angle) · SH(shear, 0) · S(sx, sy)`` (column vectors, the
    right-most factor acts first: scale, then x-shear, then rotate, then
    translate), with :func:`~torchgeo_cg.transforms.translation`,
    :func:`~torchgeo_cg.transforms.rotation` (degrees, counter-clockwise),
    :func:`~torchgeo_cg.transforms.shear` and
    :func:`~torchgeo_cg.transforms.scaling`. This is the QR decomposition of the
    linear part ``L = R · U`` with ``U = SH(shear, 0) · S = [[sx, shear·sy], [0, sy]]``
    upper triangular and ``sx >= 0``; a reflection shows as ``sy < 0``. Six numbers
    for six degrees of freedom, so the decomposition is unique (for ``sx > 0``).
    The report's chains with two shear terms (Table 3, G) are not unique; they
    come back in this canonical form, equal as matrices.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.core.numerics import cast_back, hypot, working_dtype

__all__ = ["AffineDecomposition", "decompose_affine"]


class AffineDecomposition(NamedTuple):
    """Result of :func:`decompose_affine`.

    Attributes:
        offset: ``(*, 2)`` translation ``(a, b)`` of ``T(a, b)``.
        angle_degrees: ``(*)`` counter-clockwise rotation in degrees, in ``(-180, 180]``.
        scale_xy: ``(*, 2)`` axis scales ``(sx, sy)``; ``sx >= 0``, ``sy < 0`` for reflections.
        shear: ``(*)`` x-shear ``a`` of ``SH(a, 0)`` (``x += a·y``).
    """

    offset: torch.Tensor
    angle_degrees: torch.Tensor
    scale_xy: torch.Tensor
    shear: torch.Tensor


def decompose_affine(matrix: torch.Tensor) -> AffineDecomposition:
    """Split affine matrices into ``T(offset) · R(angle) · SH(shear, 0) · S(sx, sy)``.

    The inverse of the report's ``T·R·SH·S`` chains: ``compose(translation(offset),
    rotation(angle), shear(shear, 0), scaling(scale_xy))`` gives ``matrix`` back
    (to 1e-10 in float64, tested).

    Convention:
        Column vectors; see the module docstring for the order. ``matrix`` is
        divided by ``m33`` first (unless it is exactly 0); its perspective entries
        ``m31, m32`` are ignored (check them yourself). A singular linear part does
        not give NaN: ``sx = 0`` gives angle 0, ``sy = 0`` gives shear 0; only exact
        zeros are guarded, so the result is the same at every scale (``sx`` by the
        overflow-safe ``hypot``). NaN in gives NaN out. float16/bfloat16 are
        computed in float32. Differentiable away from those cases.

    Args:
        matrix: ``(*, 3, 3)`` affine matrices.

    Returns:
        :class:`AffineDecomposition` ``(offset (*, 2), angle_degrees (*),
        scale_xy (*, 2), shear (*))``.

    Example:
        >>> from torchgeo_cg.transforms import compose, rotation, scaling, translation
        >>> m = compose(translation(torch.tensor([2.0, 10.0])), rotation(45.0), scaling(0.5))
        >>> d = decompose_affine(m)
        >>> d.offset, d.angle_degrees, d.scale_xy, d.shear.abs() < 1e-6
        (tensor([ 2., 10.]), tensor(45.), tensor([0.5000, 0.5000]), tensor(True))
    """
    check_shape(matrix, ["*", "3", "3"], "matrix")
    check_float(matrix, "matrix")
    dtype = matrix.dtype
    matrix = matrix.to(working_dtype(dtype))
    m33 = matrix[..., 2, 2]
    m33 = torch.where(m33 != 0, m33, torch.ones_like(m33))
    m = matrix / m33[..., None, None]
    a, b, c, d = m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1]
    sx = hypot(a, c)
    ok_x = sx > 0
    sx_safe = torch.where(ok_x, sx, torch.ones_like(sx))
    nan = sx * 0  # 0, or NaN where the column is NaN
    cos = torch.where(ok_x, a / sx_safe, 1 + nan)
    sin = torch.where(ok_x, c / sx_safe, nan)
    angle = torch.rad2deg(torch.atan2(sin, cos))
    # U = Rᵀ L = [[sx, shear·sy], [0, sy]]
    u01 = cos * b + sin * d
    sy = -sin * b + cos * d
    ok_y = sy != 0
    sy_safe = torch.where(ok_y, sy, torch.ones_like(sy))
    shear = torch.where(ok_y, u01 / sy_safe, u01 * 0)
    return AffineDecomposition(*(cast_back(x, dtype) for x in (
        m[..., :2, 2], angle, torch.stack([sx, sy], dim=-1), shear)))
