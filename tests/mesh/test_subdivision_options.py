"""SchemeOptions: one validated bundle of the scheme rules, taken by every subdivision
builder and module as ``options=``; the old loose arguments are gone."""

from __future__ import annotations

import copy
import dataclasses
import inspect
from pathlib import Path

import pytest
import torch

import torchgeo_cg.mesh.subdivision as S
from torchgeo_cg.mesh.subdivision import SchemeOptions

TAKERS = [S.catmull_clark_operator, S.catmull_clark, S.CatmullClark, S.loop_operator,
          S.loop_subdivide, S.LoopSubdivision, S.face_varying_operator, S.face_varying_subdivide,
          S.FaceVaryingSubdivision, S.limit_surface, S.limit_stencils, S.sample_limit_surface]
LOOSE = {"boundary", "crease_method", "triangle_rule", "interpolation", "fvar_interpolation"}


def test_defaults_are_opensubdivs_and_values_are_validated():
    opts = SchemeOptions()
    assert (opts.boundary, opts.crease_method, opts.triangle_rule, opts.fvar_interpolation) == (
        "edge_only", "uniform", "catmark", "corners_only")
    for field, bad in (("boundary", "sharp"), ("crease_method", "linear"),
                       ("triangle_rule", "loop"), ("fvar_interpolation", "linear")):
        with pytest.raises(ValueError, match=field):
            SchemeOptions(**{field: bad})
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.boundary = "none"
    assert dataclasses.replace(opts, boundary="none") == SchemeOptions("none")
    assert hash(opts) == hash(SchemeOptions()) and copy.deepcopy(opts) == opts


@pytest.mark.parametrize("taker", TAKERS, ids=lambda f: f.__name__)
def test_every_builder_takes_options_keyword_only_and_no_loose_argument(taker):
    params = inspect.signature(taker).parameters
    assert params["options"].kind is inspect.Parameter.KEYWORD_ONLY
    assert params["options"].default == SchemeOptions()
    assert not LOOSE & set(params)


def test_a_string_where_options_go_raises_naming_options():
    with pytest.raises(TypeError, match="options: expected a SchemeOptions"):
        S.catmull_clark_operator([[0, 1, 2, 3]], 4, options="edge_and_corner")
    with pytest.raises(TypeError, match="boundary"):  # the old keyword is gone
        S.catmull_clark_operator([[0, 1, 2, 3]], 4, boundary="edge_and_corner")


def test_options_reach_the_rules():
    quad = [[0, 1, 2, 3]]
    square = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=torch.float64)
    kept = S.catmull_clark(square, quad, options=SchemeOptions(boundary="edge_and_corner"))[0]
    smoothed = S.catmull_clark(square, quad)[0]
    torch.testing.assert_close(kept[:4], square)  # valence-2 corners kept
    assert not torch.equal(smoothed[:4], square)
    module = S.CatmullClark(quad, 4, levels=2, dtype=torch.float64,
                            options=SchemeOptions(boundary="none"))
    assert module.faces.shape[0] == 0 and module.options.boundary == "none"
    assert module.operator(1).boundary == "edge_only"  # "none" acts at the base level only
    uv = S.face_varying_subdivide(square, quad, quad, 4,
                                  options=SchemeOptions(fvar_interpolation="all"))[0]
    torch.testing.assert_close(uv[4], square.mean(0))  # bilinear: the face centroid


def test_the_option_values_are_documented_once():
    root = Path(S.__file__).parent
    pasted = [p.name for p in root.glob("*.py") if p.name != "options.py"
              and '"edge_and_corner"`` (keep valence-2' in p.read_text()]
    assert pasted == []
    doc = SchemeOptions.__doc__
    for value in ("edge_only", "edge_and_corner", "none", "uniform", "chaikin", "catmark",
                  "smooth", "corners_only"):
        assert f'"{value}"' in doc
