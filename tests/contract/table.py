"""The API contract as data: every public callable, a generator of valid inputs and its scaling law.

This module holds the entries of the numeric core (core, homogeneous transforms,
curves, SDF primitives, operators and grids) and gathers the areas' tables
(``table_<area>.py``: ``ENTRIES`` and ``EXEMPT`` each) into :data:`TABLE` and
:data:`EXEMPT`. The vocabulary (``Arg``, ``Entry``, laws,
generators) is in ``spec.py``.

Public callables not in the table are in :data:`EXEMPT` (result types, exceptions,
validators and figures: no geometry). The completeness test fails for any public
callable in neither.
"""

from __future__ import annotations

import torch

import torchgeo_cg.core as core
import torchgeo_cg.curves as C
import torchgeo_cg.sdf as S
import torchgeo_cg.transforms as T
from tests.contract import (
    table_cameras,
    table_engine,
    table_estimation,
    table_fitting,
    table_limit,
    table_meshes,
    table_points3d,
    table_queries,
    table_rays,
    table_rotations,
    table_sparse_mc,
    table_splines,
    table_subdivision,
    table_surfaces,
)
from tests.contract.spec import LAWS, Arg, Entry, apply_law, generate
from torchgeo_cg.curves.bernstein import bernstein_basis

__all__ = ["Arg", "Entry", "TABLE", "EXEMPT", "LAWS", "apply_law", "generate"]

AREAS = (table_cameras, table_engine, table_estimation, table_fitting, table_meshes,
         table_points3d,
         table_queries, table_subdivision, table_rotations, table_limit, table_splines,
         table_surfaces, table_sparse_mc, table_rays)

# ----------------------------------------------------------------------------- helpers


def _module_dtype(x: torch.Tensor) -> dict:
    return {"dtype": x.dtype, "device": x.device}


def _on_x(r: torch.Tensor) -> torch.Tensor:
    """The point ``(r, 0, 0)`` for each ``r`` (batched like ``r``)."""
    return torch.stack([r, torch.zeros_like(r), torch.zeros_like(r)], -1)


def _sample_grid(bounds: torch.Tensor):
    lo, hi = bounds[0], bounds[-1]
    return S.sample_grid(lambda p: S.sphere(p, 0.3 * (hi - lo).amin(), 0.5 * (lo + hi)), 5,
                         bounds)


def _level_set(values, origin, spacing, tol):
    return S.zero_level_set(values, origin, spacing, tol=float(tol))


def _spline_module(cls):
    def call(knots, values, tangents, x):
        return cls(knots, values, tangents)(x)

    return call


PTS3 = Arg("points", (2, 6, 3))
PTS2 = Arg("points", (2, 6, 2))
BAD3 = ((2, 6, 5), (3,))
BAD2 = ((2, 6, 3), (2,))
CTRL = Arg("control_points", (3, 4, 2))
T_ = Arg("t", (7,), "t01", "unitless")
BADCTRL = ((3,),)
EMPTY2 = ((0, -1), (1, -1))
EMPTY3 = ((0, -1), (1, -1), (2, -1))
EMPTY4 = ((0, 0), (1, 0), (2, 0), (3, 0))

# ----------------------------------------------------------------------------- the table

