"""The dtype rule of a shape's parameters, over every primitive and operator of sdf.

Numbers, numpy values and lists take the points' dtype and device; a tensor parameter
keeps its dtype and must match the points (TypeError naming both), float16, bfloat16
and float32 meeting. So a float64 ``rotate`` never computes in float32.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import torchgeo_cg.sdf as S

F64 = torch.float64
ROT = [[math.cos(0.3), -math.sin(0.3), 0.0], [math.sin(0.3), math.cos(0.3), 0.0],
       [0.0, 0.0, 1.0]]

# name -> (call(points, parameter), the parameter as numbers, points' last dim)
CASES = {
    "sphere.radius": (lambda p, x: S.sphere(p, x), 0.7, 3),
    "sphere.center": (lambda p, x: S.sphere(p, 1.0, x), [0.1, 0.2, 0.3], 3),
    "circle.radius": (lambda p, x: S.circle(p, x), 0.7, 2),
    "circle.center": (lambda p, x: S.circle(p, 1.0, x), [0.1, 0.2], 2),
    "box.half_size": (lambda p, x: S.box(p, x), [0.3, 0.4, 0.5], 3),
    "box.radius": (lambda p, x: S.box(p, None, x), 0.1, 3),
    "box.center": (lambda p, x: S.box(p, None, 0.0, x), [0.1, 0.2, 0.3], 3),
    "rectangle.half_size": (lambda p, x: S.rectangle(p, x), [0.3, 0.4], 2),
    "rectangle.radius": (lambda p, x: S.rectangle(p, None, x), 0.1, 2),
    "capsule.start": (lambda p, x: S.capsule(p, x), [0.1, 0.2, 0.3], 3),
    "capsule.end": (lambda p, x: S.capsule(p, None, x), [0.1, 0.2, 1.3], 3),
    "capsule.radius": (lambda p, x: S.capsule(p, None, None, x), 0.3, 3),
    "plane.normal": (lambda p, x: S.plane(p, x), [0.1, 0.2, 1.3], 3),
    "plane.offset": (lambda p, x: S.plane(p, None, x), 0.3, 3),
    "torus.major_radius": (lambda p, x: S.torus(p, x), 1.1, 3),
    "torus.minor_radius": (lambda p, x: S.torus(p, 1.0, x), 0.3, 3),
    "annulus.major_radius": (lambda p, x: S.annulus(p, x), 1.1, 2),
    "annulus.minor_radius": (lambda p, x: S.annulus(p, 1.0, x), 0.3, 2),
    "gyroid.scale": (lambda p, x: S.gyroid(p, x), 1.1, 3),
    "gyroid.thickness": (lambda p, x: S.gyroid(p, 1.0, x), 0.3, 3),
    "translate.offset": (lambda p, x: S.translate(S.sphere, x)(p), [0.1, 0.2, 0.3], 3),
    "rotate.world_from_local": (lambda p, x: S.rotate(S.capsule, x)(p), ROT, 3),
    "scale.factor": (lambda p, x: S.scale(S.sphere, x)(p), 1.3, 3),
    "smooth_union.k": (lambda p, x: S.smooth_union(S.sphere(p), S.box(p, None), x), 0.3, 3),
    "smooth_intersection.k": (
        lambda p, x: S.smooth_intersection(S.sphere(p), S.box(p, None), x), 0.3, 3),
}


def _points(dim: int, dtype=F64) -> torch.Tensor:
    g = torch.Generator().manual_seed(dim)
    return torch.randn(2, 7, dim, generator=g, dtype=F64).to(dtype)


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_tensor_parameter_of_another_dtype_raises_naming_both(case):
    call, value, dim = CASES[case]
    name = case.split(".")[1]
    with pytest.raises(TypeError, match=rf"{name} is torch.float64.* is torch.float32"):
        call(_points(dim, torch.float32), torch.tensor(value, dtype=F64))
    with pytest.raises(TypeError, match=rf"{name} is torch.float32.* is torch.float64"):
        call(_points(dim), torch.tensor(value, dtype=torch.float32))


@pytest.mark.parametrize("case", sorted(CASES))
def test_numbers_take_the_points_dtype_and_tensors_of_it_are_used_as_given(case):
    call, value, dim = CASES[case]
    for dtype in (F64, torch.float32):
        points = _points(dim, dtype)
        want = call(points, torch.tensor(value, dtype=dtype))
        assert want.dtype == dtype
        for given in (value, np.asarray(value)):  # no rounding through float32
            got = call(points, given)
            assert got.dtype == dtype
            torch.testing.assert_close(got, want, rtol=0, atol=0)


@pytest.mark.parametrize("case", sorted(CASES))
def test_low_precision_dtypes_meet(case):
    call, value, dim = CASES[case]
    points = _points(dim, torch.float16)
    out = call(points, torch.tensor(value, dtype=torch.float32))
    assert out.dtype == torch.float16
    torch.testing.assert_close(out, call(points, value), rtol=0, atol=0)


def test_float64_rotate_on_float32_points_does_not_compute_in_float32():
    rot = torch.tensor(ROT, dtype=F64)
    points = _points(3)
    with pytest.raises(TypeError, match="world_from_local is torch.float64"):
        S.rotate(S.capsule, rot)(points.float())
    exact = S.capsule(points @ rot)  # row form of R^T p
    torch.testing.assert_close(S.rotate(S.capsule, ROT)(points), exact, rtol=0, atol=0)
    module = S.Rotate(S.Capsule(dtype=F64), rot)
    with pytest.raises(TypeError, match="float64"):
        module(points.float())
