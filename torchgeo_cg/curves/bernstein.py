"""The Bernstein basis ``C(n, k) t^k (1 - t)^(n - k)``, stable to degree 1000 and beyond.

``b_{k,n}(t) = C(n, k) t^k (1 - t)^(n - k)``, ``k = 0..n``.

The binomial coefficient overflows float32 from about degree 130 (``C(130, 65)``
is about ``9.5e37``), and ``t^k`` underflows long before the product does, so the
closed form is useless at high degree. We build the basis instead by the
de Casteljau recurrence, one degree per step:

``b_{k,n}(t) = (1 - t) b_{k,n-1}(t) + t b_{k-1,n-1}(t)``, with ``b_{0,0} = 1``.

Every step is a convex combination for ``t`` in ``[0, 1]``, so each value stays in
``[0, 1]``, the basis sums to one up to rounding, and nothing can overflow or
become NaN, forward or backward, at any degree. The loop runs over degrees, never
over elements.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from torchgeo_cg.core.check import check_float, check_shape

__all__ = ["bernstein_basis", "check_degree"]


def check_degree(degree: object, name: str = "degree") -> int:
    """``degree`` as a non-negative int, or ``TypeError``/``ValueError`` naming ``name``.

    Example:
        >>> check_degree(-1, "order")
        Traceback (most recent call last):
        ...
        ValueError: order: expected a non-negative degree, got -1
    """
    if isinstance(degree, bool) or not isinstance(degree, int):
        raise TypeError(f"{name}: expected an int, got {type(degree).__name__}")
    if degree < 0:
        raise ValueError(f"{name}: expected a non-negative degree, got {degree}")
    return degree




def bernstein_basis(t: torch.Tensor, degree: int) -> torch.Tensor:
    """All ``degree + 1`` Bernstein polynomials of one degree at parameters ``t``.

    Convention:
        ``t`` in ``[0, 1]`` spans the curve; values outside are allowed and give the
        polynomial extrapolation (no clamping; the basis then leaves ``[0, 1]`` and
        can grow like ``|t|^degree``). Column ``k`` of the result is ``b_{k,n}``.

    Args:
        t: ``(*, T)`` float parameters.
        degree: ``n >= 0``.

    Returns:
        ``(*, T, n + 1)`` basis values; dtype and device of ``t``. Differentiable
        with respect to ``t``; finite for every finite ``t`` in ``[0, 1]`` at any
        degree (tested to degree 1000 in float32 and float64).

    Raises:
        TypeError: ``t`` is not a float tensor or ``degree`` is not an int.
        ValueError: ``degree`` is negative.

    Example:
        >>> bernstein_basis(torch.tensor([0.0, 0.5, 1.0]), 3)
        tensor([[1.0000, 0.0000, 0.0000, 0.0000],
                [0.1250, 0.3750, 0.3750, 0.1250],
                [0.0000, 0.0000, 0.0000, 1.0000]])
        >>> b = bernstein_basis(torch.rand(5), 1000)
        >>> bool(b.isfinite().all()), round(float(b.sum(-1).mean()), 4)
        (True, 1.0)
    """
    check_float(t, "t", low_precision=False)
    check_shape(t, ["*", "T"], "t")
    degree = check_degree(degree)
    t_col = t.unsqueeze(-1)  # (*, T, 1)
    one_minus_t = 1 - t_col
    basis = torch.ones_like(t_col)  # (*, T, 1): b_{0,0}
    for _ in range(degree):
        # b_{k,n} = (1 - t) b_{k,n-1} + t b_{k-1,n-1}; pad puts zeros at k = n and k = -1.
        basis = F.pad(basis * one_minus_t, (0, 1)) + F.pad(basis * t_col, (1, 0))
    return basis
