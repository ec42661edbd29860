"""Curves against scipy BPoly / PchipInterpolator and the `bezier` package.

Targets at 1 thread (ratio ours / peer):
- evaluate 100k cubic 2D curves at 64 parameters: <= 0.6 x scipy BPoly (curves as
  trailing dims), <= 0.05 x a loop over the `bezier` package (subset, extrapolated);
  forward+backward reported.
- split + elevate 100k cubics: <= 0.02 x the `bezier` package (subset, extrapolated).
- PCHIP, 10k series x 256 knots -> 1024 queries, float64: <= 0.8 x scipy, within 1e-12.
- arc length of 10k random cubics (10% near-cusp): <= 0.2 x `bezier` Curve.length
  (subset, extrapolated), at <= 1e-6 relative error (checked against scipy quad).

Note on the large outputs (100 MB for the evaluation, 80 MB for PCHIP): numpy
madvises huge pages for big arrays, PyTorch's CPU allocator does not unless
``THP_MEM_ALLOC_ENABLE=1`` is set before the first allocation, so our side pays
4 KiB page faults on every fresh output. That environment variable is process
wide, so this file does not set it; BENCHMARKS.md reports both numbers.
"""

from __future__ import annotations

import numpy as np
import torch

from benchmarks.harness import Case
from torchgeo_cg.curves import (
    PchipInterpolator,
    bezier_derivative,
    bezier_length,
    cubic_bezier,
    elevate_bezier,
    split_bezier,
)


def _near_cusp(count: int, gen: torch.Generator) -> torch.Tensor:
    """Symmetric cubics (0,0),(1+e,h),(-e,h),(1,0): exact cusp at e = 0."""
    e = (torch.rand(count, generator=gen, dtype=torch.float64) - 0.5) * 2e-3
    h = 0.5 + torch.rand(count, generator=gen, dtype=torch.float64)
    zero, one = torch.zeros_like(e), torch.ones_like(e)
    return torch.stack([torch.stack([zero, zero], -1), torch.stack([1 + e, h], -1),
                        torch.stack([-e, h], -1), torch.stack([one, zero], -1)], dim=-2)


def _quad_length(cp: np.ndarray) -> float:
    from scipy import integrate
    from scipy.interpolate import BPoly

    hodo = BPoly(bezier_derivative(torch.from_numpy(cp)).numpy()[:, None, :], [0.0, 1.0])
    return integrate.quad(lambda s: float(np.linalg.norm(hodo(s))), 0, 1, epsabs=1e-14,
                          epsrel=1e-13, limit=500)[0]


