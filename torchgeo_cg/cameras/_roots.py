"""The first positive root of a polynomial, isolated in the Bernstein basis.

A lens's radial map is invertible on ``[0, r*)``, where ``r*`` is the first positive
root of its derivative (or of its denominator). Newton alone cannot find ``r*``
reliably; the Bernstein form can. The polynomial ``p(s) = sum_k a_k s^k`` (``p(0) > 0``)
is written on ``t`` in ``[0, 1]``:

- a finite span ``[0, S]``: ``s = S t``, then the power-to-Bernstein conversion
  ``b_j = sum_{k <= j} C(j, k) / C(n, k) a_k S^k``;
- the half-line ``[0, inf)``: ``s = t / (1 - t)``, and ``(1 - t)^n p(s) =
  sum_k a_k t^k (1 - t)^(n - k)``, so ``b_k = a_k / C(n, k)`` exactly.

An interval whose Bernstein coefficients are all positive holds no root (the
polynomial is a convex combination of them). The search descends by de Casteljau
halving (:func:`torchgeo_cg.curves.split_bezier`): it keeps the left half unless that
half is certified positive. It ends at the leftmost non-positive point, or, if the
whole interval was positive after all, restarts from the interval's end. Every
polynomial of a batch is searched at once; the loop runs over levels, never over items.
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.curves import bernstein_basis, elevate_bezier, split_bezier

#: Halvings per descent: below float64's resolution of ``[0, 1]``.
_LEVELS = 56


def _bernstein(coeffs: torch.Tensor, span: float | None) -> torch.Tensor:
    """Bernstein coefficients ``(B, n + 1)`` of ``p`` on ``[0, span]`` (``None``: ``[0, inf)``).

    On the half-line each polynomial is written in its own degree ``d`` (trailing zero
    coefficients dropped), so its value at infinity has the sign of its leading
    coefficient, then elevated to ``n`` (:func:`torchgeo_cg.curves.elevate_bezier`).
    """
    n = coeffs.shape[-1] - 1
    if span is None:
        nonzero = coeffs != 0
        index = torch.arange(n + 1, device=coeffs.device)
        degree = torch.where(nonzero, index, 0).amax(-1)
        out = torch.zeros_like(coeffs)
        for d in range(n + 1):
            binom = coeffs.new_tensor([math.comb(d, k) for k in range(d + 1)])
            own = (coeffs[:, : d + 1] / binom)[..., None]
            own = elevate_bezier(own, n - d)[..., 0] if d < n else own[..., 0]
            out = torch.where((degree == d)[:, None], own, out)
        return out
    scaled = coeffs * coeffs.new_tensor([span ** k for k in range(n + 1)])
    convert = coeffs.new_tensor([[math.comb(j, k) / math.comb(n, k) if k <= j else 0.0
                                  for j in range(n + 1)] for k in range(n + 1)])
    return scaled @ convert


def _positive(control: torch.Tensor) -> torch.Tensor:
    return (control > 0).all(-2).squeeze(-1)


def _variations(control: torch.Tensor) -> torch.Tensor:
    """Sign changes of the coefficients (zeros counted as negative): an upper bound on the
    roots inside, exact when it is 0 or 1."""
    sign = control.squeeze(-1) > 0
    return (sign[..., 1:] != sign[..., :-1]).sum(-1)


def _descend(control: torch.Tensor):
    """Isolate the leftmost non-positive point of each Bezier function on ``[0, 1]``.

    Keeps the left half unless it is certified positive; stops once the kept interval
    has exactly one sign change (one root inside: isolated), or is certified positive
    (the uncertain half held no root after all). Returns ``(lo, hi, hit, control)``: the
    interval kept, whether it holds a non-positive point, and its coefficients; where
    nothing was hit, ``hi`` is where the search may resume.
    """
    lo = control.new_zeros(control.shape[0])
    width = torch.ones_like(lo)
    stop = ((_variations(control) == 1) & (control[:, -1, 0] <= 0)) | _positive(control)
    for _ in range(_LEVELS):
        if bool(stop.all()):
            break
        left, right = split_bezier(control, 0.5)
        go_right = _positive(left)
        half = 0.5 * width
        lo = torch.where(stop, lo, torch.where(go_right, lo + half, lo))
        width = torch.where(stop, width, half)
        chosen = torch.where(go_right[:, None, None], right, left)
        control = torch.where(stop[:, None, None], control, chosen)
        stop = stop | ((_variations(control) == 1) & (control[:, -1, 0] <= 0)) \
            | _positive(control)
    return lo, lo + width, ~_positive(control), control


def _polish(lo: torch.Tensor, hi: torch.Tensor, piece: torch.Tensor) -> torch.Tensor:
    """The root in ``[lo, hi]`` (of the piece's ``[0, 1]``) by bracketed Newton/bisection on
    the Bernstein form: ``q(lo) > 0 >= q(hi)``."""
    n = piece.shape[-2] - 1
    coef = piece[..., 0]  # (B, n + 1)
    diff = n * (coef[:, 1:] - coef[:, :-1])  # the derivative's Bernstein coefficients
    eps = torch.finfo(lo.dtype).eps
    t = 0.5 * (lo + hi)
    for _ in range(100):
        value = (bernstein_basis(t[:, None], n)[:, 0] * coef).sum(-1)
        slope = (bernstein_basis(t[:, None], n - 1)[:, 0] * diff).sum(-1) if n else 0 * t
        lo = torch.where(value > 0, t, lo)
        hi = torch.where(value <= 0, t, hi)
        newton = t - value / torch.where(slope != 0, slope, torch.ones_like(slope))
        inside = (slope != 0) & (newton > lo) & (newton < hi)
        t = torch.where(inside, newton, 0.5 * (lo + hi))
        if bool((hi - lo <= 4 * eps * hi).all()):
            break
    return hi


def first_root(coeffs: torch.Tensor, span: float | None, rounds: int = 8) -> torch.Tensor:
    """The smallest ``s`` in ``(0, span)`` where ``p(s) <= 0``; ``inf`` where there is none.

    Args:
        coeffs: ``(B, n + 1)`` float64 power coefficients ``a_0..a_n`` with ``a_0 > 0``.
        span: the end of the search interval, or ``None`` for ``[0, inf)``.
        rounds: restarts after a descent into a positive region; a search still
            unresolved after them stops at its current start (a conservative root).

    Returns:
        ``(B,)`` float64 roots (``inf`` where ``p > 0`` on the whole span).
    """
    control = _bernstein(coeffs, span)[..., None]  # (B, n + 1, 1)
    start = coeffs.new_zeros(coeffs.shape[0])
    found = torch.zeros_like(start, dtype=torch.bool)
    lo_at, hi_at, start_at = torch.ones_like(start), torch.ones_like(start), start.clone()
    pieces = control
    for _ in range(rounds):
        # coefficients on [start, 1]: the right part of a split at start
        piece = split_bezier(control, start).right
        lo, hi, hit, _ = _descend(piece)
        new = hit & ~found
        pieces = torch.where(new[:, None, None], piece, pieces)
        lo_at, hi_at = torch.where(new, lo, lo_at), torch.where(new, hi, hi_at)
        start_at = torch.where(new, start, start_at)
        start = torch.where(found | hit, start, start + hi * (1 - start))
        found = found | hit
        if bool((found | (start >= 1)).all()):
            break
    root = _polish(lo_at, hi_at, pieces)
    t = torch.where(found, start_at + root * (1 - start_at), start)
    none = t >= 1
    t = torch.where(none, torch.zeros_like(t), t)
    s = t / (1 - t) if span is None else t * span
    return torch.where(none, torch.full_like(s, math.inf), s)