CORE_TABLE: list[Entry] = [
    # --- core numerics
    Entry("core.hypot", lambda a, b, c: core.hypot(a, b, c),
          (Arg("components[0]", (5,)), Arg("components[1]", (5,)), Arg("components[2]", (5,))),
          empty=EMPTY3),
    Entry("core.safe_norm", core.safe_norm, (Arg("x", (4, 3)),), empty=(0, 0)),
    Entry("core.safe_norm[long]", core.safe_norm, (Arg("x", (4, 9)),), empty=(0, 0)),
    Entry("core.safe_div", core.safe_div, (Arg("num", (5,)), Arg("den", (5,), "positive")),
          out="unitless", empty=EMPTY2, mixed="promote"),
    Entry("core.safe_sqrt", core.safe_sqrt, (Arg("x", (5,), "positive", "area"),),
          empty=(0, -1)),
    Entry("core.clamp_away_from_zero", core.clamp_away_from_zero, (Arg("x", (5,), "positive"),),
          empty=(0, -1)),
    # --- transforms: homogeneous
    Entry("transforms.translation", T.translation, (Arg("offset", (4, 2)),), out="matrix",
          empty=(0, 0), bad=((4, 4), ())),
    Entry("transforms.rotation", T.rotation, (Arg("angle", (4,), "angle", "unitless"),),
          out="matrix", empty=(0, 0)),
    Entry("transforms.scaling", T.scaling, (Arg("factor", (4,), "positive", "unitless"),),
          out="matrix", empty=(0, 0)),
    Entry("transforms.scaling[per_axis]", lambda f: T.scaling(f, per_axis=True),
          (Arg("factor", (4, 2), "positive", "unitless"),), out="matrix", empty=(0, 0),
          bad=((4, 3),)),
    Entry("transforms.scale_x", T.scale_x, (Arg("factor", (4,), "positive", "unitless"),),
          out="matrix", empty=(0, 0)),
    Entry("transforms.scale_y", T.scale_y, (Arg("factor", (4,), "positive", "unitless"),),
          out="matrix", empty=(0, 0)),
    Entry("transforms.shear", T.shear, (Arg("a", (4,), "normal", "unitless"),
                                        Arg("b", (4,), "normal", "unitless")),
          out="matrix", empty=((0, 0), (1, 0))),
    Entry("transforms.homography", T.homography, (Arg("h", (4, 8), "normal", "h8"),),
          out="matrix", empty=(0, 0), bad=((4, 9), ())),
    Entry("transforms.compose", T.compose, (Arg("matrices[0]", (4, 3, 3), "homography", "matrix"),
                                            Arg("matrices[1]", (4, 3, 3), "homography",
                                                "matrix")),
          out="matrix", empty=((0, 0), (1, 0)), bad=((4, 3, 2), (3,))),
    Entry("transforms.compose_trs", T.compose_trs,
          (Arg("offset", (4, 2)), Arg("angle", (4,), "angle", "unitless"),
           Arg("scale", (4,), "positive", "unitless")),
          out="matrix", empty=None, bad=((4, 3), ())),
    Entry("transforms.transform_points", lambda p, m: T.transform_points(m, p),
          (Arg("points", (4, 6, 2)), Arg("matrix", (4, 3, 3), "homography", "matrix")),
          bad=((4, 6, 3), (2,))),
    Entry("transforms.transform_points[projective]", lambda p, m: T.transform_points(m, p),
          (Arg("points", (4, 6, 2), "normal", "unitless"),
           Arg("matrix", (4, 3, 3), "homography", "length")),
          out="unitless", bad=((4, 6, 3), (2,))),  # M and s M are the same transform
    Entry("transforms.inverse[magnitude]", T.inverse,
          (Arg("matrix", (4, 3, 3), "homography", "length"),), out="inv_length", empty=(0, 0),
          bad=((4, 3, 2), (3,))),  # inverse(s M) = inverse(M) / s: no absolute det test
    Entry("transforms.inverse", T.inverse, (Arg("matrix", (4, 3, 3), "homography", "matrix"),),
          out="matrix", empty=(0, 0), bad=((4, 3, 2), (3,))),
    Entry("transforms.decompose_affine", T.decompose_affine,
          (Arg("matrix", (4, 3, 3), "affine", "matrix"),),
          out=("length", "unitless", "unitless", "unitless"), empty=(0, 0),
          bad=((4, 2, 3), (3,))),
    Entry("transforms.TRSTransform",
          lambda p, off, ang, sc: T.TRSTransform(off, ang, sc)(p),
          (Arg("points", (4, 6, 2)), Arg("offset", (4, 2)), Arg("angle", (4,), "angle",
                                                                "unitless"),
           Arg("scale", (4,), "positive", "unitless")),
          bad=((4, 6, 3), (2,))),
    Entry("transforms.HomogeneousTransform",
          lambda p, m: T.HomogeneousTransform(m)(p),
          (Arg("points", (4, 6, 2)), Arg("matrix", (4, 3, 3), "homography", "matrix")),
          bad=((4, 6, 3), (2,))),
    # --- curves: bernstein / bezier
    Entry("curves.bernstein_basis", lambda t: bernstein_basis(t, 5),
          (Arg("t", (3, 7), "t01", "unitless"),), out="unitless", empty=(0, -1), low="reject",
          bad=((),)),
    Entry("curves.bezier", C.bezier, (CTRL, T_), empty=(1, -1), mixed="promote", low="reject",
          bad=BADCTRL),
    Entry("curves.cubic_bezier", C.cubic_bezier, (CTRL, T_), empty=(1, -1), mixed="promote",
          low="reject", bad=((3, 5, 2), (3,))),
    Entry("curves.quartic_bezier", C.quartic_bezier, (Arg("control_points", (3, 5, 2)), T_),
          empty=(1, -1), mixed="promote", low="reject", bad=((3, 4, 2), (3,))),
    Entry("curves.de_casteljau", C.de_casteljau, (CTRL, T_), empty=(1, -1), mixed="promote",
          low="reject", bad=BADCTRL),
    Entry("curves.bezier_derivative", C.bezier_derivative, (CTRL,), empty=(0, 0), mixed=None,
          low="reject", bad=BADCTRL),
    Entry("curves.split_bezier", C.split_bezier,
          (CTRL, Arg("t0", (3,), "t01", "unitless")), out=("length", "length"),
          empty=((0, 0), (1, 0)), mixed="promote", low="reject", bad=BADCTRL),
    Entry("curves.elevate_bezier", lambda cp: C.elevate_bezier(cp, 2), (CTRL,), empty=(0, 0),
          mixed=None, low="reject", bad=BADCTRL),
    Entry("curves.bezier_tangent", C.bezier_tangent, (CTRL, T_), out="unitless", empty=(1, -1),
          mixed="promote", low="reject", bad=BADCTRL),
    Entry("curves.bezier_normal", C.bezier_normal, (CTRL, T_), out="unitless", empty=(1, -1),
          mixed="promote", low="reject", bad=BADCTRL),
    Entry("curves.bezier_normal[3d]", C.bezier_normal, (Arg("control_points", (3, 4, 3)), T_),
          out="unitless", empty=(1, -1), mixed="promote", low="reject", bad=BADCTRL,
          rtol=1e-7),
    Entry("curves.bezier_curvature", C.bezier_curvature, (CTRL, T_), out="inv_length",
          empty=(1, -1), mixed="promote", low="reject", bad=BADCTRL, rtol=1e-7),
    Entry("curves.bezier_length", C.bezier_length, (CTRL,), empty=(0, 0), mixed=None,
          low="reject", bad=BADCTRL, rtol=1e-7),
    Entry("curves.bezier_arclength_params", lambda cp: C.bezier_arclength_params(cp, 5),
          (CTRL,), out="unitless", empty=(0, 0), mixed=None, low="reject", bad=BADCTRL,
          rtol=1e-7),
    Entry("curves.BezierCurve", lambda cp, t: C.BezierCurve(cp)(t), (CTRL, T_), empty=(1, -1),
          mixed="raise", low="reject", bad=BADCTRL),
    # --- curves: hermite
    Entry("curves.hermite_basis", C.hermite_basis, (Arg("t", (3, 7), "t01", "unitless"),),
          out="unitless", empty=(0, -1), low="reject", bad=((),)),
    Entry("curves.hermite", lambda t, p0, p1, m0, m1: C.hermite(p0, p1, m0, m1, t),
          (T_, Arg("p0", (3, 2)), Arg("p1", (3, 2)), Arg("m0", (3, 2)), Arg("m1", (3, 2))),
          empty=(0, -1), mixed="promote", low="reject", bad=((),)),
    Entry("curves.HermiteCurve", lambda t, p0, p1, m0, m1: C.HermiteCurve(p0, p1, m0, m1)(t),
          (T_, Arg("p0", (3, 2)), Arg("p1", (3, 2)), Arg("m0", (3, 2)), Arg("m1", (3, 2))),
          empty=(0, -1), mixed="raise", low="reject", bad=((),)),
    Entry("curves.hermite_to_bezier", C.hermite_to_bezier,
          (Arg("p0", (3, 2)), Arg("p1", (3, 2)), Arg("m0", (3, 2)), Arg("m1", (3, 2))),
          empty=EMPTY4, mixed="promote", low="reject", bad=((),)),
    Entry("curves.bezier_to_hermite", C.bezier_to_hermite, (CTRL,),
          out=("length",) * 4, empty=(0, 0), mixed=None, low="reject", bad=((3, 5, 2), (3,))),
    Entry("curves.hermite_spline",
          lambda x, knots, values, tangents: C.hermite_spline(knots, values, tangents, x),
          (Arg("x", (3, 9), "inside", "length"), Arg("knots", (6,), "increasing"),
           Arg("values", (3, 6)), Arg("tangents", (3, 6), "normal", "unitless")),
          empty=(0, -1), mixed="promote", low="reject", bad=((),)),
    Entry("curves.HermiteSpline", lambda x, k, v, m: C.HermiteSpline(k, v, m)(x),
          (Arg("x", (3, 9), "inside", "length"), Arg("knots", (6,), "increasing"),
           Arg("values", (3, 6)), Arg("tangents", (3, 6), "normal", "unitless")),
          empty=(0, -1), mixed="raise", low="reject", bad=((),)),
    Entry("curves.pchip_tangents", C.pchip_tangents,
          (Arg("x", (6,), "increasing"), Arg("y", (3, 6))), out="unitless", empty=(1, 0),
          mixed="promote", low="reject", nan="raise", bad=((),)),
    Entry("curves.pchip_interpolate", lambda xq, x, y: C.pchip_interpolate(x, y, xq),
          (Arg("xq", (3, 9), "inside", "length"), Arg("x", (6,), "increasing"),
           Arg("y", (3, 6))), empty=(0, -1), mixed="promote", low="reject", bad=((),)),
    Entry("curves.PchipInterpolator", lambda xq, x, y: C.PchipInterpolator(x, y)(xq),
          (Arg("xq", (3, 9), "inside", "length"), Arg("x", (6,), "increasing"),
           Arg("y", (3, 6))), empty=(0, -1), mixed="promote", low="reject", bad=((),)),
    Entry("curves.cardinal_tangents", lambda v, k: C.cardinal_tangents(k, v, 0.3),
          (Arg("values", (3, 6)), Arg("knots", (6,), "increasing")), out="unitless",
          empty=(0, 0), mixed="promote", low="reject", bad=((),)),
    Entry("curves.catmull_rom_tangents", lambda v, k: C.catmull_rom_tangents(k, v),
          (Arg("values", (3, 6)), Arg("knots", (6,), "increasing")), out="unitless",
          empty=(0, 0), mixed="promote", low="reject", bad=((),)),
    # --- curves: parametric
    Entry("curves.circle", C.circle,
          (Arg("t", (3, 7), "angle", "unitless"), Arg("center", (3, 2)),
           Arg("radius", (3,), "positive")),
          empty=(0, -1), mixed=("follow", 0), low="reject", bad=((),)),
    Entry("curves.implicit_circle", C.implicit_circle,
          (Arg("xy", (3, 7, 2)), Arg("center", (3, 1, 2)), Arg("radius", (3, 1), "positive")),
          out="area", empty=(0, -2), mixed=("follow", 0), low="reject", bad=((3, 7, 3), ())),
    Entry("curves.cycloid", C.cycloid, (Arg("t", (3, 7), "angle", "unitless"),
                                        Arg("radius", (3,), "positive")),
          empty=(0, -1), mixed=("follow", 0), low="reject", bad=((),)),
    Entry("curves.figure_eight_implicit", C.figure_eight_implicit,
          (Arg("xy", (3, 7, 2)), Arg("radius", (3, 1), "positive")), out="area2",
          empty=(0, -2), mixed=("follow", 0), low="reject", bad=((3, 7, 3), ()), rtol=1e-7),
    Entry("curves.figure_eight_parametric", C.figure_eight_parametric,
          (Arg("t", (3, 7), "angle", "unitless"), Arg("radius", (3,), "positive")),
          empty=(0, -1), mixed=("follow", 0), low="reject", bad=((),)),
    # --- sdf: primitives
    Entry("sdf.sphere", S.sphere, (PTS3, Arg("radius", (2,), "positive"), Arg("center", (3,))),
          mixed="raise", bad=BAD3),
    Entry("sdf.circle", S.circle, (PTS2, Arg("radius", (2,), "positive"), Arg("center", (2,))),
          mixed="raise", bad=BAD2),
    Entry("sdf.box", S.box, (PTS3, Arg("half_size", (2, 3), "positive"),
                             Arg("radius", (2,), "small_positive"), Arg("center", (3,))),
          mixed="raise", bad=BAD3),
    Entry("sdf.rectangle", S.rectangle, (PTS2, Arg("half_size", (2, 2), "positive"),
                                         Arg("radius", (2,), "small_positive")),
          mixed="raise", bad=BAD2),
    Entry("sdf.capsule", S.capsule, (PTS3, Arg("start", (3,)), Arg("end", (2, 3)),
                                     Arg("radius", (2,), "positive")),
          mixed="raise", bad=BAD3),
    Entry("sdf.plane", S.plane, (PTS3, Arg("normal", (2, 3), "normal", "unitless"),
                                 Arg("offset", (2,))),
          mixed="raise", bad=BAD3),
    Entry("sdf.torus", S.torus, (PTS3, Arg("major_radius", (2,), "positive"),
                                 Arg("minor_radius", (2,), "small_positive")),
          mixed="raise", bad=BAD3),
    Entry("sdf.torus[algebraic]", lambda p, R, r: S.torus(p, R, r, exact=False),
          (PTS3, Arg("major_radius", (2,), "positive"),
           Arg("minor_radius", (2,), "small_positive")),
          out="area", mixed="raise", bad=BAD3),
    Entry("sdf.annulus", S.annulus, (PTS2, Arg("major_radius", (2,), "positive"),
                                     Arg("minor_radius", (2,), "small_positive")),
          mixed="raise", bad=BAD2),
    Entry("sdf.gyroid", S.gyroid, (PTS3, Arg("scale", (2,), "positive", "inv_length"),
                                   Arg("thickness", (2,), "small_positive")),
          mixed="raise", bad=BAD3, rtol=1e-7),
    Entry("sdf.Sphere", lambda p, r, c: S.Sphere(r, c, **_module_dtype(c))(p),
          (PTS3, Arg("radius", (), "positive"), Arg("center", (3,))), mixed=None, bad=BAD3),
    Entry("sdf.Circle", lambda p, r, c: S.Circle(r, c, **_module_dtype(c))(p),
          (PTS2, Arg("radius", (), "positive"), Arg("center", (2,))), mixed=None, bad=BAD2),
    Entry("sdf.Box", lambda p, h, r, c: S.Box(h, r, c, **_module_dtype(c))(p),
          (PTS3, Arg("half_size", (3,), "positive"), Arg("radius", (), "small_positive"),
           Arg("center", (3,))), mixed=None, bad=BAD3),
    Entry("sdf.Rectangle", lambda p, h, r, c: S.Rectangle(h, r, c, **_module_dtype(c))(p),
          (PTS2, Arg("half_size", (2,), "positive"), Arg("radius", (), "small_positive"),
           Arg("center", (2,))), mixed=None, bad=BAD2),
    Entry("sdf.Capsule", lambda p, a, b, r: S.Capsule(a, b, r, **_module_dtype(r))(p),
          (PTS3, Arg("start", (3,)), Arg("end", (3,)), Arg("radius", (), "positive")),
          mixed=None, bad=BAD3),
    Entry("sdf.Plane", lambda p, n, d: S.Plane(n, d, **_module_dtype(d))(p),
          (PTS3, Arg("normal", (3,), "normal", "unitless"), Arg("offset", ())), mixed=None,
          bad=BAD3),
    Entry("sdf.Torus", lambda p, R, r: S.Torus(R, r, **_module_dtype(r))(p),
          (PTS3, Arg("major_radius", (), "positive"), Arg("minor_radius", (), "small_positive")),
          mixed=None, bad=BAD3),
    Entry("sdf.Annulus", lambda p, R, r: S.Annulus(R, r, **_module_dtype(r))(p),
          (PTS2, Arg("major_radius", (), "positive"), Arg("minor_radius", (), "small_positive")),
          mixed=None, bad=BAD2),
    Entry("sdf.Gyroid", lambda p, k, w: S.Gyroid(k, w, **_module_dtype(w))(p),
          (PTS3, Arg("scale", (), "positive", "inv_length"), Arg("thickness", (),
                                                                 "small_positive")),
          mixed=None, bad=BAD3, rtol=1e-7),
    # --- sdf: operators on values
    Entry("sdf.union", S.union, (Arg("sdf[0]", (2, 6)), Arg("sdf[1]", (2, 6)),
                                 Arg("sdf[2]", (2, 6))), empty=EMPTY3, bad=((3, 6),)),
    Entry("sdf.intersection", S.intersection, (Arg("sdf[0]", (2, 6)), Arg("sdf[1]", (2, 6))),
          empty=EMPTY2, bad=((3, 6),)),
    Entry("sdf.difference", S.difference, (Arg("sdf[0]", (2, 6)), Arg("sdf[1]", (2, 6))),
          empty=EMPTY2, bad=((3, 6),)),
    Entry("sdf.smooth_union", S.smooth_union, (Arg("sdf[0]", (2, 6)), Arg("sdf[1]", (2, 6)),
                                               Arg("k", (), "positive")),
          empty=EMPTY2, bad=((3, 6),)),
    Entry("sdf.smooth_intersection", S.smooth_intersection,
          (Arg("sdf[0]", (2, 6)), Arg("sdf[1]", (2, 6)), Arg("k", (), "positive")),
          empty=EMPTY2, bad=((3, 6),)),
    Entry("sdf.product", S.product, (Arg("sdf[0]", (2, 6)), Arg("sdf[1]", (2, 6))),
          out="area", empty=EMPTY2, bad=((3, 6),)),
    # --- sdf: operators on functions and their modules
    Entry("sdf.translate", lambda p, off, r: S.translate(lambda q: S.sphere(q, r), off)(p),
          (PTS3, Arg("offset", (3,)), Arg("radius", (), "positive")), mixed="raise",
          bad=((2, 6, 2), (3,))),
    Entry("sdf.rotate",
          lambda p, rot, a: S.rotate(lambda q: S.capsule(q, a, -a, a.abs().sum()), rot)(p),
          (PTS3, Arg("world_from_local", (3, 3), "rotation", "unitless"), Arg("start", (3,))),
          mixed="raise", bad=((2, 6, 2), (3,))),
    Entry("sdf.scale", lambda p, f, r: S.scale(lambda q: S.sphere(q, r), f)(p),
          (PTS3, Arg("factor", (2,), "positive", "unitless"), Arg("radius", (), "positive")),
          mixed="raise", bad=BAD3),
    Entry("sdf.Union", lambda p, r: S.Union(S.Sphere(r, **_module_dtype(r)),
                                            S.Sphere(r / 2, _on_x(r), **_module_dtype(r)))(p),
          (PTS3, Arg("radius", (), "positive")), mixed=None, bad=BAD3),
    Entry("sdf.Intersection",
          lambda p, r: S.Intersection(S.Sphere(r, **_module_dtype(r)),
                                      S.Sphere(r, _on_x(r), **_module_dtype(r)))(p),
          (PTS3, Arg("radius", (), "positive")), mixed=None, bad=BAD3),
    Entry("sdf.Difference",
          lambda p, r: S.Difference(S.Sphere(r, **_module_dtype(r)),
                                    S.Sphere(r / 2, **_module_dtype(r)))(p),
          (PTS3, Arg("radius", (), "positive")), mixed=None, bad=BAD3),
    Entry("sdf.SmoothUnion",
          lambda p, r: S.SmoothUnion(S.Sphere(r, **_module_dtype(r)),
                                     S.Sphere(r, _on_x(r), **_module_dtype(r)), k=r / 4,
                                     **_module_dtype(r))(p),
          (PTS3, Arg("radius", (), "positive")), mixed=None, bad=BAD3),
    Entry("sdf.SmoothIntersection",
          lambda p, r: S.SmoothIntersection(S.Sphere(r, **_module_dtype(r)),
                                            S.Sphere(r, _on_x(r), **_module_dtype(r)),
                                            k=r / 4, **_module_dtype(r))(p),
          (PTS3, Arg("radius", (), "positive")), mixed=None, bad=BAD3),
    Entry("sdf.Product",
          lambda p, r: S.Product(S.Sphere(r, **_module_dtype(r)),
                                 S.Sphere(r, _on_x(r), **_module_dtype(r)))(p),
          (PTS3, Arg("radius", (), "positive")), out="area", mixed=None, bad=BAD3),
    Entry("sdf.Translate",
          lambda p, off, r: S.Translate(S.Sphere(r, **_module_dtype(r)), off,
                                        **_module_dtype(r))(p),
          (PTS3, Arg("offset", (3,)), Arg("radius", (), "positive")), mixed=None, bad=BAD3),
    Entry("sdf.Rotate",
          lambda p, rot, r: S.Rotate(S.Sphere(r, _on_x(r), **_module_dtype(r)), rot)(p),
          (PTS3, Arg("world_from_local", (3, 3), "rotation", "unitless"),
           Arg("radius", (), "positive")), mixed=None, bad=((2, 6, 2), (3,))),
    Entry("sdf.Scale", lambda p, f, r: S.Scale(S.Sphere(r, **_module_dtype(r)), f,
                                               **_module_dtype(r))(p),
          (PTS3, Arg("factor", (), "positive", "unitless"), Arg("radius", (), "positive")),
          mixed=None, bad=BAD3),
    # --- sdf: the grid
    Entry("sdf.grid_spacing", lambda b: S.grid_spacing(5, b), (Arg("bounds", (2, 3), "bounds"),),
          out=("length", "length"), empty=None, mixed=None, nan="raise", bad=((3, 3),)),
    Entry("sdf.grid_points", lambda b: S.grid_points((3, 4, 2), b),
          (Arg("bounds", (2, 3), "bounds"),), empty=None, mixed=None, nan="raise",
          bad=((3, 3),)),
    Entry("sdf.sample_grid", _sample_grid, (Arg("bounds", (2, 3), "bounds"),),
          out=("length", "length", "length"), empty=None, mixed=None, nan="raise",
          bad=((3, 3),), cross="bounds take no batch, and the call reads its rows"),
    Entry("core.index_to_world", core.index_to_world,
          (Arg("indices", (2, 5, 3), "index", "unitless"), Arg("origin", (3,)),
           Arg("spacing", (3,), "positive")), int_ok=True, mixed=("follow", 1),
          bad=((2, 5, 2),), low="compute32"),
    Entry("core.world_to_index", core.world_to_index,
          (Arg("points", (2, 5, 3)), Arg("origin", (3,)), Arg("spacing", (3,), "positive")),
          out="unitless", mixed=("follow", 0), bad=((2, 5, 2), ())),
    Entry("sdf.grid_interpolate",
          lambda p, v, o, sp: S.grid_interpolate(v, p, o, sp),
          (Arg("points", (2, 5, 3), "inside"), Arg("volume", (4, 5, 3)), Arg("origin", (3,), "t01"),
           Arg("spacing", (3,), "positive")), mixed=("follow", 0), bad=((2, 5, 2), (3,)),
          rtol=1e-7),
    Entry("sdf.zero_level_set", _level_set,
          (Arg("volume", (2, 4, 5, 3)), Arg("origin", (3,)), Arg("spacing", (3,), "positive"),
           Arg("tol", (), "positive")),
          out=("length", "index", "index", "index"), empty=(0, 0), mixed=("follow", 0),
          bad=((5, 3),), nan="raise", cross="tol is a Python number (float(tol) in the call)"),
    # --- sdf: gradients
    Entry("sdf.sdf_gradient", lambda p: S.sdf_gradient(S.sphere, p), (PTS3,), out="unitless",
          bad=((2, 6), ())),
    Entry("sdf.sdf_normal", lambda p: S.sdf_normal(S.sphere, p), (PTS3,), out="unitless",
          bad=((2, 6), ())),
    Entry("sdf.eikonal_loss", S.eikonal_loss, (Arg("gradients", (2, 6, 3), "normal",
                                                   "unitless"),),
          out="unitless", empty_scalar=True, bad=((6,),)),
]

