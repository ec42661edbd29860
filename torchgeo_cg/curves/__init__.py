"""Curves: Bernstein/Bezier, B-splines/NURBS, Hermite/PCHIP, parametric and implicit 2D curves, marching squares.

Report sections 1.1-1.3. Every function is batched over leading dimensions,
differentiable, and takes dtype and device from its inputs.
"""

from torchgeo_cg.curves.bernstein import bernstein_basis
from torchgeo_cg.curves.bezier import (
    BezierCurve,
    SplitResult,
    bezier,
    bezier_arclength_params,
    bezier_curvature,
    bezier_derivative,
    bezier_length,
    bezier_normal,
    bezier_tangent,
    cubic_bezier,
    de_casteljau,
    elevate_bezier,
    quartic_bezier,
    split_bezier,
)
from torchgeo_cg.curves.bspline import BSplineControls, BSplineCurve, bspline, bspline_derivative
from torchgeo_cg.curves.bspline_fitting import BSplineFit, fit_bspline, interpolate_bspline
from torchgeo_cg.curves.fitting import BezierFit, fit_bezier, fit_parameters
from torchgeo_cg.curves.hermite import (
    HermiteControls,
    HermiteCurve,
    HermiteSpline,
    PchipInterpolator,
    bezier_to_hermite,
    cardinal_tangents,
    catmull_rom_tangents,
    check_knots,
    hermite,
    hermite_basis,
    hermite_spline,
    hermite_to_bezier,
    pchip_interpolate,
    pchip_tangents,
)
from torchgeo_cg.curves.knot_ops import (
    BezierSegments,
    bezier_to_bspline,
    bspline_to_bezier,
    insert_knot,
)
from torchgeo_cg.curves.knots import BSplineBasis, bspline_basis, uniform_knots
from torchgeo_cg.curves.marching_squares import MarchingSquaresResult, marching_squares
from torchgeo_cg.curves.nurbs import NURBSCurve, nurbs, nurbs_derivative
from torchgeo_cg.curves.parametric import (
    circle,
    cycloid,
    figure_eight_implicit,
    figure_eight_parametric,
    grid_2d,
    implicit_circle,
)

__all__ = [
    "bernstein_basis",
    "BezierCurve",
    "SplitResult",
    "bezier",
    "bezier_arclength_params",
    "bezier_curvature",
    "bezier_derivative",
    "bezier_length",
    "bezier_normal",
    "bezier_tangent",
    "cubic_bezier",
    "de_casteljau",
    "elevate_bezier",
    "quartic_bezier",
    "split_bezier",
    "HermiteControls",
    "HermiteCurve",
    "HermiteSpline",
    "PchipInterpolator",
    "bezier_to_hermite",
    "cardinal_tangents",
    "catmull_rom_tangents",
    "check_knots",
    "hermite",
    "hermite_basis",
    "hermite_spline",
    "hermite_to_bezier",
    "pchip_interpolate",
    "pchip_tangents",
    "BezierFit",
    "fit_bezier",
    "fit_parameters",
    "MarchingSquaresResult",
    "marching_squares",
    "circle",
    "cycloid",
    "figure_eight_implicit",
    "figure_eight_parametric",
    "grid_2d",
    "implicit_circle",
    "BSplineBasis",
    "BSplineControls",
    "BSplineCurve",
    "BSplineFit",
    "BezierSegments",
    "NURBSCurve",
    "bezier_to_bspline",
    "bspline",
    "bspline_basis",
    "bspline_derivative",
    "bspline_to_bezier",
    "fit_bspline",
    "insert_knot",
    "interpolate_bspline",
    "nurbs",
    "nurbs_derivative",
    "uniform_knots",
]
