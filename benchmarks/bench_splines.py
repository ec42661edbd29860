"""B-spline curves and NURBS surfaces against scipy's BSpline and geomdl.

Targets at 1 thread (ratio ours / peer):
- evaluate 10,000 cubic 3D B-splines x 16 control points at 256 parameters, float64:
  <= 1 x scipy ``BSpline`` called once with every curve as a column of one coefficient
  array (shared knots; our result is a view of one matrix product, as scipy's is);
  <= 0.5 x scipy looped over the curves, each with its own knots (the loop is timed on a
  subset and extrapolated); <= 0.01 x geomdl (subset, extrapolated).
- a NURBS surface of 64 x 64 control points (bicubic) at 512^2 paired (u, v), with first
  derivatives: <= 0.01 x geomdl ``Surface.derivatives`` (timed on a subset of the points
  and extrapolated: geomdl is pure Python, about 100 us per point).
"""

from __future__ import annotations

import numpy as np
import torch

from benchmarks.harness import Case
from torchgeo_cg.curves import bspline, uniform_knots
from torchgeo_cg.surfaces import nurbs_surface_derivatives


def _random_knots(count, degree, rows, gen):
    inner = torch.sort(torch.rand(rows, count - degree - 1, generator=gen, dtype=torch.float64),
                       -1).values
    zeros = torch.zeros(rows, degree + 1, dtype=torch.float64)
    return torch.cat([zeros, inner, zeros + 1], -1)


def _curve_cases(quick: bool, gen) -> list[Case]:
    import geomdl
    import scipy
    from geomdl import BSpline as GeomdlBSpline
    from scipy.interpolate import BSpline

    n_curves, count, degree, n_t = (2000 if quick else 10_000), 16, 3, 256
    subset = 100 if quick else 500
    cp = torch.randn(n_curves, count, 3, generator=gen, dtype=torch.float64)
    t = torch.linspace(0, 1, n_t, dtype=torch.float64)
    knots = uniform_knots(count, degree, dtype=torch.float64)
    columns = np.ascontiguousarray(cp.permute(1, 0, 2).numpy())  # (16, B, 3)
    shared = BSpline(knots.numpy(), columns, degree)
    t_np = t.numpy()
    err = float((bspline(cp, t, degree) - torch.from_numpy(shared(t_np)).permute(1, 0, 2))
                .abs().max())
    size = f"{n_curves // 1000}k cubics x {count} cp x {n_t} t f64"
    sci = f"scipy {scipy.__version__}"
    out = [Case(f"bspline {size}, shared knots", lambda: bspline(cp, t, degree),
                lambda: shared(t_np), sci + " BSpline (curves as columns)", target=1.0,
                extra={"max_abs_err": err})]
    own = _random_knots(count, degree, n_curves, gen)
    own_np, cp_np = own.numpy(), cp.numpy()

    def scipy_loop():
        for b in range(subset):
            BSpline(own_np[b], cp_np[b], degree)(t_np)

    loop_err = max(float(np.abs(bspline(cp[b], t, degree, own[b]).numpy()
                                - BSpline(own_np[b], cp_np[b], degree)(t_np)).max())
                   for b in range(5))
    out.append(Case(f"bspline {size}, own knots per curve", lambda: bspline(cp, t, degree, own),
                    scipy_loop, sci + " BSpline loop", target=0.5,
                    peer_scale=n_curves / subset, extra={"max_abs_err": loop_err}))
    geo_subset = 10 if quick else 40
    curves = []
    for b in range(geo_subset):
        c = GeomdlBSpline.Curve()
        c.degree = degree
        c.ctrlpts = cp_np[b].tolist()
        c.knotvector = knots.tolist()
        curves.append(c)
    params = t_np.tolist()

    def geomdl_loop():
        for c in curves:
            c.evaluate_list(params)

    out.append(Case(f"bspline {size} vs geomdl", lambda: bspline(cp, t, degree), geomdl_loop,
                    f"geomdl {geomdl.__version__} loop", target=0.01,
                    peer_scale=n_curves / geo_subset))
    return out


def _surface_cases(quick: bool, gen) -> list[Case]:
    import geomdl
    from geomdl import NURBS

    side, degree = 64, 3
    res = 128 if quick else 512
    grid = torch.randn(side, side, 3, generator=gen, dtype=torch.float64)
    weights = 0.5 + torch.rand(side, side, generator=gen, dtype=torch.float64)
    x = torch.linspace(0, 1, res, dtype=torch.float64)
    u, v = (a.reshape(-1) for a in torch.meshgrid(x, x, indexing="ij"))
    surface = NURBS.Surface()
    surface.degree_u = surface.degree_v = degree
    surface.ctrlpts_size_u = surface.ctrlpts_size_v = side
    homogeneous = torch.cat([grid * weights[..., None], weights[..., None]], -1)
    surface.ctrlptsw = homogeneous.reshape(-1, 4).tolist()
    surface.knotvector_u = surface.knotvector_v = uniform_knots(side, degree,
                                                                dtype=torch.float64).tolist()
    subset = 100 if quick else 500
    pick = torch.randperm(u.shape[0], generator=gen)[:subset]
    pairs = list(zip(u[pick].tolist(), v[pick].tolist()))
    ours = nurbs_surface_derivatives(grid, weights, u[pick], v[pick], degree)
    ref = torch.tensor([surface.derivatives(a, b, 1) for a, b in pairs], dtype=torch.float64)
    err = max(float((ours.points - ref[:, 0, 0]).abs().max()),
              float((ours.du - ref[:, 1, 0]).abs().max()),
              float((ours.dv - ref[:, 0, 1]).abs().max()))

    def geomdl_loop():
        for a, b in pairs:
            surface.derivatives(a, b, 1)

    return [Case(f"nurbs_surface_derivatives {side}x{side} bicubic at {res}^2 (u, v) f64",
                 lambda: nurbs_surface_derivatives(grid, weights, u, v, degree), geomdl_loop,
                 f"geomdl {geomdl.__version__} Surface.derivatives loop", target=0.01,
                 peer_scale=u.shape[0] / subset, extra={"max_abs_err": err})]


def cases(quick: bool = False) -> list[Case]:
    gen = torch.Generator().manual_seed(0)
    return _curve_cases(quick, gen) + _surface_cases(quick, gen)
