"""Two arguments whose batch shapes do not broadcast raise ``ShapeError`` naming both.

Each case calls a public function with two arguments that are valid alone but whose
leading (batch) dims clash; the error must name both arguments and their shapes,
never surface as a raw torch error. Shapes that are legal (one side of size 1, an
empty batch against a broadcastable one) must work.
"""

from __future__ import annotations

import re

import pytest
import torch

from torchgeo_cg.core import ShapeError, safe_div

F64 = torch.float64


def _raises_naming(call, *parts):
    with pytest.raises(ShapeError) as err:
        call()
    message = str(err.value)
    for part in parts:
        assert re.search(re.escape(part), message), (part, message)


def test_safe_div_mismatched_operands():
    _raises_naming(lambda: safe_div(torch.ones(3, dtype=F64), torch.ones(4, dtype=F64)),
                   "num (3)", "den (4)")
    _raises_naming(lambda: safe_div(torch.ones(3), torch.ones(4), eps=1e-8), "num", "den")
    out = safe_div(torch.ones(3, 1, dtype=F64), torch.full((4,), 2.0, dtype=F64))
    assert out.shape == (3, 4) and bool((out == 0.5).all())


# ----------------------------------------------------------------------------- curves

from torchgeo_cg.curves import (  # noqa: E402
    PchipInterpolator,
    cardinal_tangents,
    hermite,
    hermite_spline,
    implicit_circle,
    pchip_interpolate,
    split_bezier,
)


def _knots(*batch, k=5):
    return torch.arange(float(k), dtype=F64).expand(*batch, k)


def test_hermite_t_of_a_wrong_leading_shape():
    p = torch.zeros(3, 2, dtype=F64)
    _raises_naming(lambda: hermite(p, p, p, p, torch.rand(4, 5, dtype=F64)), "t (4)", "(3)")
    _raises_naming(lambda: hermite(p, torch.zeros(4, 2, dtype=F64), p, p,
                                   torch.rand(5, dtype=F64)), "p0 (3)", "p1 (4)")
    assert hermite(p, p, p, p, torch.rand(1, 5, dtype=F64)).shape == (3, 5, 2)


def test_split_bezier_t0_of_a_mismatched_batch():
    cp = torch.randn(3, 4, 2, dtype=F64)
    _raises_naming(lambda: split_bezier(cp, torch.rand(5, dtype=F64)),
                   "control_points (3)", "t0 (5)")
    left, right = split_bezier(cp, torch.rand(2, 1, dtype=F64))
    assert left.shape == right.shape == (2, 3, 4, 2)


def test_pchip_xq_or_x_of_a_mismatched_batch():
    y = torch.randn(3, 5, dtype=F64)
    _raises_naming(lambda: pchip_interpolate(_knots(), y, torch.rand(4, 7, dtype=F64)),
                   "xq (4)", "y (3)")
    _raises_naming(lambda: pchip_interpolate(_knots(4), y, torch.rand(7, dtype=F64)),
                   "x (4)", "y (3)")
    _raises_naming(lambda: PchipInterpolator(_knots(4), y), "x (4)", "y (3)")
    _raises_naming(lambda: PchipInterpolator(_knots(), y)(torch.rand(4, 7, dtype=F64)),
                   "xq (4)", "y (3)")
    assert PchipInterpolator(_knots(), y)(torch.rand(1, 7, dtype=F64)).shape == (3, 7)


def test_hermite_spline_with_expanded_tangents():
    y = torch.randn(3, 5, dtype=F64)
    x = torch.rand(7, dtype=F64)
    tangents = torch.randn(2, 1, 5, dtype=F64).expand(2, 3, 5)
    got = hermite_spline(_knots(), y, tangents, x)
    want = hermite_spline(_knots(), y.expand(2, 3, 5).contiguous(), tangents.contiguous(),
                          x.expand(2, 3, 7).contiguous())
    assert got.shape == (2, 3, 7)
    torch.testing.assert_close(got, want)
    _raises_naming(lambda: hermite_spline(_knots(), y, torch.randn(4, 5, dtype=F64), x),
                   "values (3)", "tangents (4)")
    _raises_naming(lambda: hermite_spline(_knots(), y, y, torch.rand(4, 7, dtype=F64)),
                   "values (3)", "x (4)")


def test_cardinal_tangents_on_an_empty_batch():
    assert cardinal_tangents(_knots(0), torch.randn(0, 5, dtype=F64)).shape == (0, 5)
    assert cardinal_tangents(_knots(), torch.randn(0, 5, dtype=F64)).shape == (0, 5)
    _raises_naming(lambda: cardinal_tangents(_knots(0), torch.randn(3, 5, dtype=F64)),
                   "knots (0)", "values (3)")
    _raises_naming(lambda: cardinal_tangents(_knots(3), torch.randn(0, 5, dtype=F64)),
                   "knots (3)", "values (0)")


def test_implicit_circle_with_an_empty_batch_centre():
    xy = torch.randn(10, 2, dtype=F64)
    _raises_naming(lambda: implicit_circle(xy, torch.randn(0, 2, dtype=F64)),
                   "xy (10)", "center (0)")
    assert implicit_circle(xy[:0], torch.randn(0, 2, dtype=F64)).shape == (0,)
    assert implicit_circle(xy, torch.randn(1, 2, dtype=F64)).shape == (10,)


# ----------------------------------------------------------------------------- sdf

from torchgeo_cg.sdf import SDFSampler, sphere  # noqa: E402


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def test_sdf_sampler_callable_with_an_empty_batch_of_bounds():
    box = torch.tensor([[-1.0, -1, -1], [1, 1, 1]], dtype=F64)
    for bounds in (box.expand(0, 2, 3), box.expand(3, 2, 3)):
        with pytest.raises(ShapeError, match=re.escape("bounds: expected one box (2, 3)")):
            SDFSampler(sphere, bounds=bounds, generator=_gen(0))
    assert SDFSampler(sphere, bounds=box, generator=_gen(0)).sample(10).points.shape == (10, 3)


def test_sdf_sampler_mesh_bounds_of_another_batch():
    verts = torch.tensor([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1],
                          [0, 0, -1]], dtype=F64)
    faces = torch.tensor([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5],
                          [3, 1, 5], [0, 3, 5]])
    box = torch.tensor([[-2.0, -2, -2], [2, 2, 2]], dtype=F64)
    _raises_naming(lambda: SDFSampler((verts.expand(2, 6, 3), faces), bounds=box.expand(3, 2, 3)),
                   "vertices (2)", "bounds (3)")
    with pytest.raises(ShapeError, match="bounds"):
        SDFSampler((verts, faces), bounds=box.expand(3, 2, 3))
    out = SDFSampler((verts.expand(2, 6, 3), faces), bounds=box.expand(1, 2, 3), generator=_gen(0),
                     backend="torch").sample(20)
    assert out.points.shape == (2, 20, 3)


def test_winding_number_chunk_must_be_positive():
    from torchgeo_cg.sdf import winding_number

    tet = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=F64)
    points = torch.tensor([[0.1, 0.1, 0.1], [1.0, 1.0, 1.0]], dtype=F64)
    for chunk in (0, -5, 2.5, True):
        with pytest.raises(ValueError, match="chunk"):
            winding_number(verts, tet, points, chunk=chunk)
    torch.testing.assert_close(winding_number(verts, tet, points, chunk=1).abs(),
                               torch.tensor([1.0, 0.0], dtype=F64))
