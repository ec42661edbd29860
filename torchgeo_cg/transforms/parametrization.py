"""Parametrizations of 2D transforms in the Hartley-normalized frame, for iterative fitting.

Convention:
    Column vectors; ``params = 0`` is the identity. Angles in radians, scales as logs.
    The models and their parameter counts are :data:`MODELS`; the homography has the
    parametrizations :data:`PARAMETRIZATIONS`.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.check import check_broadcastable, check_choice, check_float, check_shape
from torchgeo_cg.core.coerce import check_same_dtype
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.transforms.homogeneous import transform_points

__all__ = [
    "MODELS",
    "PARAMETRIZATIONS",
    "parameters_to_matrix",
    "matrix_to_parameters",
]

#: Number of parameters of each model.
MODELS: dict[str, int] = {
    "homography": 8,
    "affine": 6,
    "similarity": 4,
    "euclidean": 3,
    "translation": 2,
    "trs": 5,
}


#: Parametrizations of the homography model.
PARAMETRIZATIONS: tuple[str, ...] = ("entries", "corners", "sl3")


_CORNERS = ((-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0))


def _square_to_quad(quad: torch.Tensor) -> torch.Tensor:
    """Homography taking (0,0), (1,0), (1,1), (0,1) to ``quad`` (*, 4, 2) (Heckbert 1989)."""
    x, y = quad[..., 0], quad[..., 1]
    sx = x[..., 0] - x[..., 1] + x[..., 2] - x[..., 3]
    sy = y[..., 0] - y[..., 1] + y[..., 2] - y[..., 3]
    dx1, dx2 = x[..., 1] - x[..., 2], x[..., 3] - x[..., 2]
    dy1, dy2 = y[..., 1] - y[..., 2], y[..., 3] - y[..., 2]
    den = dx1 * dy2 - dx2 * dy1
    ok = den.abs() > 1e-12
    den = torch.where(ok, den, torch.ones_like(den))  # degenerate quad: affine fallback
    g = torch.where(ok, (sx * dy2 - dx2 * sy) / den, torch.zeros_like(den))
    h = torch.where(ok, (dx1 * sy - sx * dy1) / den, torch.zeros_like(den))
    a, b = x[..., 1] - x[..., 0] + g * x[..., 1], x[..., 3] - x[..., 0] + h * x[..., 3]
    d, e = y[..., 1] - y[..., 0] + g * y[..., 1], y[..., 3] - y[..., 0] + h * y[..., 3]
    one = torch.ones_like(a)
    rows = [a, b, x[..., 0], d, e, y[..., 0], g, h, one]
    return torch.stack(rows, dim=-1).unflatten(-1, (3, 3))


def _sl3_basis(like: torch.Tensor) -> torch.Tensor:
    """(8, 3, 3) traceless generators: x/y translation, shear, rotation, scales, perspective."""
    e = torch.zeros(8, 3, 3, dtype=like.dtype, device=like.device)
    e[0, 0, 2] = e[1, 1, 2] = 1.0  # translations
    e[2, 0, 1] = 1.0  # x shear
    e[3, 1, 0] = 1.0  # y shear
    e[4, 0, 0], e[4, 1, 1] = 1.0, -1.0  # anisotropic scale
    e[5, 0, 0] = e[5, 1, 1] = 1.0
    e[5, 2, 2] = -2.0  # isotropic scale (traceless)
    e[6, 2, 0] = e[7, 2, 1] = 1.0  # perspective
    return e


def _rows_to_matrix(rows: list[torch.Tensor]) -> torch.Tensor:
    return torch.stack(rows, dim=-1).unflatten(-1, (3, 3))


def parameters_to_matrix(
    params: torch.Tensor,
    model: str = "homography",
    parametrization: str = "entries",
    base: torch.Tensor | None = None,
) -> torch.Tensor:
    """The normalized-frame transform ``Ĥ`` of ``params`` for ``model``.

    Convention:
        Column vectors; ``params = 0`` is the identity (or ``base``). ``base``
        must have the dtype of ``params`` (else ``TypeError`` naming both);
        float16/bfloat16 are computed in float32 and returned in their dtype.

        - ``homography`` / ``entries``: ``Ĥ = I + [p0..p7, 0]`` row-major (``h33 = 1``).
        - ``homography`` / ``corners``: ``p`` moves the images of the corners
          ``(-1,-1), (1,-1), (1,1), (-1,1)`` (x, y pairs); ``Ĥ`` maps the corners there.
        - ``homography`` / ``sl3``: ``Ĥ = base · exp(Σ p_i G_i)`` with traceless
          generators ``G`` (translations, shears, scales, perspective).
        - ``affine``: ``Ĥ = I + [[p0, p1, p2], [p3, p4, p5], [0, 0, 0]]``.
        - ``similarity``: ``[[1 + p0, -p1, p2], [p1, 1 + p0, p3], [0, 0, 1]]``.
        - ``euclidean``: ``T(p1, p2) · R(p0)``, ``p0`` in radians, counter-clockwise.
        - ``translation``: ``T(p0, p1)``.
        - ``trs``: ``T(p0, p1) · R(p2) · S(exp p3, exp p4)``, the report's T·R·Xs·Ys.

    Args:
        params: ``(*, P)`` with ``P = MODELS[model]``.
        model: one of :data:`MODELS`.
        parametrization: homography parametrization, one of :data:`PARAMETRIZATIONS`.
        base: ``(*, 3, 3)`` left factor of the ``sl3`` parametrization (identity if None).

    Returns:
        ``(*, 3, 3)`` matrices.

    Example:
        >>> parameters_to_matrix(torch.tensor([1.0, 2.0, 0.0, 0.0, 0.0]), "trs")
        tensor([[1., 0., 1.],
                [0., 1., 2.],
                [0., 0., 1.]])
    """
    check_choice(model, MODELS, "model")
    check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
    check_shape(params, ["*", str(MODELS[model])], "params")
    check_float(params, "params")
    if base is not None:
        check_shape(base, ["*", "3", "3"], "base")
        check_broadcastable({"params": params.shape[:-1], "base": base.shape[:-2]})
        check_same_dtype({"params": params, "base": check_float(base, "base")})
    work = working_dtype(params.dtype)  # float16/bfloat16: computed in float32
    out = _parameters_to_matrix(params.to(work), model, parametrization,
                                None if base is None else base.to(work))
    return cast_back(out, params.dtype)


def _parameters_to_matrix(params, model, parametrization, base):
    p = params.unbind(-1)
    one, zero = torch.ones_like(p[0]), torch.zeros_like(p[0])
    if model == "homography":
        if parametrization == "entries":
            return _rows_to_matrix([one + p[0], p[1], p[2], p[3], one + p[4], p[5], p[6], p[7],
                                    one])
        if parametrization == "corners":
            corners = torch.tensor(_CORNERS, dtype=params.dtype, device=params.device)
            quad = corners + params.unflatten(-1, (4, 2))  # (*, 4, 2)
            # unit square (u, v) from corner frame: u = (x + 1) / 2
            half = torch.tensor([[0.5, 0, 0.5], [0, 0.5, 0.5], [0, 0, 1.0]],
                                dtype=params.dtype, device=params.device)
            poison = (params * 0).sum(-1)[..., None, None]  # a NaN offset anywhere gives NaN
            return _square_to_quad(quad) @ half + poison
        gen = torch.einsum("...i,ijk->...jk", params, _sl3_basis(params))
        h = torch.linalg.matrix_exp(gen)
        return h if base is None else base @ h
    if model == "affine":
        return _rows_to_matrix([one + p[0], p[1], p[2], p[3], one + p[4], p[5], zero, zero, one])
    if model == "similarity":
        return _rows_to_matrix([one + p[0], -p[1], p[2], p[1], one + p[0], p[3], zero, zero, one])
    if model == "euclidean":
        c, s = torch.cos(p[0]), torch.sin(p[0])
        return _rows_to_matrix([c, -s, p[1], s, c, p[2], zero, zero, one])
    if model == "translation":
        return _rows_to_matrix([one, zero, p[0], zero, one, p[1], zero, zero, one])
    c, s = torch.cos(p[2]), torch.sin(p[2])
    sx, sy = torch.exp(p[3]), torch.exp(p[4])
    return _rows_to_matrix([c * sx, -s * sy, p[0], s * sx, c * sy, p[1], zero, zero, one])


def matrix_to_parameters(
    matrix: torch.Tensor, model: str = "homography", parametrization: str = "entries"
) -> torch.Tensor:
    """Parameters of ``matrix`` for ``model`` (the inverse of :func:`parameters_to_matrix`).

    Convention:
        Exact for matrices of the model's class; other matrices are projected
        (e.g. the rotation of a ``euclidean`` model is the polar angle of the
        linear part). For ``sl3`` the parameters are zero: pass ``matrix`` as
        ``base`` instead. ``h33`` is divided out first (unless it is exactly 0).
        A NaN or inf entry anywhere gives NaN parameters, also for an entry the
        model ignores. float16/bfloat16 are computed in float32.

    Args:
        matrix: ``(*, 3, 3)`` normalized-frame transforms.
        model: one of :data:`MODELS`.
        parametrization: one of :data:`PARAMETRIZATIONS`.

    Returns:
        ``(*, P)`` parameters.

    Example:
        >>> m = parameters_to_matrix(torch.tensor([0.1, 0.2, 0.3, 0.4, 0.5]), "trs")
        >>> matrix_to_parameters(m, "trs")
        tensor([0.1000, 0.2000, 0.3000, 0.4000, 0.5000])
    """
    check_choice(model, MODELS, "model")
    check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
    check_shape(matrix, ["*", "3", "3"], "matrix")
    check_float(matrix, "matrix")
    work = working_dtype(matrix.dtype)  # float16/bfloat16: computed in float32
    m = matrix.to(work)
    h33 = m[..., 2, 2]
    m = m / torch.where(h33 == 0, torch.ones_like(h33), h33)[..., None, None]  # NaN stays
    # a non-finite entry anywhere makes every parameter NaN, also those a model ignores
    poison = (m * 0).sum((-2, -1))[..., None]
    return cast_back(_matrix_to_parameters(m, model, parametrization) + poison, matrix.dtype)


def _matrix_to_parameters(m: torch.Tensor, model: str, parametrization: str) -> torch.Tensor:
    eye = torch.eye(3, dtype=m.dtype, device=m.device)
    if model == "homography":
        if parametrization == "entries":
            return (m - eye).flatten(-2)[..., :8]
        if parametrization == "corners":
            corners = torch.tensor(_CORNERS, dtype=m.dtype, device=m.device)
            return (transform_points(m, corners.expand(*m.shape[:-2], 4, 2)) - corners).flatten(-2)
        return m.new_zeros(*m.shape[:-2], 8)  # zeros: the matrix goes into ``base``
    if model == "affine":
        return (m - eye)[..., :2, :].flatten(-2)
    t = m[..., :2, 2]
    if model == "similarity":
        a = (m[..., 0, 0] + m[..., 1, 1]) / 2 - 1
        b = (m[..., 1, 0] - m[..., 0, 1]) / 2
        return torch.cat([torch.stack([a, b], -1), t], -1)
    if model == "euclidean":
        angle = torch.atan2(m[..., 1, 0] - m[..., 0, 1], m[..., 0, 0] + m[..., 1, 1])
        return torch.cat([angle[..., None], t], -1)
    if model == "translation":
        return t.clone()
    angle = torch.atan2(m[..., 1, 0], m[..., 0, 0])
    c, s = torch.cos(angle), torch.sin(angle)
    sx = torch.hypot(m[..., 0, 0], m[..., 1, 0])
    sy = -s * m[..., 0, 1] + c * m[..., 1, 1]
    tiny = torch.finfo(m.dtype).tiny
    log_s = torch.stack([sx, sy], -1).clamp_min(tiny).log()
    return torch.cat([t, angle[..., None], log_s], -1)
