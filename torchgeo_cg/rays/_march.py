"""The march of :func:`~torchgeo_cg.rays.sphere_trace`, without a graph: roots of ``f`` along rays.

Three stages, each vectorised over the rays still running (one field evaluation per
stage step for all of them, never a loop over rays):

1. **March.** From ``t = 0``, step ``|f| / L`` (``L`` the Lipschitz bound): the ball of
   radius ``|f| / L`` around the point holds no root, so the step (``|f| / (L |d|)`` in
   ``t``) never crosses the
   surface. Without a bound (``L=None``) the step is over-relaxed, ``1.6 |f|`` (Keinert
   et al. 2014, "Enhanced sphere tracing"); when the balls of two successive points do
   not overlap (``step > |f_a| + |f_b|``) the step is taken again unrelaxed. A sign change
   of ``f`` between two points brackets a root; a value ``|f| <= tol |d| t_max`` ends the
   march as "near".
2. **Bracket.** From a near point, probe ``t + 2**k |f| / (L |d|)`` (``k = 1..8``) for a sign
   change; a near point without one stays a hit at its own ``t`` (the value within tol).
3. **Refine.** Illinois regula falsi (a safeguarded secant that halves the stale end's
   value; a bisection when the secant leaves the bracket) until the bracket is a few
   ulps wide or ``f = 0``.
"""

from __future__ import annotations

import torch

__all__: list[str] = []

_RELAX = 1.6
_PROBES = 8
_REFINE_STEPS = 80


def _eval(sdf, o, d, t, rows):
    """``f(o + t d)`` at the rays ``rows`` (``t`` given for those rows)."""
    p = o.index_select(0, rows) + t[:, None] * d.index_select(0, rows)
    return sdf(p).reshape(-1).to(o.dtype)


def march(sdf, o, d, valid, lipschitz, t_max: float, max_steps: int, tol: float):
    """``(t, f, state)`` per ray after stage 1: ``state`` 0 running/miss, 1 near, 2 bracket;
    ``t_b, f_b`` the far end of a bracket. Returns ``(t, f, t_b, f_b, state)``."""
    n = o.shape[0]
    t, f = o.new_zeros(n), o.new_zeros(n)
    tb, fb = o.new_zeros(n), o.new_zeros(n)
    state = torch.zeros(n, dtype=torch.long, device=o.device)
    dn = d.norm(dim=-1)
    thresh = tol * dn * t_max
    rows = valid.nonzero().squeeze(1)
    f[rows] = _eval(sdf, o, d, t[rows], rows)
    side = torch.sign(f)
    state[rows] = torch.where(f[rows].abs() <= thresh[rows], 1, 0)
    rows = rows[state[rows] == 0]
    omega = torch.full((n,), 1.0 if lipschitz is not None else _RELAX, dtype=o.dtype,
                       device=o.device)
    inv_l = 1.0 / (lipschitz if lipschitz is not None else 1.0)
    for _ in range(max_steps):
        if rows.numel() == 0:
            break
        fr, tr = f[rows], t[rows]
        step = omega[rows] * fr.abs() * inv_l / dn[rows]  # a ball of radius |f| / L
        tn = tr + step
        fn = _eval(sdf, o, d, tn, rows)
        crossed = (torch.sign(fn) != side[rows]) & ~torch.isnan(fn)
        overshoot = (omega[rows] > 1) & (step * dn[rows] > fr.abs() + fn.abs()) & ~crossed
        accept = ~overshoot
        omega[rows[overshoot]] = 1.0  # retry from the same point, unrelaxed
        tb[rows], fb[rows] = tn, fn
        state[rows] = torch.where(crossed, 2, torch.where(accept & (fn.abs() <= thresh[rows]),
                                                          1, 0))
        t[rows] = torch.where(accept & ~crossed, tn, tr)
        f[rows] = torch.where(accept & ~crossed, fn, fr)
        alive = (state[rows] == 0) & (t[rows] <= t_max) & torch.isfinite(f[rows])
        rows = rows[alive]
    return t, f, tb, fb, state, side


def bracket(sdf, o, d, t, f, tb, fb, state, side, lipschitz):
    """Stage 2, in place: near rays whose probes find a sign change become brackets (2)."""
    inv_l = 1.0 / (lipschitz if lipschitz is not None else 1.0)
    rows = (state == 1).nonzero().squeeze(1)
    rows = rows[f[rows] != 0]
    dn = d.index_select(0, rows).norm(dim=-1)
    lo_t = t[rows].clone()
    lo_f = f[rows].clone()
    for k in range(1, _PROBES + 1):
        if rows.numel() == 0:
            break
        tp = t[rows] + f[rows].abs() * (2.0**k * inv_l) / dn
        fp = _eval(sdf, o, d, tp, rows)
        crossed = (torch.sign(fp) != side[rows]) & ~torch.isnan(fp)
        hit = rows[crossed]
        t[hit], f[hit] = lo_t[crossed], lo_f[crossed]
        tb[hit], fb[hit] = tp[crossed], fp[crossed]
        state[hit] = 2
        keep = ~crossed  # the probe is on the origin's side: the bracket's new near end
        lo_t, lo_f, rows, dn = tp[keep], fp[keep], rows[keep], dn[keep]


def refine(sdf, o, d, t, f, tb, fb, state) -> None:
    """Stage 3, in place: Illinois regula falsi on every bracket ``[t, tb]``; ``t`` ends at
    the end with the smaller ``|f|``."""
    rows = (state == 2).nonzero().squeeze(1)
    a, fa, b, fbb = t[rows], f[rows], tb[rows], fb[rows]
    done_t, done_rows = [], []
    for _ in range(_REFINE_STEPS):
        if rows.numel() == 0:
            break
        denom = fbb - fa
        sec = b - fbb * (b - a) / torch.where(denom == 0, 1.0, denom)
        lo, hi = torch.minimum(a, b), torch.maximum(a, b)
        inside = (sec > lo) & (sec < hi) & (denom != 0)
        c = torch.where(inside, sec, (a + b) / 2)
        fc = _eval(sdf, o, d, c, rows)
        same = torch.sign(fc) == torch.sign(fbb)
        a, fa = torch.where(same, a, b), torch.where(same, fa / 2, fbb)  # Illinois
        b, fbb = c, fc
        width = (b - a).abs()
        conv = (fc == 0) | (width <= 4 * torch.finfo(o.dtype).eps * b.abs().clamp_min(
            torch.finfo(o.dtype).tiny)) | (c == lo) | (c == hi)
        done_rows.append(rows[conv])
        done_t.append(b[conv])
        keep = ~conv
        rows, a, fa, b, fbb = rows[keep], a[keep], fa[keep], b[keep], fbb[keep]
    done_rows.append(rows)
    done_t.append(b)
    t[torch.cat(done_rows)] = torch.cat(done_t)