def cases(quick: bool = False) -> list[Case]:
    import bezier as bezier_pkg
    import scipy
    from scipy.interpolate import BPoly
    from scipy.interpolate import PchipInterpolator as ScipyPchip

    gen = torch.Generator().manual_seed(0)
    out: list[Case] = []
    bez = f"bezier {bezier_pkg.__version__} loop"
    sci = f"scipy {scipy.__version__}"

    # --- evaluation -----------------------------------------------------------------
    n_curves = 10_000 if quick else 100_000
    subset = 200 if quick else 1000
    cp = torch.randn(n_curves, 4, 2, generator=gen, dtype=torch.float64)
    t = torch.linspace(0, 1, 64, dtype=torch.float64)
    t_np = t.numpy()
    coeffs = np.ascontiguousarray(cp.permute(1, 0, 2).reshape(4, 1, -1).numpy())  # (4, 1, 2N)
    bpoly = BPoly(coeffs, [0.0, 1.0])
    ref = torch.from_numpy(bpoly(t_np)).reshape(64, n_curves, 2).permute(1, 0, 2)
    err = float((cubic_bezier(cp, t) - ref).abs().max())
    size = f"{n_curves // 1000}k cubics x 64 t"
    out.append(Case(f"cubic_bezier {size} f64 vs BPoly", lambda: cubic_bezier(cp, t),
                    lambda: bpoly(t_np), sci + " BPoly", target=0.6,
                    extra={"max_abs_err": err}))
    cp32, t32 = cp.float(), t.float()
    out.append(Case(f"cubic_bezier {size} f32 vs BPoly f64", lambda: cubic_bezier(cp32, t32),
                    lambda: bpoly(t_np), sci + " BPoly"))
    nodes = [np.asfortranarray(c.numpy().T) for c in cp[:subset]]
    curves = [bezier_pkg.Curve(n, degree=3) for n in nodes]

    def pkg_eval():
        for c in curves:
            c.evaluate_multi(t_np)

    out.append(Case(f"cubic_bezier {size} f64 vs bezier pkg", lambda: cubic_bezier(cp, t),
                    pkg_eval, bez, target=0.05, peer_scale=n_curves / subset))
    cp_g = cp.clone().requires_grad_(True)

    def ours_fb():
        cp_g.grad = None
        cubic_bezier(cp_g, t).sum().backward()

    out.append(Case(f"cubic_bezier {size} f64 fwd+bwd", ours_fb))

    # --- split + elevate ------------------------------------------------------------
    def ours_split_elevate():
        split_bezier(cp, 0.5)
        elevate_bezier(cp)

    def pkg_split_elevate():
        for c in curves:
            c.subdivide()
            c.elevate()

    out.append(Case(f"split(0.5)+elevate {n_curves // 1000}k cubics f64", ours_split_elevate,
                    pkg_split_elevate, bez, target=0.02, peer_scale=n_curves / subset))

    # --- PCHIP ----------------------------------------------------------------------
    series, knots, queries = (1000, 256, 1024) if quick else (10_000, 256, 1024)
    rng = np.random.default_rng(0)
    x = np.sort(rng.random(knots)) + np.arange(knots) * 1e-4
    y = rng.standard_normal((series, knots)).cumsum(1)
    xq = np.sort(rng.uniform(x[0], x[-1], queries))
    X, Y, XQ = (torch.from_numpy(a) for a in (x, y, xq))
    ref = ScipyPchip(x, y, axis=1)(xq)
    err = float(np.abs(PchipInterpolator(X, Y)(XQ).numpy() - ref).max())
    out.append(Case(f"PCHIP {series // 1000}k x {knots} knots -> {queries} f64 (build+eval)",
                    lambda: PchipInterpolator(X, Y)(XQ),
                    lambda: ScipyPchip(x, y, axis=1)(xq), sci + " PchipInterpolator",
                    target=0.8, extra={"max_abs_err": err}))

    # --- arc length -----------------------------------------------------------------
    n_len = 1000 if quick else 10_000
    n_cusp = n_len // 10
    lengths_cp = torch.cat([torch.randn(n_len - n_cusp, 4, 2, generator=gen, dtype=torch.float64),
                            _near_cusp(n_cusp, gen)])
    lengths_cp = lengths_cp[torch.randperm(n_len, generator=gen)]
    check = torch.cat([lengths_cp[:40], _near_cusp(10, gen)])
    quad = np.array([_quad_length(c.numpy()) for c in check])
    ours64 = bezier_length(check).numpy()
    ours32 = bezier_length(check.float()).double().numpy()
    len_subset = 200 if quick else 1000
    len_curves = [bezier_pkg.Curve(np.asfortranarray(c.numpy().T), degree=3)
                  for c in lengths_cp[:len_subset]]
    pkg = np.array([c.length for c in len_curves[:50]])
    ours_sub = bezier_length(lengths_cp[:50]).numpy()

    def pkg_length():
        for c in len_curves:
            _ = c.length

    out.append(Case(
        f"bezier_length {n_len // 1000}k cubics (10% near-cusp) f64", lambda: bezier_length(
            lengths_cp), pkg_length, bez + " Curve.length", target=0.2,
        peer_scale=n_len / len_subset,
        extra={"max_rel_err_f64_vs_quad": float(np.abs(ours64 / quad - 1).max()),
               "max_rel_err_f32_vs_quad": float(np.abs(ours32 / quad - 1).max()),
               "max_rel_diff_vs_bezier_pkg": float(np.abs(ours_sub / pkg - 1).max())}))
    lengths32 = lengths_cp.float()
    out.append(Case(f"bezier_length {n_len // 1000}k cubics (10% near-cusp) f32",
                    lambda: bezier_length(lengths32), pkg_length, bez + " Curve.length",
                    target=0.2, peer_scale=n_len / len_subset))
    return out
