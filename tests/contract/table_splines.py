"""Contract entries of B-spline and NURBS curves: evaluation, knot operations, fits.

``ENTRIES`` join ``table.TABLE``;
``EXEMPT`` names have no geometry (result types, validators, knot factories).
"""

from __future__ import annotations

import torch

import torchgeo_cg.curves as C
from tests.contract.spec import Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]


def _sorted(shape, g, dtype):
    """Increasing knots (distinct, unclamped) in ``[0, 1]``."""
    return torch.sort(torch.rand(shape, generator=g, dtype=torch.float64), -1).values


def _weights(shape, g, dtype):
    return 0.5 + torch.rand(shape, generator=g, dtype=torch.float64)


CP = Arg("control_points", (3, 6, 2))
T = Arg("t", (7,), "t01", "unitless")
KNOTS = Arg("knots", (10,), _sorted, "unitless")  # 6 points, degree 3
W = Arg("weights", (3, 6), _weights, "unitless")
BAD = ((3,), (3, 2, 2))
CURVE = dict(empty=(1, -1), mixed="promote", low="reject", bad=BAD)
CONTROLS = ("length", "unitless")
STROKES = Arg("points", (2, 12, 2))
FIT = ("length", "unitless", "unitless", "length")

ENTRIES: list[Entry] = [
    Entry("curves.bspline", lambda cp, t: C.bspline(cp, t, 3), (CP, T), **CURVE),
    Entry("curves.bspline[knots]", lambda cp, t, k: C.bspline(cp, t, 3, k), (CP, T, KNOTS),
          **CURVE),
    Entry("curves.bspline[periodic]", lambda cp, t: C.bspline(cp, t, 3, periodic=True),
          (CP, T), empty=(1, -1), mixed="promote", low="reject", bad=((3,),)),
    Entry("curves.bspline_derivative", lambda cp, t, k: C.bspline_derivative(cp, t, 3, 2, k),
          (CP, T, KNOTS), **CURVE),
    Entry("curves.bspline_basis", lambda t: C.bspline_basis(t, 3, order=1).values,
          (Arg("t", (3, 7), "t01", "unitless"),), out="unitless", empty=(0, -1), low="reject",
          bad=((),)),
    Entry("curves.BSplineCurve", lambda cp, t: C.BSplineCurve(cp, 3)(t), (CP, T),
          **{**CURVE, "mixed": "raise"}),  # a module: its state and t share one dtype
    Entry("curves.nurbs", lambda cp, w, t: C.nurbs(cp, w, t, 3), (CP, W, T), empty=(2, -1),
          mixed="promote", low="reject", bad=((3,),)),
    Entry("curves.nurbs_derivative",
          lambda cp, w, t, k: C.nurbs_derivative(cp, w, t, 3, 2, k), (CP, W, T, KNOTS),
          empty=(2, -1), mixed="promote", low="reject", bad=((3,),), rtol=1e-8),
    Entry("curves.NURBSCurve", lambda cp, w, t: C.NURBSCurve(cp, w, 3)(t), (CP, W, T),
          empty=(2, -1), mixed="promote", low="reject", bad=((3,),)),
    Entry("curves.insert_knot", lambda cp, k: C.insert_knot(cp, 0.5 * (k[3] + k[6]), 3, k, times=2),
          (CP, KNOTS), out=CONTROLS, empty=(0, 0), mixed="promote", low="reject", bad=BAD,
          cross="the call takes the new knot from one knot vector (k[3], k[6])"),
    Entry("curves.bspline_to_bezier", lambda cp, k: C.bspline_to_bezier(cp, 3, k),
          (CP, KNOTS), out=("length", "unitless", "unitless"), empty=(0, 0), mixed="promote",
          low="reject", bad=BAD),
    Entry("curves.bezier_to_bspline", C.bezier_to_bspline,
          (Arg("control_points", (3, 4, 3, 2)), Arg("breaks", (5,), _sorted, "unitless")),
          out=CONTROLS, empty=(0, 0), mixed="promote", low="reject", bad=((3, 2),)),
    Entry("curves.interpolate_bspline", lambda p, x: C.interpolate_bspline(x, p, 3),
          (Arg("points", (3, 8, 2)), Arg("x", (8,), "increasing", "unitless")), out=CONTROLS,
          empty=(0, 0), mixed="promote", low="reject", bad=((3, 7, 2),), rtol=1e-8),
    Entry("curves.fit_bspline", lambda p: C.fit_bspline(p, 3, 6), (STROKES,), out=FIT,
          empty=(0, 0), mixed=None, low="reject", bad=((12,),), rtol=1e-8),
    Entry("curves.fit_bspline[periodic]", lambda p: C.fit_bspline(p, 3, 6, periodic=True),
          (STROKES,), out=FIT, empty=(0, 0), mixed=None, low="reject", bad=((12,),),
          rtol=1e-8),
    Entry("curves.averaged_knots", lambda t: C.averaged_knots(t, 5, 3),
          (Arg("t", (2, 9), _sorted, "unitless"),), out="unitless", empty=(0, 0),
          low="reject", mixed=None, bad=()),
    Entry("curves.collocation_matrix", lambda t, k: C.collocation_matrix(t, 3, k),
          (Arg("t", (2, 9), "t01", "unitless"), KNOTS), out="unitless", empty=(0, -1),
          low="reject", mixed="promote", bad=((),)),
]

EXEMPT: dict[str, str] = {
    "curves.BSplineBasis": "NamedTuple result type",
    "curves.BSplineControls": "NamedTuple result type",
    "curves.BSplineFit": "NamedTuple result type",
    "curves.BezierSegments": "NamedTuple result type",
    "curves.uniform_knots": "factory of numbers (counts, degree), no tensor input; tests/curves",
}
