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

from torchgeo_cg.curves import split_bezier

#: Halvings per descent: below float64's resolution of ``[0, 1]``.
_LEVELS = 56


def _bernstein(coeffs: torch.Tensor, span: float | None) -> torch.Tensor:
    """Bernstein coefficients ``(B, n + 1)`` of ``p`` on ``[0, span]`` (``None``: ``[0, inf)``)."""
    n = coeffs.shape[-1] - 1
    binom = coeffs.new_tensor([math.comb(n, k) for k in range(n + 1)])
    if span is None:
        return coeffs / binom
    scaled = coeffs * coeffs.new_tensor([span ** k for k in range(n + 1)])
    convert = coeffs.new_tensor([[math.comb(j, k) / math.comb(n, k) if k <= j else 0.0
                                  for j in range(n + 1)] for k in range(n + 1)])
    return scaled @ convert


def _positive(control: torch.Tensor) -> torch.Tensor:
    return (control > 0).all(-2).squeeze(-1)


def _descend(control: torch.Tensor):
    """Leftmost non-positive point of each Bezier function on its ``[0, 1]``.

    Returns ``(t, hit)``: the left end of the last interval kept, and whether that
    interval still has a non-positive coefficient (else ``t`` is 1: nothing found).
    """
    lo = control.new_zeros(control.shape[0])
    width = 1.0
    for _ in range(_LEVELS):
        left, right = split_bezier(control, 0.5)
        go_right = _positive(left)
        width = 0.5 * width
        lo = torch.where(go_right, lo + width, lo)
        control = torch.where(go_right[:, None, None], right, left)
    hit = ~_positive(control)
    return torch.where(hit, lo, torch.ones_like(lo)), hit


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
    for _ in range(rounds):
        # coefficients on [start, 1]: the right part of a split at start
        piece = split_bezier(control, start).right
        t, hit = _descend(piece)
        t = start + t * (1 - start)
        start = torch.where(found, start, t)
        found = found | hit
        if bool((found | (start >= 1)).all()):
            break
    # a root in the last interval of the half-line is the leading coefficient's zero at
    # infinity (a polynomial of lower degree): no root
    end = 1 - 2.0 ** (4 - _LEVELS) if span is None else 1.0
    none = start >= end
    t = torch.where(none, torch.zeros_like(start), start)
    s = t / (1 - t) if span is None else t * span
    return torch.where(none, torch.full_like(s, math.inf), s)
