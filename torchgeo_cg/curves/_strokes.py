"""Curve parameters of ordered samples and strokes of different lengths padded into one
batch, shared by the Bezier and B-spline fits (re-exported by
:mod:`torchgeo_cg.curves.fitting`)."""

from __future__ import annotations

from collections.abc import Sequence

import torch

from torchgeo_cg.core.check import ShapeError, check_choice, check_float, check_shape
from torchgeo_cg.core.numerics import safe_norm

__all__ = ["PARAMETRIZATIONS", "as_padded_strokes", "fit_parameters", "stroke_parameters"]


PARAMETRIZATIONS = ("uniform", "chord", "centripetal")


def fit_parameters(points: torch.Tensor, parametrization: str = "chord") -> torch.Tensor:
    """Parameters in ``[0, 1]`` for ordered samples ``(*, M, D)``.

    Convention:
        See the module docstring; ``t_0 = 0`` and ``t_{M-1} = 1``.

    Args:
        points: ``(*, M, D)``, ``M >= 2``.
        parametrization: ``"uniform"``, ``"chord"`` or ``"centripetal"``.

    Returns:
        ``(*, M)`` non-decreasing parameters (computed without gradients).

    Example:
        >>> fit_parameters(torch.tensor([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]]))
        tensor([0.0000, 0.3333, 1.0000])
    """
    check_float(points, "points")
    sizes = check_shape(points, ["*", "M", "D"], "points")
    if sizes["M"] < 2:
        raise ShapeError(f"points: expected at least 2 points, got shape {tuple(points.shape)}")
    check_choice(parametrization, PARAMETRIZATIONS, "parametrization")
    m = sizes["M"]
    with torch.no_grad():
        uniform = torch.linspace(0, 1, m, dtype=points.dtype, device=points.device)
        uniform = uniform.expand(*points.shape[:-2], m)
        if parametrization == "uniform":
            return uniform.clone()
        step = safe_norm(points[..., 1:, :] - points[..., :-1, :], dim=-1)  # (*, M - 1)
        if parametrization == "centripetal":
            step = step.sqrt()
        cumulative = torch.cat([torch.zeros_like(step[..., :1]), step.cumsum(-1)], dim=-1)
        total = cumulative[..., -1:]
        flat = total == 0  # all samples coincide: fall back to uniform; NaN stays NaN
        t = cumulative / torch.where(flat, torch.ones_like(total), total)
        return torch.where(flat, uniform, t)


def _pad_list(items, name: str) -> tuple[torch.Tensor, torch.Tensor]:
    """A list of ``(M_i, ...)`` tensors as a zero-padded ``(B, M, ...)`` tensor and lengths."""
    items = [torch.as_tensor(x) for x in items]
    if not items:
        raise ValueError(f"{name}: expected at least one stroke, got an empty list")
    lengths = torch.tensor([x.shape[0] for x in items], device=items[0].device)
    return torch.nn.utils.rnn.pad_sequence(items, batch_first=True), lengths


def as_padded_strokes(points, lengths=None, weights=None):
    """Normalise strokes to ``(points (*, M, D), valid (*, M), weights (*, M) | None)``.

    Args:
        points: ``(*, M, D)`` tensor, a list of ``(M_i, D)`` tensors or a nested tensor.
        lengths: ``(*,)`` integer valid rows of a padded tensor (default: all ``M``).
        weights: ``(*, M)`` non-negative per-sample weights (a list for list input),
            cast to the dtype of ``points``.

    Example:
        >>> p, valid, w = as_padded_strokes([torch.zeros(3, 2), torch.ones(2, 2)])
        >>> p.shape, valid.tolist(), w
        (torch.Size([2, 3, 2]), [[True, True, True], [True, True, False]], None)
    """
    if isinstance(points, torch.Tensor) and points.is_nested:
        points = list(points.unbind())
    if isinstance(points, Sequence) and not isinstance(points, torch.Tensor):
        if lengths is not None:
            raise ValueError("lengths: give lengths only with a padded tensor, not a list")
        points, lengths = _pad_list(points, "points")
        if weights is not None and not isinstance(weights, torch.Tensor):
            weights = _pad_list(weights, "weights")[0]
    check_float(points, "points")
    sizes = check_shape(points, ["*", "M", "D"], "points")
    m = sizes["M"]
    if lengths is None:
        valid = torch.ones(points.shape[:-1], dtype=torch.bool, device=points.device)
    else:
        lengths = torch.as_tensor(lengths, device=points.device)
        if lengths.is_floating_point() or tuple(lengths.shape) != tuple(sizes["*"]):
            raise ShapeError(f"lengths: expected an integer tensor of shape {tuple(sizes['*'])},"
                             f" got {lengths.dtype} {tuple(lengths.shape)}")
        if lengths.numel() and (int(lengths.min()) < 0 or int(lengths.max()) > m):
            raise ValueError(f"lengths: expected values in [0, {m}], got {lengths.tolist()}")
        valid = torch.arange(m, device=points.device) < lengths[..., None]
    if weights is not None:
        check_float(weights, "weights")
        check_shape(weights, [*sizes["*"], m], "weights")
        if bool((weights < 0).any()):
            raise ValueError("weights: expected non-negative weights, got a negative one")
        weights = weights.to(points)
    return points, valid, weights


def stroke_parameters(points, valid, parametrization: str) -> torch.Tensor:
    """Chord/centripetal/uniform parameters ``(*, M)`` over the valid rows of padded strokes.

    Args:
        points: ``(*, M, D)`` padded strokes.
        valid: ``(*, M)`` bool, the valid rows (a prefix of each stroke).
        parametrization: ``"uniform"``, ``"chord"`` or ``"centripetal"``.

    Returns:
        ``(*, M)`` parameters in ``[0, 1]``; padded rows get ``0``.

    Example:
        >>> points = torch.tensor([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [9.0, 9.0]])
        >>> stroke_parameters(points, torch.tensor([True, True, True, False]), "chord")
        tensor([0.0000, 0.3333, 1.0000, 0.0000])
    """
    if bool(valid.all()):
        return fit_parameters(points, parametrization)
    with torch.no_grad():
        n_valid = valid.sum(-1, keepdim=True).to(points.dtype)
        index = torch.arange(points.shape[-2], device=points.device).to(points.dtype)
        uniform = (index / (n_valid - 1).clamp_min(1)).clamp_max(1)
        if parametrization == "uniform":
            return torch.where(valid, uniform, 0.0)
        step = safe_norm(points[..., 1:, :] - points[..., :-1, :], dim=-1)
        step = torch.where(valid[..., 1:], step, 0.0)
        if parametrization == "centripetal":
            step = step.sqrt()
        cumulative = torch.cat([torch.zeros_like(step[..., :1]), step.cumsum(-1)], dim=-1)
        total = cumulative[..., -1:]
        flat = total == 0  # all valid samples coincide: uniform; NaN stays NaN
        t = torch.where(flat, uniform, cumulative / torch.where(flat, 1.0, total))
        return torch.where(valid, t, 0.0)