TABLE: list[Entry] = CORE_TABLE + [e for area in AREAS for e in area.ENTRIES]

#: Public names with no geometry to put under contract (name -> reason).
EXEMPT: dict[str, str] = {
    **{k: v for area in AREAS for k, v in area.EXEMPT.items()},
    **{f"viz.{n}": "figures: pictures, no numeric contract (tests/viz)"
       for n in ("GalleryFigure", "build_gallery", "figure", "registered_figures")},
    "cli.CommandError": "the command line's one-line error (tests/cli)",
    "ShapeError": "exception type",
    "core.ShapeError": "exception type",
    "core.as_tensor_like": "coercion helper (tests/core/test_coerce.py)",
    "core.check_same_dtype": "validation helper (tests/core/test_coerce.py)",
    "core.check_module_dtype": "validation helper (tests/test_module_machinery.py)",
    "core.check_broadcastable": "validation helper (tests/core/test_check.py)",
    "core.check_choice": "validation helper (tests/core/test_check.py)",
    "core.check_generator": "validation helper (tests/core/test_check.py)",
    "core.check_float": "validation helper (tests/core/test_check.py)",
    "core.check_shape": "validation helper (tests/core/test_check.py)",
    "core.check_tensor": "validation helper (tests/core/test_check.py)",
    "core.check_spacing": "validation helper (tests/sdf/test_grid.py)",
    "core.cast_back": "dtype helper (tests/core/test_numerics.py)",
    "core.working_dtype": "dtype helper (tests/core/test_numerics.py)",
    "core.records_graph": "autograd predicate, no geometry (tests/core/test_autograd.py)",
    "core.is_transform_wrapped": "autograd predicate, no geometry (its doctest)",
    "core.power_of_two_scale": "a detached constant factor, exact by construction "
                               "(tests/core/test_numerics.py)",
    "curves.SplitResult": "NamedTuple result type",
    "curves.HermiteControls": "NamedTuple result type",
    "curves.grid_2d": "factory of numbers (n, low, high), no tensor input; tests/curves",
    "core.Volume": "NamedTuple result type",
    "sdf.LevelSetPoints": "NamedTuple result type",
    "transforms.AffineDecomposition": "NamedTuple result type",
}
