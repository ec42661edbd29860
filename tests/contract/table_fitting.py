"""Contract entries of scene graph, report shapes, Bezier fitting, marching squares.

``ENTRIES`` join ``table.TABLE``; ``EXEMPT`` names have no geometry (result types,
exceptions, validators).
"""

from __future__ import annotations

import math

import torch

import torchgeo_cg.curves as C
import torchgeo_cg.transforms as T
from tests.contract.spec import Arg, Entry
from torchgeo_cg.core.grid import Volume

__all__ = ["ENTRIES", "EXEMPT"]


# ----------------------------------------------------------------------------- helpers


def _phases(shape, g, dtype):
    """Phases in radians, one cycle ``[0, 2π)``."""
    return 2 * math.pi * torch.rand(shape, generator=g, dtype=torch.float64)


def _orbit(spin: bool, learnable: bool = False):
    def call(theta, radius, speed, phase):
        return T.Orbit(radius, speed, phase, spin=spin, learnable=learnable)(theta)

    return call


def _scene(theta, root, r1, r2):
    """A three-level tree: a fixed root, an orbit, a spinning orbit around it."""
    scene = T.SceneGraph()
    scene.add("root", None, root)
    scene.add("a", "root", T.Orbit(r1, r1.new_tensor(1.0), r1.new_tensor(0.0)))  # r1's dtype
    scene.add("b", "a", T.Orbit(r2, r2.new_tensor(2.0), r2.new_tensor(0.5), spin=True))
    scene.add("c", "root", lambda th: T.translation(torch.stack([r2 + 0 * th, r1 + 0 * th], -1)))
    world = scene.world_transforms(theta)
    return world.matrices, world.positions()


def _solar(spin: bool = False):
    """The report's system, its state in the dtype of the floating ``theta``."""

    def call(theta):
        scene = T.solar_system(spin=spin)
        return (scene.to(theta.dtype) if theta.is_floating_point() else scene)(theta)

    return call


def _polylines(result):
    return result.verts, result.lengths, result.batch, result.closed


def _fit(fit):
    return fit.control_points, fit.t, fit.rms


THETA = Arg("theta", (5,), _phases, "unitless")
SCALARS = (Arg("radius", (), "positive"), Arg("speed", (), "normal", "unitless"),
           Arg("phase", (), "normal", "unitless"))
FIELD = Arg("field", (2, 4, 5), "normal", "unitless")
FRAME = (Arg("origin", (2,)), Arg("spacing", (2,), "positive"))
POLY = ("length", "index", "index", "index")
STROKES = Arg("points", (2, 6, 2))
FIT = ("length", "unitless", "length")

# ----------------------------------------------------------------------------- the table

