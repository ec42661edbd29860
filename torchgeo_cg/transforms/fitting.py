"""Iterative fitting of 2D transforms (and 3D rigid and similarity ones) to correspondences.

The design asks for homographies fitted by gradient descent, so that a network can
be trained through them. :func:`fit_transform` fits one transform per problem of a
batch with Adam, L-BFGS or Levenberg-Marquardt, and :class:`HomographyModel` is a
learnable homography with the same parametrizations.

Hartley normalization is built into every parametrization: the parameters live in
the frame where both point sets are centered with mean distance ``sqrt(2)``, where
plain gradient descent on the 8 raw entries converges (in pixel units it does not:
the entries differ in scale by orders of magnitude).

Convention:
    - Column vectors, ``dst ~ M @ [x, y, 1]ᵀ`` with the perspective divide;
      ``matrix`` maps ``src`` to ``dst`` (``dst_from_src``).
    - ``params`` are those of the *normalized* transform ``Ĥ = T_dst M T_src⁻¹``
      (see :func:`parameters_to_matrix`); angles in radians, scales as logs.
    - Homography and affine models normalize ``src`` and ``dst`` separately; the
      similarity, euclidean, translation and trs models share one scale between
      them, so that the normalized transform stays in its class.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import torch
from torch import nn
from tqdm.auto import tqdm

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import (
    ShapeError,
    check_broadcastable,
    check_choice,
    check_float,
    check_shape,
)
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.transforms._correspondences import (
    check_pair,
    check_points_nonempty,
    effective_weights,
    hartley_weighted,
)
from torchgeo_cg.transforms._fit_3d import lm_fit_3d
from torchgeo_cg.transforms._objective import Objective, denormalize, loss_terms, normalize_problem
from torchgeo_cg.transforms._solvers import (
    ParamFn,
    first_order,
    gauss_newton_step,
    levenberg_marquardt,
)
from torchgeo_cg.transforms.estimation import find_euclidean, find_similarity
from torchgeo_cg.transforms.homogeneous import inverse, transform_points
from torchgeo_cg.transforms.parametrization import (
    MODELS,
    PARAMETRIZATIONS,
    matrix_to_parameters,
    parameters_to_matrix,
)
from torchgeo_cg.transforms.robust import LOSSES

__all__ = [
    "FitResult",
    "SolverOptions",
    "LossOptions",
    "fit_transform",
    "HomographyModel",
]

_DEFAULT_STEPS = {"adam": 200, "lbfgs": 50, "lm": 10}


_DEFAULT_LR = {"adam": 0.05, "lbfgs": 1.0, "lm": 1e-3}


@dataclass(frozen=True)
class SolverOptions:
    """How :func:`fit_transform` optimizes: the optimizer and when it stops, validated once.

    Attributes:
        optimizer: ``"lm"`` (default, Levenberg-Marquardt; the only one in 3D),
            ``"adam"`` or ``"lbfgs"``.
        steps: maximum iterations, ``>= 0`` (``None``: adam 200, lbfgs 50, lm 10).
        lr: learning rate (``None``: adam 0.05, lbfgs 1) or initial LM damping
            (``None``: 1e-3).
        tol: relative improvement below which a problem counts as converged, ``>= 0``
            (``None``: ``1000 * eps`` of the dtype, 2.2e-13 in float64, 1.2e-4 in float32).
        patience: adam/lbfgs stop after this many steps without improvement.
        progress: show a tqdm progress bar.

    Raises:
        ValueError: an unknown optimizer, negative or non-integer ``steps``, a negative
            or non-finite ``tol`` (the message names the field).

    Example:
        >>> SolverOptions(optimizer="adam", steps=500).steps
        500
    """

    optimizer: str = "lm"
    steps: int | None = None
    lr: float | None = None
    tol: float | None = None
    patience: int = 20
    progress: bool = False

    def __post_init__(self) -> None:
        check_choice(self.optimizer, _DEFAULT_STEPS, "optimizer")
        steps = self.steps
        if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int)
                                  or steps < 0):
            raise ValueError(f"steps: expected a non-negative int, got {steps!r}")
        if self.tol is not None and not (math.isfinite(float(self.tol)) and self.tol >= 0):
            raise ValueError(f"tol: expected a finite number >= 0 (a relative improvement), "
                             f"got {self.tol!r}")


@dataclass(frozen=True)
class LossOptions:
    """What :func:`fit_transform` minimizes: the (robust) transfer error, validated once.

    Attributes:
        loss: ``"l2"`` (default, the mean squared transfer error), ``"huber"``,
            ``"cauchy"`` or ``"tukey"`` (``torchgeo_cg.transforms.robust.LOSSES``, the
            ``rho`` of :func:`~torchgeo_cg.transforms.robust_loss`).
        scale: the robust scale ``c`` in input units (pixels), finite and ``> 0``;
            unused by ``"l2"``.
        symmetric: add the backward transfer error ``Σ w ρ(‖π(M⁻¹ q) - p‖²) / Σ w``
            (2D only).

    Raises:
        ValueError: an unknown loss or a scale that is not finite and positive.

    Example:
        >>> LossOptions("tukey", scale=0.1)
        LossOptions(loss='tukey', scale=0.1, symmetric=False)
    """

    loss: str = "l2"
    scale: float = 1.0
    symmetric: bool = False

    def __post_init__(self) -> None:
        check_choice(self.loss, LOSSES, "loss")
        scale = float(self.scale)
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"scale: expected a finite positive number of pixels, "
                             f"got {self.scale!r}")


def _check_bundle(value, cls, name: str):
    if not isinstance(value, cls):
        raise TypeError(f"{name}: expected a {cls.__name__}, got {type(value).__name__}")
    return value


class FitResult(NamedTuple):
    """Result of :func:`fit_transform`.

    Attributes:
        matrix: ``(*, 3, 3)`` fitted ``dst_from_src`` (``matrix[..., 2, 2] = 1``).
        params: ``(*, P)`` parameters of the normalized transform (see
            :func:`parameters_to_matrix`).
        loss: ``(*)`` final loss in input units squared (mean squared transfer
            error, robust ``ρ`` of ``LossOptions.loss``, plus the backward one if
            ``LossOptions.symmetric``).
        history: ``(steps_run + 1, *)`` the loss at the start and after each step.
    """

    matrix: torch.Tensor
    params: torch.Tensor
    loss: torch.Tensor
    history: torch.Tensor


def fit_transform(
    src: torch.Tensor,
    dst: torch.Tensor,
    model: str = "homography",
    *,
    weights: torch.Tensor | None = None,
    init: torch.Tensor | None = None,
    parametrization: str = "entries",
    solver: SolverOptions = SolverOptions(),
    loss: LossOptions = LossOptions(),
) -> FitResult:
    """Fit ``dst_from_src`` of a ``model`` to correspondences by iterative optimization, batched.

    Every problem of the batch is fitted at once (the losses are independent, so
    Adam and LM treat each problem separately; L-BFGS sees their sum).

    Convention:
        Column vectors; ``dst ~ matrix @ [x, y, 1]ᵀ``. The loss is the weighted
        mean robust transfer error ``Σ w ρ(‖π(M p) - q‖²) / Σ w`` (plus
        ``Σ w ρ(‖π(M⁻¹ q) - p‖²) / Σ w`` if ``loss.symmetric``), with ``ρ`` of
        :func:`robust_loss` at ``loss.scale`` (input units, pixels): ``"l2"`` is the
        plain mean squared error. It is optimized in the Hartley-normalized
        frame (the scale moves with it) and reported in input units squared.
        ``"lm"`` solves robust losses by iteratively reweighted least squares
        (the weights ``ρ'(r²)`` are recomputed at every LM iteration, and a step
        is accepted only if the robust cost decreases); ``"adam"``/``"lbfgs"``
        descend the robust cost directly. Robust losses need a good start
        (``init``, e.g. from :func:`find_transform_ransac`): Cauchy and Tukey
        are not convex. ``init=None``
        starts from the identity of the normalized frame (which maps the src
        centroid to the dst centroid). float16/bfloat16 inputs are fitted in
        float32 and the results returned in their dtype. Differentiable with
        respect to ``src``, ``dst`` and ``weights``: ``"lm"`` is unrolled (exact derivative of the
        result); ``"adam"`` and ``"lbfgs"`` run detached and, only when an
        input requires grad, end with one Gauss-Newton step that carries the
        implicit-function gradient (exact at a zero-residual optimum; the
        returned value then moves by that one refining step).

        In 3D (``(*, N, 3)`` points, ``(*, 4, 4)`` matrices) the models are
        ``"euclidean"`` (rigid) and ``"similarity"``, fitted by ``"lm"`` only, on
        se(3): each step is a left perturbation ``Ĥ ← E(δ) Ĥ`` of the normalized
        transform with ``δ = (v, ω)`` (plus ``log`` of the scale for a similarity)
        and ``E = se3_exp``, so there is no singularity at any rotation.
        ``init=None`` starts from the weighted least-squares optimum
        (:func:`find_euclidean` / :func:`find_similarity`), so ``"l2"`` returns it
        (polished) and the robust losses start there (Tukey's weights vanish beyond
        ``scale``: with many outliers start it from a Cauchy fit or
        :func:`find_transform_ransac`); ``params`` are
        ``se3_log`` of the normalized ``[[R, t̂], [0, 1]]`` (``(*, 6)``), with
        ``log s`` appended for a similarity (``(*, 7)``). ``loss.symmetric`` and
        ``parametrization`` do not apply in 3D (ValueError).

    Args:
        src: ``(*, N, 2)`` or ``(*, N, 3)`` source points.
        dst: ``(*, N, 2)`` or ``(*, N, 3)`` destination points.
        model: one of :data:`MODELS` (``"trs"`` is the report's ``T·R·Xs·Ys``).
        weights: optional ``(*, N)`` non-negative weights.
        init: optional ``(*, 3, 3)`` (3D: ``(*, 4, 4)``, rigid or a similarity)
            starting ``dst_from_src``.
        parametrization: for ``model="homography"``: ``"entries"``, ``"corners"``
            (4-corner offsets) or ``"sl3"`` (Lie-algebra exponential).
        solver: :class:`SolverOptions`: optimizer, steps, learning rate or damping,
            tolerance, patience, progress bar.
        loss: :class:`LossOptions`: the robust loss, its scale, and whether the error
            is symmetric.

    Returns:
        :class:`FitResult` ``(matrix (*, 3, 3), params (*, P), loss (*),
        history (steps_run + 1, *))``; in 3D ``matrix (*, 4, 4)``.

    Example:
        >>> from torchgeo_cg.transforms import homography, transform_points
        >>> h = homography(torch.tensor([0.27, 0, -0.85, -0.25, -0.2, 5.65, -0.02, -0.09],
        ...                             dtype=torch.float64))
        >>> src = torch.tensor([[0.0, 0], [4, 0], [4, 5], [0, 5], [2, 1]], dtype=torch.float64)
        >>> fit = fit_transform(src, transform_points(h, src), solver=SolverOptions("lm"))
        >>> torch.allclose(fit.matrix, h, atol=1e-9), fit.history.shape[0] <= 11
        (True, True)

        A rigid motion in 3D with 30% gross outliers: Tukey's loss, started from the
        least-squares fit, rejects them exactly (Cauchy still feels them, 7e-5 here):

        >>> from torchgeo_cg.transforms import se3_exp
        >>> g = torch.Generator().manual_seed(0)
        >>> m = se3_exp(torch.tensor([0.5, -1.0, 2.0, 0.3, -0.2, 0.4], dtype=torch.float64))
        >>> src = torch.randn(200, 3, generator=g, dtype=torch.float64)
        >>> dst = transform_points(m, src)
        >>> dst[:60] += 3 * torch.randn(60, 3, generator=g, dtype=torch.float64)
        >>> fit = fit_transform(src, dst, "euclidean", loss=LossOptions("tukey", scale=0.1),
        ...                     solver=SolverOptions(steps=50))
        >>> fit.matrix.shape, bool((fit.matrix - m).abs().max() < 1e-12)
        (torch.Size([4, 4]), True)
    """
    weights = check_pair(src, dst, weights, dims=(2, 3))
    solver = _check_bundle(solver, SolverOptions, "solver")
    loss = _check_bundle(loss, LossOptions, "loss")
    if working_dtype(src.dtype) != src.dtype:  # float16/bfloat16: fitted in float32
        work = working_dtype(src.dtype)
        fit = fit_transform(src.to(work), dst.to(work), model,
                            weights=None if weights is None else weights.to(work),
                            init=None if init is None else check_float(init, "init").to(work),
                            parametrization=parametrization, solver=solver, loss=loss)
        return FitResult(*(cast_back(t, src.dtype) for t in fit))
    check_choice(model, MODELS, "model")
    check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
    optimizer, scale, kind = solver.optimizer, float(loss.scale), loss.loss
    if src.shape[-1] == 3:
        _check_3d(model, optimizer, parametrization, loss.symmetric)
    steps = _DEFAULT_STEPS[optimizer] if solver.steps is None else solver.steps
    lr = _DEFAULT_LR[optimizer] if solver.lr is None else float(solver.lr)
    tol = 1000 * torch.finfo(src.dtype).eps if solver.tol is None else float(solver.tol)
    progress = solver.progress
    if src.shape[-1] == 3:
        return _fit_3d(src, dst, model, steps, init, kind, weights, lr, tol, progress, scale)
    batch, n = src.shape[:-2], src.shape[-2]
    p_in, q_in = src.reshape(-1, n, 2), dst.reshape(-1, n, 2)
    w = effective_weights(p_in, None if weights is None else weights.reshape(-1, n))
    prob = normalize_problem(p_in, q_in, w, model)
    base = None
    if init is not None:
        init = _expand_init(init, src, batch, 3)
        init_n = prob.t_dst @ init @ inverse(prob.t_src)
        theta = matrix_to_parameters(init_n, model, parametrization).detach()
        if model == "homography" and parametrization == "sl3":
            base = init_n.detach()
    else:
        theta = src.new_zeros(p_in.shape[0], MODELS[model])
    fn = ParamFn(model, parametrization, base)
    objective = Objective(bool(loss.symmetric), kind, scale * prob.scale_dst,
                          scale * prob.scale_src)
    bar = tqdm(range(steps), disable=not progress, desc=f"fit {model} ({optimizer})")
    with torch.no_grad():
        history = [loss_terms(fn(theta), prob, objective)[1]]
    if optimizer == "lm":
        theta = levenberg_marquardt(fn, theta, prob, objective, steps, lr, tol, bar, history)
    else:
        theta = first_order(optimizer, fn, theta, prob, objective, steps, lr, tol,
                            solver.patience, bar, history)
        if records_graph(src, dst, weights):
            theta = gauss_newton_step(fn, theta, prob, objective)
    bar.close()
    hn = fn(theta)
    matrix = denormalize(hn, prob)
    _, final = loss_terms(hn, prob, objective)
    return FitResult(
        matrix.reshape(*batch, 3, 3),
        theta.reshape(*batch, theta.shape[-1]),
        final.reshape(batch),
        torch.stack([h.detach() for h in history]).reshape(len(history), *batch),
    )


_MODELS_3D = {"euclidean": 6, "similarity": 7}


def _check_3d(model: str, optimizer: str, parametrization: str, symmetric: bool) -> None:
    if model not in _MODELS_3D:
        raise ValueError(f"model: 3D points (*, N, 3) are fitted as 'euclidean' or "
                         f"'similarity', got {model!r}")
    if optimizer != "lm":
        raise ValueError(f"optimizer: 3D fits use 'lm' (on se(3)), got {optimizer!r}")
    if parametrization != "entries":
        raise ValueError(f"parametrization: 3D fits are parametrized on se(3) only; leave it "
                         f"at 'entries', got {parametrization!r}")
    if symmetric:
        raise ValueError("symmetric: 3D fits minimize the forward transfer error only")


def _expand_init(init: torch.Tensor, src: torch.Tensor, batch, size: int) -> torch.Tensor:
    """``init (*, size, size)`` checked against the batch of ``src``, as ``(B, size, size)``."""
    check_shape(init, ["*", str(size), str(size)], "init")
    check_float(init, "init")
    if check_broadcastable({"src": batch, "init": init.shape[:-2]}) != tuple(batch):
        raise ShapeError(f"init: expected ({size}, {size}) or batch dims that broadcast to "
                         f"src's {tuple(batch)}, got {tuple(init.shape)}")
    return init.to(src).expand(*batch, size, size).reshape(-1, size, size)


def _fit_3d(src, dst, model, steps, init, loss, weights, lr, tol, progress, scale) -> FitResult:
    batch, n = src.shape[:-2], src.shape[-2]
    p_in, q_in = src.reshape(-1, n, 3), dst.reshape(-1, n, 3)
    w = effective_weights(p_in, None if weights is None else weights.reshape(-1, n))
    with_scale = model == "similarity"
    if init is None:  # the weighted least-squares optimum, in closed form
        closed = find_similarity if with_scale else find_euclidean
        init = closed(p_in, q_in, w).matrix
    else:
        init = _expand_init(init, src, batch, 4)
    bar = tqdm(range(steps), disable=not progress, desc=f"fit {model} 3D (lm)")
    matrix, params, final, history = lm_fit_3d(p_in, q_in, w, init, with_scale, loss, scale,
                                                steps, lr, tol, bar)
    bar.close()
    return FitResult(
        matrix.reshape(*batch, 4, 4),
        params.reshape(*batch, params.shape[-1]),
        final.reshape(batch),
        torch.stack(history).reshape(len(history), *batch),
    )


class HomographyModel(nn.Module):
    """A learnable homography ``dst_from_src`` with the parametrizations of :func:`fit_transform`.

    ``matrix() = T_dst⁻¹ Ĥ(params) T_src`` where ``T_src``/``T_dst`` are Hartley
    normalizations (buffers, identity unless ``src``/``dst`` are given) and
    ``Ĥ = parameters_to_matrix(params, "homography", parametrization, base)``.

    Convention:
        Column vectors; ``forward(points)`` is ``transform_points(matrix(), points)``.
        ``params`` is an ``nn.Parameter`` of shape ``(*batch_shape, 8)``, zero
        (the identity, or ``init``) at construction; the normalizations and the
        ``sl3`` base are non-persistent buffers, so ``.to()`` moves everything.

    Args:
        parametrization: ``"entries"``, ``"corners"`` or ``"sl3"`` (same default as
            :func:`fit_transform`).
        batch_shape: leading shape of the parameters (one homography per item).
        src: optional ``(*batch_shape, N, 2)`` points defining ``T_src`` (``N >= 1``,
            else ``ShapeError``).
        dst: optional ``(*batch_shape, N, 2)`` points defining ``T_dst``.
        init: optional ``(*batch_shape, 3, 3)`` starting ``dst_from_src``.
        device: device of the parameters (when no tensor is given).
        dtype: dtype of the parameters (when no tensor is given).

    Example:
        >>> model = HomographyModel()
        >>> model(torch.tensor([[1.0, 2.0]])).detach()
        tensor([[1., 2.]])
        >>> model.params.shape
        torch.Size([8])
    """

    def __init__(
        self,
        parametrization: str = "entries",
        batch_shape: tuple[int, ...] = (),
        src: torch.Tensor | None = None,
        dst: torch.Tensor | None = None,
        init: torch.Tensor | None = None,
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__()
        check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
        self.parametrization = parametrization
        given = [(name, t) for name, t in (("src", src), ("dst", dst), ("init", init))
                 if t is not None]
        for name, t in given[1:]:
            if t.dtype != given[0][1].dtype:
                raise TypeError(f"{name}: expected the dtype of {given[0][0]} "
                                f"({given[0][1].dtype}), got {t.dtype}")
        ref = given[0][1] if given else None
        kw = {"device": device if ref is None else ref.device,
              "dtype": (dtype or torch.get_default_dtype()) if ref is None else ref.dtype}
        batch_shape = tuple(batch_shape)
        eye = torch.eye(3, **kw).expand(*batch_shape, 3, 3)
        t_src, t_dst = eye, eye
        for name, pts in (("src", src), ("dst", dst)):
            if pts is None:
                continue
            check_shape(pts, [*map(str, batch_shape), "N", "2"], name)
            check_float(pts, name)
            check_points_nonempty(pts, name)  # no normalization of zero points (was NaN)
            t = hartley_weighted(pts, torch.ones_like(pts[..., 0])).transform
            t_src, t_dst = (t, t_dst) if name == "src" else (t_src, t)
        self.register_buffer("src_transform", t_src.clone(), persistent=False)
        self.register_buffer("dst_transform", t_dst.clone(), persistent=False)
        params = torch.zeros(*batch_shape, 8, **kw)
        base = None
        if init is not None:
            check_shape(init, [*map(str, batch_shape), "3", "3"], "init")
            check_float(init, "init")
            init_n = t_dst @ init.to(**kw) @ inverse(t_src)
            params = matrix_to_parameters(init_n, "homography", parametrization)
            if parametrization == "sl3":
                base = init_n
        self.register_buffer("base", base, persistent=False)
        self.params = nn.Parameter(params.detach().clone())

    def matrix(self) -> torch.Tensor:
        """The current ``(*batch_shape, 3, 3)`` ``dst_from_src``.

        Example:
            >>> HomographyModel(batch_shape=(2,)).matrix().shape
            torch.Size([2, 3, 3])
        """
        hn = parameters_to_matrix(self.params, "homography", self.parametrization, self.base)
        h = inverse(self.dst_transform) @ hn @ self.src_transform
        h33 = h[..., 2, 2]
        return h / torch.where(h33 != 0, h33, torch.ones_like(h33))[..., None, None]

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """Transform ``points`` ``(*batch_shape, N, 2)`` -> ``(*batch_shape, N, 2)``."""
        check_shape(points, ["*", "N", "2"], "points")
        return transform_points(self.matrix(), points)
