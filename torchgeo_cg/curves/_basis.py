"""Knot spans and the local B-spline basis functions shared by the curve and surface evaluators
(Cox-de Boor, Piegl & Tiller A2.1-A2.3); internals of :mod:`torchgeo_cg.curves.knots`."""

from __future__ import annotations

import torch

from torchgeo_cg.core.autograd import records_graph

__all__ = ["find_spans", "local_basis", "local_basis_list", "span_limits"]


def find_spans(knots: torch.Tensor, t: torch.Tensor, degree: int) -> torch.Tensor:
    """Span index ``s`` in ``[p, n]`` of every parameter (right-continuous, see above)."""
    knots, t = knots.detach(), t.detach()
    low, high = span_limits(knots, degree)
    span = torch.searchsorted(knots.contiguous(), t.contiguous(), right=True) - 1
    return torch.minimum(torch.maximum(span, low), high)


def span_limits(knots: torch.Tensor, degree: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The first and last non-empty spans ``(*, 1)`` of the domain, in ``[p, n]``.

    The lowest ``s`` with ``u_s <= u_p`` and the highest with ``u_{s+1} >= u_{n+1}``:
    parameters outside the domain use them (extrapolation). The clamp to ``[p, n]`` only
    acts for NaN knots (a NaN stroke of a fit): indices stay valid.

    Example:
        >>> span_limits(torch.tensor([0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 2.0]), 2)
        (tensor([2]), tensor([4]))
    """
    knots = knots.detach()
    last = knots.shape[-1] - degree - 2  # n
    seq = knots.contiguous()
    low = torch.searchsorted(seq, knots[..., degree:degree + 1].contiguous(), right=True) - 1
    high = torch.searchsorted(seq, knots[..., last + 1:last + 2].contiguous(), right=False) - 1
    return low.clamp(degree, last), high.clamp(degree, last)


def local_basis(knots, t, spans, degree: int, order: int) -> torch.Tensor:
    """Local basis values ``(order + 1, *, T, p + 1)`` on given spans (no validation)."""
    levels = local_basis_list(knots, t, spans, degree, order)
    return torch.stack([torch.stack(level, -1) for level in levels])


def local_basis_list(knots, t, spans, degree: int, order: int) -> list[list[torch.Tensor]]:
    """:func:`local_basis` as ``order + 1`` lists of ``p + 1`` tensors ``(*, T)``.

    The scalar form of algorithm A2.2 on whole tensors: ``p (p + 1) / 2`` steps of a few
    elementwise operations, with no stacking or padding of ``(*, T, j)`` intermediates.
    """
    left = [t - _gather1(knots, spans - (j - 1)) for j in range(1, degree + 1)]  # t - u_{s+1-j}
    right = [_gather1(knots, spans + j) - t for j in range(1, degree + 1)]  # u_{s+j} - t
    levels = [[torch.ones_like(t)]]  # degree 0: N_{s,0} = 1
    for j in range(1, degree + 1):  # loop over degrees
        previous, new, saved = levels[-1], [], None
        for r in range(j):  # in-place steps where autograd allows: fewer fresh buffers
            temp = right[r] + left[j - r - 1]  # u_{s+r+1} - u_{s+1-j+r} > 0
            temp = previous[r] / temp
            term = right[r] * temp
            new.append(term if saved is None else term.add_(saved))
            saved = temp.mul_(left[j - r - 1]) if _inplace(t, knots) else temp * left[j - r - 1]
        new.append(saved)
        levels.append(new)
    out = [levels[degree]]
    for k in range(1, order + 1):  # loop over derivative orders
        if k > degree:
            out.append([torch.zeros_like(t)] * (degree + 1))
            continue
        values = levels[degree - k]
        for d in range(degree - k + 1, degree + 1):  # raise degree d - 1 -> d (eq. 2.9)
            values = _raise(knots, spans, values, d, d == degree)
        out.append(values)
    return out


def _inplace(*tensors: torch.Tensor) -> bool:
    """In-place arithmetic is safe: nothing here needs the intermediates for a gradient."""
    return not records_graph(*tensors)


def _gather1(knots: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    if knots.dim() == 1:
        return knots.index_select(0, index.reshape(-1)).view(index.shape)
    return knots.gather(-1, index)


def _raise(knots, spans, values, d: int, top: bool) -> list[torch.Tensor]:
    """``d (N_{i,d-1} / (u_{i+d} - u_i) - N_{i+1,d-1} / (u_{i+d+1} - u_{i+1}))`` locally."""
    scaled = []
    for j in range(d):  # in-index j is i' = s - d + 1 + j
        gap = _gather1(knots, spans + 1 + j) - _gather1(knots, spans - d + 1 + j)
        if top:  # d = p: the gap contains the span, which is never empty: positive
            scaled.append(values[j] / gap * d)
            continue
        scaled.append(torch.where(gap > 0, values[j] / torch.where(gap > 0, gap, 1.0), 0.0) * d)
    return [-scaled[0]] + [scaled[j - 1] - scaled[j] for j in range(1, d)] + [scaled[-1]]
