"""The report's shapes A–H (section 2.4, Table 3) as data, and their automatic recovery.

The report estimates by hand the transform from a start shape to eight targets.
It does not give the start shape itself, so this module uses one of its own
making: a letter "F" (10 vertices), asymmetric under every reflection and
rotation, so a fit cannot confuse the transform with a flipped one. The eight
targets are the start shape moved by Table 3's transforms, built with the
matrices of :mod:`torchgeo_cg.transforms.homogeneous`.

Convention:
    Column vectors, ``target = transform_points(matrix, start)``; ``(x, y)`` with
    y up; angles in degrees, counter-clockwise. The report's chains read left to
    right as written: ``T(9.5, 1.55)·Xs(1.2)·Ys(0.4)`` is
    ``compose(translation(...), scale_x(1.2), scale_y(0.4))``.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.transforms.decompose import decompose_affine
from torchgeo_cg.transforms.fitting import SolverOptions, fit_transform
from torchgeo_cg.transforms.homogeneous import (
    compose,
    homography,
    rotation,
    scale_x,
    scale_y,
    scaling,
    shear,
    transform_points,
    translation,
)
from torchgeo_cg.transforms.homography_dlt import find_homography_dlt

__all__ = [
    "ReportShapes", "ShapeFit", "report_shapes", "fit_report_shapes", "format_report_table",
    "format_transform",
]

#: Table 3's shape names.
_REPORT_NAMES: tuple[str, ...] = ("A", "B", "C", "D", "E", "F", "G", "H")
#: Table 3's estimates, as the report writes them.
_REPORT_FORMULAS: tuple[str, ...] = (
    "T(5,1)",
    "T(7,0)·S(1/2.45)",
    "T(9.5,1.55)·Xs(1.2)·Ys(0.4)",
    "T(0,7)·R(315°)",
    "T(2,10)·R(45°)·S(0.5)",
    "T(4,14)·R(-135°)·Xs(0.4)·Ys(0.8)",
    "T(8,8)·R(22.5°)·SH(0.01,1.05)·Ys(0.685)·Xs(0.95)",
    "H[[0.27,0,-0.85],[-0.25,-0.2,5.65],[-0.02,-0.09,1]]",
)

# The start shape: a letter "F", counter-clockwise, in [0, 2] x [0, 3] (our own design).
_START_F = (
    (0.0, 0.0), (0.6, 0.0), (0.6, 1.2), (1.4, 1.2), (1.4, 1.8),
    (0.6, 1.8), (0.6, 2.4), (2.0, 2.4), (2.0, 3.0), (0.0, 3.0),
)


def _float_dtype(dtype) -> torch.dtype:
    """``dtype`` (default: torch's default), or ``TypeError`` unless it is a float dtype."""
    dtype = torch.get_default_dtype() if dtype is None else dtype
    if not isinstance(dtype, torch.dtype) or not dtype.is_floating_point:
        raise TypeError(f"dtype: expected a floating-point torch.dtype, got {dtype}")
    return dtype


class ReportShapes(NamedTuple):
    """Result of :func:`report_shapes`.

    Attributes:
        start: ``(N, 2)`` the start polygon (N = 10 vertices, closed implicitly).
        matrices: ``(8, 3, 3)`` Table 3's transforms ``target_from_start``, A..H.
        targets: ``(8, N, 2)`` the start polygon moved by each transform.
        names: the letters ``A``..``H``.
        formulas: the report's formulas, as written in Table 3.
    """

    start: torch.Tensor
    matrices: torch.Tensor
    targets: torch.Tensor
    names: tuple[str, ...]
    formulas: tuple[str, ...]


def report_shapes(device=None, dtype=None) -> ReportShapes:
    """The report's start shape and Table 3's eight targets A–H.

    Convention:
        See the module docstring; the start shape is this project's letter "F"
        (the report does not give its own). float16/bfloat16 are built in float32
        and cast back.

    Args:
        device: device of the tensors (default: torch's default).
        dtype: float dtype of the tensors (default: torch's default).

    Raises:
        TypeError: ``dtype`` is not a floating-point dtype.

    Returns:
        :class:`ReportShapes` ``(start (10, 2), matrices (8, 3, 3),
        targets (8, 10, 2), names, formulas)``.

    Example:
        >>> shapes = report_shapes(dtype=torch.float64)
        >>> shapes.start.shape, shapes.targets.shape
        (torch.Size([10, 2]), torch.Size([8, 10, 2]))
        >>> shapes.targets[0, :2]  # A = T(5, 1)
        tensor([[5.0000, 1.0000],
                [5.6000, 1.0000]], dtype=torch.float64)
    """
    dtype = _float_dtype(dtype)
    kw = {"device": device, "dtype": working_dtype(dtype)}

    def vec(*values: float) -> torch.Tensor:
        return torch.tensor(values, **kw)

    def num(value: float) -> torch.Tensor:
        return torch.tensor(value, **kw)

    matrices = torch.stack([
        translation(vec(5.0, 1.0)),
        compose(translation(vec(7.0, 0.0)), scaling(num(1 / 2.45))),
        compose(translation(vec(9.5, 1.55)), scale_x(num(1.2)), scale_y(num(0.4))),
        compose(translation(vec(0.0, 7.0)), rotation(num(315.0))),
        compose(translation(vec(2.0, 10.0)), rotation(num(45.0)), scaling(num(0.5))),
        compose(translation(vec(4.0, 14.0)), rotation(num(-135.0)), scale_x(num(0.4)),
                scale_y(num(0.8))),
        compose(translation(vec(8.0, 8.0)), rotation(num(22.5)), shear(num(0.01), num(1.05)),
                scale_y(num(0.685)), scale_x(num(0.95))),
        homography(vec(0.27, 0.0, -0.85, -0.25, -0.2, 5.65, -0.02, -0.09)),
    ])
    start = torch.tensor(_START_F, **kw)
    targets = transform_points(matrices, start.expand(8, -1, -1))
    start, matrices, targets = (cast_back(x, dtype) for x in (start, matrices, targets))
    return ReportShapes(start, matrices, targets, _REPORT_NAMES, _REPORT_FORMULAS)


class ShapeFit(NamedTuple):
    """Result of :func:`fit_report_shapes`.

    Attributes:
        shapes: the :class:`ReportShapes` fitted.
        homography: ``(8, 3, 3)`` fitted ``target_from_start`` with ``model="homography"``.
        affine: ``(8, 3, 3)`` fitted with ``model="affine"`` (meaningful for A–G).
        dlt: ``(8, 3, 3)`` the closed-form DLT, for comparison.
        error_homography: ``(8,)`` max abs entry error of ``homography`` against the truth.
        error_affine: ``(8,)`` the same for ``affine``.
    """

    shapes: ReportShapes
    homography: torch.Tensor
    affine: torch.Tensor
    dlt: torch.Tensor
    error_homography: torch.Tensor
    error_affine: torch.Tensor


def fit_report_shapes(optimizer: str = "lm", steps: int | None = None,
                      dtype: torch.dtype = torch.float64, device=None) -> ShapeFit:
    """Recover Table 3's transforms from the shapes, all eight in one batched call.

    Convention:
        Fits ``target_from_start`` with :func:`fit_transform` from the identity
        (``init=None``), once with ``model="homography"`` and once with
        ``model="affine"``; errors are the largest absolute matrix-entry
        differences to the truth (both scaled to ``m33 = 1``). float16/bfloat16
        fit in float32 (from the float32 shapes) and every tensor is cast back.

    Args:
        optimizer: ``"lm"``, ``"adam"`` or ``"lbfgs"``.
        steps: iterations (the optimizer's default if None).
        dtype: float dtype of the fit.
        device: device of the fit.

    Returns:
        :class:`ShapeFit`.

    Raises:
        TypeError: ``dtype`` is not a floating-point dtype.

    Example:
        >>> fit = fit_report_shapes()
        >>> bool(fit.error_homography.max() < 1e-6), bool(fit.error_affine[:7].max() < 1e-6)
        (True, True)
    """
    dtype = _float_dtype(dtype)
    shapes = report_shapes(device=device, dtype=working_dtype(dtype))
    src = shapes.start.expand(8, -1, -1)
    fit_h = fit_transform(src, shapes.targets, "homography",
                          solver=SolverOptions(optimizer, steps=steps))
    fit_a = fit_transform(src, shapes.targets, "affine",
                          solver=SolverOptions(optimizer, steps=steps))
    dlt = find_homography_dlt(src, shapes.targets).matrix
    err_h = (fit_h.matrix - shapes.matrices).abs().amax((-2, -1))
    err_a = (fit_a.matrix - shapes.matrices).abs().amax((-2, -1))
    if dtype != shapes.start.dtype:  # float16/bfloat16: fitted in float32, cast back
        shapes = shapes._replace(**{k: cast_back(getattr(shapes, k), dtype)
                                    for k in ("start", "matrices", "targets")})
    out = (cast_back(x, dtype) for x in (fit_h.matrix, fit_a.matrix, dlt, err_h, err_a))
    return ShapeFit(shapes, *out)


def _num(x: float) -> str:
    text = f"{x:.4g}" if abs(x) > 1e-9 else "0"
    return "0" if text in ("-0", "0") else text


def format_transform(matrix: torch.Tensor, atol: float = 1e-9) -> str:
    """One matrix in the report's terms: ``T(a,b)·R(θ°)·SH(s,0)·S(sx,sy)`` or ``H[...]``.

    Convention:
        Affine matrices (``|m31|, |m32| <= atol``) are decomposed by
        :func:`~torchgeo_cg.transforms.decompose_affine` (``T·R·SH·S``); identity
        factors are left out, equal scales print as ``S(s)``. Others print as a
        homography with ``m33 = 1``. 4 significant digits.

    Args:
        matrix: ``(3, 3)`` matrix.
        atol: tolerance for "affine", identity factors and equal scales.

    Returns:
        The formula as a string.

    Example:
        >>> from torchgeo_cg.transforms import compose, rotation, translation
        >>> format_transform(compose(translation(torch.tensor([0.0, 7.0])), rotation(315.0)))
        'T(0,7)·R(-45°)'
    """
    m = matrix.detach().double().cpu()
    m = m / m[2, 2]
    if m[2, :2].abs().max() > atol:
        rows = [",".join(_num(float(v)) for v in row) for row in m]
        return "H[" + ",".join(f"[{r}]" for r in rows) + "]"
    d = decompose_affine(m)
    tol = max(atol, 1e-6)
    parts = []
    off = [float(v) for v in d.offset]
    if max(abs(v) for v in off) > tol:
        parts.append(f"T({_num(off[0])},{_num(off[1])})")
    if abs(float(d.angle_degrees)) > tol:
        parts.append(f"R({_num(float(d.angle_degrees))}°)")
    if abs(float(d.shear)) > tol:
        parts.append(f"SH({_num(float(d.shear))},0)")
    sx, sy = (float(v) for v in d.scale_xy)
    if abs(sx - sy) <= tol:
        if abs(sx - 1) > tol:
            parts.append(f"S({_num(sx)})")
    else:
        parts.append(f"S({_num(sx)},{_num(sy)})")
    return "·".join(parts) or "I"


def format_report_table(fit: ShapeFit) -> str:
    """A Table-3-style summary: truth, recovered homography and affine, and their errors.

    Args:
        fit: the result of :func:`fit_report_shapes`.

    Returns:
        A plain-text table, one row per shape.

    Example:
        >>> print(format_report_table(fit_report_shapes()).splitlines()[0])  # doctest: +ELLIPSIS
        shape | report (truth) ...
    """
    header = ("shape | report (truth) | recovered, model=homography | err | "
              "recovered, model=affine | err")
    lines = [header, "-" * len(header)]
    for i, name in enumerate(fit.shapes.names):
        affine = format_transform(fit.affine[i]) if i < 7 else "(not affine)"
        err_a = f"{float(fit.error_affine[i]):.1e}" if i < 7 else "-"
        lines.append(
            f"{name} | {fit.shapes.formulas[i]} | {format_transform(fit.homography[i])} | "
            f"{float(fit.error_homography[i]):.1e} | {affine} | {err_a}"
        )
    return "\n".join(lines)
