"""Error-free float64 arithmetic: exact signs of 2x2 determinants, double-double values.

The watertight ray-triangle test needs the *exact* sign of ``a b - c d`` for float64
operands (the 2D edge functions of the sheared corners), so that the signs of the edges
around a vertex are those of one real planar configuration. The hit parameter ``t`` of a
near-grazing ray is refined in double-double arithmetic (about 106 bits), so that it
matches the exact rational solution to the last bit of float64.

Building blocks (no FMA needed; exact without overflow or underflow, which the callers
avoid by scaling their data into ``[-1, 1]`` with a power of two):

- ``two_sum(a, b) -> (s, e)``: ``s = fl(a + b)``, ``a + b = s + e`` exactly (Knuth);
- ``two_prod(a, b) -> (p, e)``: ``p = fl(a b)``, ``a b = p + e`` exactly (Dekker, with
  Veltkamp's splitting);
- Shewchuk's ``Grow-Expansion`` (1997, Theorem 10) for the exact sign of a short sum.
"""

from __future__ import annotations

import torch

__all__: list[str] = []

_SPLITTER = 134217729.0  # 2**27 + 1: splits a float64 into two 26-bit halves
_U = 2.0**-53  # unit roundoff of float64


def two_sum(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(s, e)`` with ``s = fl(a + b)`` and ``a + b = s + e`` exactly.

    Example:
        >>> s, e = two_sum(torch.tensor([1.0], dtype=torch.float64),
        ...                torch.tensor([2.0**-60], dtype=torch.float64))
        >>> s.item() == 1.0, e.item() == 2.0**-60
        (True, True)
    """
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _split(a: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    c = _SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


def two_prod(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(p, e)`` with ``p = fl(a b)`` and ``a b = p + e`` exactly.

    Example:
        >>> x = torch.tensor([1.0 + 2.0**-30], dtype=torch.float64)
        >>> p, e = two_prod(x, x)
        >>> e.item() == 2.0**-60
        True
    """
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    return p, al * bl - (((p - ah * bh) - al * bh) - ah * bl)


def _sign_of_sum(terms: list[torch.Tensor]) -> torch.Tensor:
    """Exact sign of ``sum(terms)`` (float64): grow a nonoverlapping expansion term by term
    (Shewchuk's Grow-Expansion); its sign is that of its largest nonzero component."""
    expansion = [terms[0]]
    for b in terms[1:]:
        q, grown = b, []
        for e in expansion:
            q, h = two_sum(q, e)
            grown.append(h)
        expansion = grown + [q]
    sign = torch.zeros_like(terms[0])
    for comp in expansion:  # increasing magnitude: the last nonzero one decides
        sign = torch.where(comp != 0, torch.sign(comp), sign)
    return sign


def cross_sign(a: torch.Tensor, b: torch.Tensor, c: torch.Tensor, d: torch.Tensor
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """``(fl(a b - c d), exact sign of a b - c d)`` for float64 tensors of one shape.

    The rounded value decides where it is far from zero compared with its error bound;
    the few others are decided exactly from the error-free products.

    Example:
        >>> one = torch.tensor([1.0 + 2.0**-30], dtype=torch.float64)
        >>> lo = torch.tensor([1.0 + 2.0**-29], dtype=torch.float64)
        >>> hi = torch.tensor([1.0], dtype=torch.float64)
        >>> cross_sign(one, one, lo, hi)[1]  # (1 + 2^-30)^2 - (1 + 2^-29) = 2^-60 > 0
        tensor([1.], dtype=torch.float64)
    """
    p1, p2 = a * b, c * d
    value = p1 - p2
    sign = torch.sign(value)
    unsure = (value.abs() <= 4 * _U * (p1.abs() + p2.abs())).nonzero().squeeze(1)
    if unsure.numel():
        aa, bb, cc, dd = (x.index_select(0, unsure) for x in (a, b, c, d))
        q1, e1 = two_prod(aa, bb)
        q2, e2 = two_prod(cc, dd)
        exact = _sign_of_sum([e1, -e2, q1, -q2])
        sign = sign.index_put((unsure,), exact)
    return value, sign


# ------------------------------------------------------------------ double-double values


def dd_add(ah, al, bh, bl):
    """Double-double sum ``(ah + al) + (bh + bl)`` (the accurate QD-library variant)."""
    s, e = two_sum(ah, bh)
    t, f = two_sum(al, bl)
    s, e = two_sum(s, e + t)
    return two_sum(s, e + f)


def dd_mul(ah, al, bh, bl):
    """Double-double product ``(ah + al) (bh + bl)``."""
    p, e = two_prod(ah, bh)
    return two_sum(p, e + (ah * bl + al * bh))


def dd_dot3(a: list, b: list):
    """Double-double dot product of two 3-vectors given as lists of ``(hi, lo)`` pairs."""
    h, lo = dd_mul(*a[0], *b[0])
    for x, y in zip(a[1:], b[1:]):
        h, lo = dd_add(h, lo, *dd_mul(*x, *y))
    return h, lo


def dd_cross3(a: list, b: list) -> list:
    """Double-double cross product of two 3-vectors of ``(hi, lo)`` pairs."""
    out = []
    for i, j in ((1, 2), (2, 0), (0, 1)):
        x = dd_mul(*a[i], *b[j])
        y = dd_mul(*a[j], *b[i])
        out.append(dd_add(*x, -y[0], -y[1]))
    return out


def dd_div_to_float(nh, nl, dh, dl) -> torch.Tensor:
    """``(nh + nl) / (dh + dl)`` rounded to float64 (one Newton correction)."""
    q1 = nh / dh
    ph, pl = dd_mul(q1, torch.zeros_like(q1), dh, dl)
    rh, rl = dd_add(nh, nl, -ph, -pl)
    return q1 + rh / dh