ENTRIES: list[Entry] = [
    # --- transforms: scene graph
    Entry("transforms.Orbit", _orbit(False), (THETA, *SCALARS), out="matrix", empty=(0, 0),
          mixed="raise", bad=((2,),), bad_arg=1),
    Entry("transforms.Orbit[spin]", _orbit(True), (THETA, *SCALARS), out="matrix",
          empty=(0, 0), mixed="raise", bad=((2,),), bad_arg=1),
    Entry("transforms.Orbit[learnable]", _orbit(True, True), (THETA, *SCALARS), out="matrix",
          empty=(0, 0), mixed="raise", bad=((2,),), bad_arg=1),
    Entry("transforms.FixedTransform", lambda m, theta: T.FixedTransform(m)(theta),
          (Arg("matrix", (3, 3), "homography", "matrix"), THETA), out="matrix", empty=(1, 0),
          mixed="raise", bad=((3, 2), (3,))),
    Entry("transforms.SceneGraph", _scene,
          (THETA, Arg("root", (3, 3), "homography", "matrix"), Arg("r1", (), "positive"),
           Arg("r2", (), "positive")),
          # mixed dtypes raise in the node modules (FixedTransform, Orbit entries), whose
          # message names their own state, not this entry's argument names
          out=("matrix", "length"), empty=(0, 0), mixed=None, bad=((5, 2), ()),
          cross="the nodes' errors name their own arguments (matrix, theta), not this "
                "entry's; the node modules' entries cover them"),
    # The report's system has fixed radii (2, 3, 1): no input carries a length.
    Entry("transforms.solar_system", _solar(), (THETA,),
          out="unitless", empty=(0, 0), mixed=None, bad=((5, 2),)),
    Entry("transforms.solar_system[spin]", _solar(True),
          (THETA,), out="unitless", empty=(0, 0), mixed=None, bad=((5, 2),)),
    # --- curves: fitting
    Entry("curves.fit_parameters", C.fit_parameters, (STROKES,), out="unitless", empty=(0, 0),
          mixed=None, bad=((6,), (2, 1, 2))),
    Entry("curves.fit_parameters[centripetal]", lambda p: C.fit_parameters(p, "centripetal"),
          (STROKES,), out="unitless", empty=(0, 0), mixed=None, bad=((6,), (2, 1, 2))),
    # uniform parameters read only the count M, never the values: a NaN point has no effect
    Entry("curves.fit_parameters[uniform]", lambda p: C.fit_parameters(p, "uniform"),
          (STROKES,), out="unitless", empty=(0, 0), mixed=None, nan="skip",
          bad=((6,), (2, 1, 2))),
    Entry("curves.fit_bezier", lambda p: _fit(C.fit_bezier(p, 2)), (STROKES,), out=FIT,
          empty=(0, 0), mixed=None, bad=((6,), (2, 2, 2))),
    Entry("curves.fit_bezier[uniform]", lambda p: _fit(C.fit_bezier(p, 3, "uniform")),
          (STROKES,), out=FIT, empty=(0, 0), mixed=None, bad=((6,), (2, 3, 2))),
    Entry("curves.fit_bezier[weights]", lambda w, p: _fit(C.fit_bezier(p, 2, weights=w)),
          (Arg("weights", (2, 6), "positive", "unitless"), STROKES), out=FIT,
          empty=((0, 0), (1, 0)), mixed=("follow", 1), bad=((2, 5),)),
    Entry("curves.fit_bezier[lengths]",
          lambda p: _fit(C.fit_bezier(p, 2, "centripetal", lengths=torch.tensor([6, 4])[
              :p.shape[0]])),
          (STROKES,), out=FIT, empty=(0, 0), mixed=None, bad=((6,),),
          cross="the call makes lengths for the unbatched strokes"),
    Entry("curves.fit_bezier[corrected]",
          lambda p: _fit(C.fit_bezier(p, 2, correct_parameters=True, tol=0.0,
                                      max_iterations=3)),
          (STROKES,), out=FIT, empty=(0, 0), mixed=None, bad=((6,), (2, 2, 2))),
    # --- curves: marching squares. NaN samples are skipped: cells with a NaN corner give
    # no segment (as in skimage), so a NaN in gives no NaN out.
    Entry("curves.marching_squares",
          lambda f, o, sp: _polylines(C.marching_squares(f, origin=o, spacing=sp)),
          (FIELD, *FRAME), out=POLY, empty=(0, 0), mixed=("follow", 0), nan="skip",
          bad=((5,), (1, 5))),
    # scaling the values by s > 0 leaves the outline (iso = 0) unchanged
    Entry("curves.marching_squares[values]", lambda f: _polylines(C.marching_squares(f)),
          (Arg("field", (2, 4, 5)),), out=("unitless", "index", "index", "index"),
          empty=(0, 0), mixed=None, nan="skip", bad=((5,), (1, 5))),
    Entry("curves.marching_squares[low]",
          lambda f, o, sp: _polylines(C.marching_squares(f, origin=o, spacing=sp,
                                                         fully_connected="low")),
          (FIELD, *FRAME), out=POLY, empty=(0, 0), mixed=("follow", 0), nan="skip",
          bad=((5,), (1, 5))),
    Entry("curves.marching_squares[high]",
          lambda f, o, sp: _polylines(C.marching_squares(f, origin=o, spacing=sp,
                                                         fully_connected="high")),
          (FIELD, *FRAME), out=POLY, empty=(0, 0), mixed=("follow", 0), nan="skip",
          bad=((5,), (1, 5))),
    Entry("curves.marching_squares[volume]",
          lambda f, o, sp: _polylines(C.marching_squares(Volume(f, o, sp))),
          (FIELD, *FRAME), out=POLY, empty=(0, 0), mixed=("follow", 0), nan="skip",
          bad=((5,), (1, 5))),
]

EXEMPT: dict[str, str] = {
    "transforms.WorldTransforms": "NamedTuple result type (SceneGraph's entry checks "
                                  "its matrices and positions())",
    "transforms.report_shapes": "factory of the report's fixed data set (device/dtype "
                                "keywords, no tensor input); dtype policy and values in "
                                "tests/transforms/test_report_shapes.py",
    "transforms.fit_report_shapes": "fits the fixed report data (no tensor input): its numerics "
                                    "are fit_transform's and find_homography_dlt's, under "
                                    "contract in table_estimation; dtype policy in "
                                    "tests/transforms/test_report_shapes.py",
    "transforms.ReportShapes": "NamedTuple result type",
    "transforms.ShapeFit": "NamedTuple result type",
    "curves.BezierFit": "NamedTuple result type",
    "curves.MarchingSquaresResult": "NamedTuple result type",
}
