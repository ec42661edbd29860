"""Shared numerics that hold at every scale and never give birth to NaN or inf.

Geometry has no unit, so no helper here compares a value with an absolute
threshold by default:

- guards act only where a result is exactly undefined (a zero denominator, the
  gradient of a norm at the zero vector), or at a threshold the *caller* scales
  with its operands (``eps=torch.finfo(dtype).eps * scale``);
- norms are overflow- and underflow-safe: :func:`hypot` chains ``torch.hypot``
  (which scales internally), :func:`safe_norm` uses it for short vectors and
  divides by the largest component first for long ones;
- float16 and bfloat16 are computed in float32 by the callers that declare it
  (:func:`working_dtype`, :func:`cast_back`), and cast back saturating, so a
  huge-but-finite float32 value becomes ``±finfo(float16).max``, never ``inf``.

All helpers use the double-``where`` idiom: the unsafe input is replaced by a
safe value *before* the dangerous operation, so the branch that is thrown away
cannot poison the gradient. NaN inputs give NaN outputs.

Legacy note: ``safe_div``, ``safe_sqrt``, ``safe_norm`` and
``clamp_away_from_zero`` keep their signatures; an explicit ``eps`` keeps its
old meaning (an absolute bound chosen by the caller), only the *defaults* changed
from absolute constants (1e-8, 1e-12) to "exact zero only".
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import check_broadcastable, check_float
from torchgeo_cg.core.coerce import check_same_dtype

__all__ = [
    "clamp_away_from_zero",
    "safe_div",
    "safe_sqrt",
    "safe_norm",
    "hypot",
    "working_dtype",
    "cast_back",
    "power_of_two_scale",
]

#: vectors up to this length are normed by chained ``torch.hypot`` (fast, few temporaries)
_HYPOT_MAX = 4


def working_dtype(dtype: torch.dtype) -> torch.dtype:
    """The dtype to compute in: float32 for float16/bfloat16, ``dtype`` otherwise.

    Example:
        >>> working_dtype(torch.float16), working_dtype(torch.float64)
        (torch.float32, torch.float64)
    """
    if dtype in (torch.float16, torch.bfloat16):
        return torch.float32
    return dtype


def cast_back(x: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """Cast ``x`` to ``dtype``, saturating at ``±finfo(dtype).max`` (NaN stays NaN).

    A no-op (the same tensor) when ``x`` already has ``dtype``; only a narrowing
    cast to float16/bfloat16 clamps, so a value beyond the small range becomes the
    largest finite value instead of ``inf``.

    Example:
        >>> cast_back(torch.tensor([1e6, -1e6, float("nan"), 1.5]), torch.float16)
        tensor([ 65504., -65504.,     nan,      1.5000], dtype=torch.float16)
    """
    if x.dtype == dtype:
        return x
    if dtype in (torch.float16, torch.bfloat16):
        big = torch.finfo(dtype).max
        x = x.clamp(-big, big)
    return x.to(dtype)


def power_of_two_scale(magnitude: torch.Tensor) -> torch.Tensor:
    """The power of two ``2**e`` just above ``magnitude``: ``magnitude / 2**e`` in ``[0.5, 1)``.

    Dividing data by the scale of its largest magnitude is exact (no rounding), leaves
    every ratio, sign and direction unchanged, and brings the data into ``[-1, 1]``, where
    products of a few coordinates neither overflow nor underflow at any input scale.
    Above the dtype's largest power of two (where ``2**e`` would be ``inf``) the scale is
    that power, and the data lands in ``[-2, 2]``. Where ``magnitude`` is zero, NaN or
    infinite the scale is 1 (nothing to scale; NaN and inf pass through the division).
    The result is detached (a constant factor).

    Args:
        magnitude: ``(*)`` non-negative magnitudes, typically ``x.abs().amax(dims)`` of
            the data to scale (any float dtype).

    Returns:
        ``(*)`` powers of two, dtype and device of ``magnitude``.

    Example:
        >>> x = torch.tensor([[3.0, -0.1], [0.0, 0.0], [1e-30, 5e-31]])
        >>> scale = power_of_two_scale(x.abs().amax(-1, keepdim=True))
        >>> scale.flatten(), (x / scale).abs().amax(-1)
        (tensor([4.0000e+00, 1.0000e+00, 1.5777e-30]), tensor([0.7500, 0.0000, 0.6338]))
    """
    big = magnitude.detach()
    _, exponent = torch.frexp(big)  # big = m * 2**e with m in [0.5, 1)
    top = math.frexp(torch.finfo(big.dtype).max)[1] - 1  # 2**top is the largest finite
    one = torch.ones_like(big)
    return torch.where(torch.isfinite(big) & (big > 0), torch.ldexp(one, exponent.clamp_max(top)),
                       one)


def clamp_away_from_zero(x: torch.Tensor, eps: float | torch.Tensor | None = None) -> torch.Tensor:
    """Replace entries with ``|x| < eps`` by ``eps`` carrying the sign of ``x``.

    ``eps=None`` (default) guards only exact zeros and subnormals: the bound is
    ``finfo(x.dtype).tiny``. Pass a bound that scales with the operands, e.g.
    ``torch.finfo(x.dtype).eps * scale`` (a tensor broadcastable with ``x``), for a
    relative guard. ``+0.0`` becomes ``+eps`` and ``-0.0`` becomes ``-eps``. Where an
    entry was replaced its gradient is zero. NaN stays NaN.

    Example:
        >>> clamp_away_from_zero(torch.tensor([2.0, 0.0, -1e-12, float("nan")]), 1e-8)
        tensor([ 2.0000e+00,  1.0000e-08, -1.0000e-08,         nan])
        >>> clamp_away_from_zero(torch.tensor([1e-30, -0.0]))  # default: exact zeros only
        tensor([ 1.0000e-30, -1.1755e-38])
    """
    check_float(x, "x")
    tiny = torch.finfo(x.dtype).tiny
    if isinstance(eps, torch.Tensor):
        floor = eps.to(x.dtype).clamp_min(tiny)
    else:
        floor = torch.full_like(x, tiny if eps is None else max(float(eps), tiny))
    return torch.where(x.abs() < floor, floor.copysign(x), x)


def safe_div(
    num: torch.Tensor, den: torch.Tensor, eps: float | torch.Tensor | None = None
) -> torch.Tensor:
    """``num / den`` that is finite where ``den`` is zero, with finite gradients.

    Args:
        num: numerator, any shape broadcastable with ``den``.
        den: denominator.
        eps: ``None`` (default): the quotient is defined as ``0`` where ``den == 0``
            exactly (NaN if ``num`` is NaN), and is ``num / den`` everywhere else:
            no threshold, so the result is the same at every scale. A number or a
            tensor: the legacy guard, ``|den| < eps`` is replaced by ``±eps`` (sign
            kept, ``+eps`` at ``+0``); pass a bound that scales with the operands.

    Returns:
        The broadcast quotient. Gradients are zero where the guard acted.

    Example:
        >>> safe_div(torch.tensor([1.0, 1.0, 1.0]), torch.tensor([2.0, 0.0, -1e-12]))
        tensor([ 5.0000e-01,  0.0000e+00, -1.0000e+12])
        >>> safe_div(torch.tensor([1.0, 1.0]), torch.tensor([0.0, -1e-12]), eps=1e-8)
        tensor([ 1.0000e+08, -1.0000e+08])
    """
    check_float(num, "num")
    check_float(den, "den")
    check_broadcastable({"num": num.shape, "den": den.shape})
    if eps is not None:
        return num / clamp_away_from_zero(den, eps)
    zero = den == 0
    quotient = num / torch.where(zero, torch.ones_like(den), den)
    # (num * 0) is 0 for finite num and NaN for NaN num: NaN in, NaN out
    return torch.where(zero, quotient * 0, quotient)


def safe_sqrt(x: torch.Tensor, eps: float | None = None) -> torch.Tensor:
    """``sqrt(max(x, 0))`` with a finite gradient; NaN stays NaN.

    The gradient is zero where ``x <= eps`` (default ``eps=None``: where ``x <= 0``,
    i.e. only where it is undefined). An explicit ``eps`` is an absolute bound
    chosen by the caller.

    Example:
        >>> x = torch.tensor([4.0, 0.0, -1.0], requires_grad=True)
        >>> y = safe_sqrt(x)
        >>> y.sum().backward()
        >>> y.detach(), x.grad
        (tensor([2., 0., 0.]), tensor([0.2500, 0.0000, 0.0000]))
    """
    check_float(x, "x")
    positive = x > (0.0 if eps is None else eps)
    x_safe = torch.where(positive, x, torch.ones_like(x))
    # (x * 0).abs() is 0 for finite x and NaN for NaN, so NaN in gives NaN out
    return torch.where(positive, x_safe.sqrt(), (x * 0).abs())


def _hypot_exact(components: tuple[torch.Tensor, ...]) -> torch.Tensor:
    """Chained ``torch.hypot``: scales internally, never overflows or underflows (slow)."""
    out = torch.hypot(components[0], components[1])
    for c in components[2:]:
        out = torch.hypot(out, c)
    return out


def _hypot_value(components: tuple[torch.Tensor, ...]) -> torch.Tensor:
    """``sqrt(sum c^2)``: the fast sum of squares, redone exactly where it lost range.

    The sum of squares is exact to rounding wherever it is a normal, finite number
    (``lo <= sq <= max``); one ``aminmax`` pass checks that. Only the entries outside
    (overflow, underflow, exact zeros whose components may be subnormal) are
    recomputed with chained ``torch.hypot``; ``inf`` inputs give ``inf``.
    """
    sq = components[0] * components[0]  # fresh: accumulated in place (fastest on CPU)
    for c in components[1:]:
        if c.shape == sq.shape:
            sq += c * c
        else:
            sq = sq + c * c
    if sq.numel() == 0:
        return sq.sqrt_()
    info = torch.finfo(sq.dtype)
    lo = info.tiny / info.eps  # below this, squares of the components lost digits
    try:
        low, high = torch.aminmax(sq)
        fine = float(low) >= lo and float(high) <= info.max
    except RuntimeError:  # data-dependent branching is impossible (vmap): always exact
        return _hypot_exact(components)
    if fine:
        return sq.sqrt_()
    redo = (sq < lo) | (sq > info.max)  # NaN entries stay as they are (NaN)
    out = sq.sqrt_()
    if bool(redo.any()):
        parts = tuple(c.expand_as(out)[redo] for c in components)
        out.masked_scatter_(redo, _hypot_exact(parts))
    return out


class _Hypot(torch.autograd.Function):
    """``sqrt(sum c_i^2)`` without intermediate overflow; gradient ``c_i / r``, 0 at ``r = 0``."""

    generate_vmap_rule = True

    @staticmethod
    def forward(*components: torch.Tensor) -> torch.Tensor:
        return _hypot_value(components)

    @staticmethod
    def setup_context(ctx, inputs, output) -> None:
        ctx.save_for_backward(output, *inputs)
        ctx.save_for_forward(output, *inputs)

    @staticmethod
    def jvp(ctx, *tangents):
        # forward mode: d r = sum c_i d c_i / r, 0 at r = 0 (as the backward)
        out, *components = ctx.saved_tensors
        total = sum(c * t for c, t in zip(components, tangents) if t is not None)
        return total / torch.where(out > 0, out, torch.ones_like(out))

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        out, *components = ctx.saved_tensors
        # r > 0 is False for r = 0 (where every c_i = 0, so c_i / 1 = 0) and for NaN
        # (where c_i / 1 keeps the NaN of the NaN component, or is finite elsewhere).
        scale = grad / torch.where(out > 0, out, torch.ones_like(out))
        return tuple(scale * c for c in components)


def hypot(*components: torch.Tensor) -> torch.Tensor:
    """Euclidean length ``sqrt(c_0^2 + c_1^2 + ...)`` of a vector given by its components.

    Overflow- and underflow-safe: ``hypot(2e19, 2e19)`` is ``2.83e19`` in float32,
    where the naive sum of squares is ``inf``. Fast: the plain sum of squares is
    used wherever it is in range (checked by one ``aminmax`` pass) and only the
    entries out of range are recomputed by chained ``torch.hypot`` (which scales
    internally); under ``vmap`` every entry takes the exact path. The gradient is
    ``c_i / r``, and zero at the zero vector (not NaN); differentiable twice. NaN in
    gives NaN out (IEEE: an infinite component wins).

    Args:
        *components: one or more broadcastable tensors of one float dtype and device
            (else ``TypeError`` naming two of them).

    Returns:
        The broadcast length.

    Example:
        >>> hypot(torch.tensor([3.0, 2e19, 0.0]), torch.tensor([4.0, 2e19, 0.0]))
        tensor([5.0000e+00, 2.8284e+19, 0.0000e+00])
    """
    first = components[0]
    if not all(isinstance(c, torch.Tensor) and c.dtype == first.dtype and c.device == first.device
               for c in components) or not first.is_floating_point():
        check_same_dtype({f"components[{i}]": check_float(c, f"components[{i}]")
                          for i, c in enumerate(components)})
    if len(components) == 1:
        return first.abs()
    if any(c.shape != first.shape for c in components):
        check_broadcastable({f"components[{i}]": c.shape for i, c in enumerate(components)})
    if records_graph(*components):
        return _Hypot.apply(*components)
    return _hypot_value(components)  # no autograd needed: skip the Function's overhead


def safe_norm(
    x: torch.Tensor, dim: int = -1, keepdim: bool = False, eps: float | None = None
) -> torch.Tensor:
    """Euclidean norm along ``dim``, overflow-safe, with a zero (not NaN) gradient at 0.

    Vectors of up to 4 components use :func:`hypot`; longer ones are divided by
    their largest absolute component first (as ``hypot`` does), so no intermediate
    overflows or underflows. An explicit ``eps`` (legacy, absolute) returns 0 with
    a zero gradient where the norm is ``<= eps``; the default has no threshold.

    Example:
        >>> x = torch.tensor([[3.0, 4.0], [0.0, 0.0], [3e30, 4e30]], requires_grad=True)
        >>> n = safe_norm(x)
        >>> n.sum().backward()
        >>> n.detach(), x.grad
        (tensor([5.0000e+00, 0.0000e+00, 5.0000e+30]), tensor([[0.6000, 0.8000],
                [0.0000, 0.0000],
                [0.6000, 0.8000]]))
    """
    check_float(x, "x")
    size = x.shape[dim] if x.dim() > 0 else 1
    if x.dim() == 0:
        out = x.abs()
    elif size == 0:
        out = x.new_zeros(x.shape[:dim % x.dim()] + x.shape[dim % x.dim() + 1:])
    elif size <= _HYPOT_MAX:
        out = hypot(*x.unbind(dim))
    else:
        big = x.detach().abs().amax(dim=dim, keepdim=True)
        big = torch.where(big > 0, big, torch.ones_like(big))  # NaN and inf pass through
        scaled = x / big
        out = safe_sqrt((scaled * scaled).sum(dim=dim)) * big.squeeze(dim)
    if eps is not None:
        out = torch.where(out > eps, out, out * 0)
    if keepdim and x.dim() > 0:
        out = out.unsqueeze(dim)
    return out
