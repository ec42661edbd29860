"""The public surface of torchgeo_cg.curves: names never silently disappear."""

from __future__ import annotations

import torchgeo_cg.curves as curves

EXPECTED = {
    "bernstein_basis", "bezier", "cubic_bezier", "quartic_bezier", "de_casteljau",
    "BezierCurve", "fit_bezier", "hermite_basis", "hermite", "HermiteCurve", "HermiteSpline",
    "pchip_tangents", "PchipInterpolator", "catmull_rom_tangents", "cardinal_tangents",
    "hermite_to_bezier", "bezier_to_hermite", "circle", "implicit_circle", "cycloid",
    "figure_eight_implicit", "figure_eight_parametric", "marching_squares",
    "split_bezier", "elevate_bezier", "bezier_length", "bezier_derivative",
}


def test_public_names_exist_and_are_documented():
    assert EXPECTED <= set(curves.__all__)
    for name in curves.__all__:
        obj = getattr(curves, name)
        assert obj.__doc__ and len(obj.__doc__) > 40, name


def test_bezier_curve_methods():
    for method in ("forward", "derivative", "tangent", "normal", "curvature", "split",
                   "elevate", "length", "reparametrize_by_arclength"):
        assert callable(getattr(curves.BezierCurve, method))
