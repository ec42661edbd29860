"""limit_frames: OpenSubdiv's limit tangent masks, checked against planes,
hand-derived magnitudes and normals fitted to densely refined limit points."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.mesh import SubdivisionTags, bilinear_operator
from torchgeo_cg.mesh.subdivision import (
    CatmullClark,
    SchemeOptions,
    catmull_clark_operator,
    limit_positions,
)
from torchgeo_cg.mesh.subdivision.limit import limit_frames
from torchgeo_cg.mesh.subdivision.loop import LoopSubdivision, loop_operator

GRID_Q = [[r * 4 + c, r * 4 + c + 1, r * 4 + c + 5, r * 4 + c + 4]
          for r in range(3) for c in range(3)]
GRID_T = [[a, b, c] for a, b, c, d in GRID_Q] + [[a, c, d] for a, b, c, d in GRID_Q]
CUBE_V = torch.tensor([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)],
                      dtype=torch.float64)
CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
def test_planar_grid_normals_are_the_plane_normal(scheme, boundary):
    g = torch.Generator().manual_seed(0)
    xy = torch.tensor([[c, r] for r in range(4) for c in range(4)], dtype=torch.float64)
    xy = xy + 0.15 * torch.rand(16, 2, generator=g, dtype=torch.float64)
    verts = torch.cat([xy, torch.zeros(16, 1, dtype=torch.float64)], 1)
    build = catmull_clark_operator if scheme == "catmark" else loop_operator
    op = build(GRID_Q if scheme == "catmark" else GRID_T, 16,
               options=SchemeOptions(boundary=boundary),
               dtype=torch.float64)
    frames = limit_frames(op, verts)
    assert_close(frames.positions, limit_positions(op, verts))
    expected = torch.zeros_like(frames.normals)
    expected[:, 2] = 1.0
    used = torch.unique(op.faces)
    assert_close(frames.normals[used], expected[used], rtol=0, atol=1e-12)
    assert frames.tangent_u[:, 2].abs().max() < 1e-12
    assert frames.tangent_v[:, 2].abs().max() < 1e-12


def test_regular_vertex_tangents_hand_derived():
    """Valence-4 mask: tan_u = 4 (e0 - e2) + (d0 - d1 - d2 + d3); on the refined unit grid
    (spacing 1/2) that is 4 * 1 + 2 = 6 along edge 0, and tan_v is tan_u rotated by 90 deg."""
    xy = torch.tensor([[c, r, 0.0] for r in range(4) for c in range(4)], dtype=torch.float64)
    frames = limit_frames(catmull_clark_operator(GRID_Q, 16, dtype=torch.float64), xy)
    tu, tv = frames.tangent_u[5], frames.tangent_v[5]
    assert_close(tu.norm(), torch.tensor(6.0, dtype=torch.float64))
    assert_close(tv, torch.stack([-tu[1], tu[0], tu[2]]))


def _fitted_normal(points):
    centred = points - points.mean(0)
    return np.linalg.svd(centred)[2][-1]


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_normals_match_planes_fitted_to_refined_limit_points(scheme):
    """At each control vertex, the normal is that of the plane through the limit points of
    its 1-ring after 4 more levels (a disc of radius ~1/16 of an edge)."""
    if scheme == "catmark":
        verts, faces, cls = CUBE_V * torch.tensor([1.0, 1.5, 0.8], dtype=torch.float64), \
            CUBE_F, CatmullClark
    else:
        mesh = trimesh.creation.icosphere(subdivisions=1)
        verts = torch.from_numpy(np.asarray(mesh.vertices)) * torch.tensor([1.0, 0.7, 1.3])
        verts, faces, cls = verts.double(), mesh.faces.tolist(), LoopSubdivision
    fine = cls(faces, len(verts), levels=4, dtype=torch.float64)
    op0 = fine.operator(0)
    frames = limit_frames(op0, verts)
    last = fine.operator(3)
    level3 = cls(faces, len(verts), levels=3, dtype=torch.float64)(verts)
    limit = limit_positions(last, level3)
    faces_l = last.faces.numpy()
    for v in range(len(verts)):
        ring = np.unique(faces_l[(faces_l == v).any(1)])
        n = _fitted_normal(limit[ring].numpy())
        ours = frames.normals[v].numpy()
        assert abs(n @ ours) > 0.999, (v, n, ours)
        outward = (verts[v] - verts.mean(0)).numpy()
        assert ours @ outward > 0
        assert abs(frames.tangent_u[v].numpy() @ ours) < 1e-9


def test_crease_tangent_runs_along_the_crease():
    loop = [(0, 1), (1, 3), (3, 2), (2, 0)]
    tags = SubdivisionTags(torch.tensor(loop), torch.full((4,), 10.0, dtype=torch.float64),
                           torch.zeros(0, dtype=torch.long), torch.zeros(0, dtype=torch.float64),
                           torch.zeros(0, dtype=torch.long))
    op = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64, tags=tags)
    frames = limit_frames(op, CUBE_V)
    # vertex 0 = (0,0,0) on the crease square x = 0: the crease is the B-spline of the square,
    # its tangent at vertex 0 lies in the plane x = 0, along the diagonal direction
    tu = frames.tangent_u[0]
    assert abs(float(tu[0])) < 1e-12 and float(tu.norm()) > 0
    assert_close(tu[1].abs(), tu[2].abs())


def test_refuses_schemes_without_masks():
    with pytest.raises(ValueError, match="scheme 'bilinear'"):
        limit_frames(bilinear_operator(CUBE_F, 8), CUBE_V)


@pytest.mark.parametrize("dtype, scale", [(torch.float32, 1e20), (torch.float32, 1e-25),
                                          (torch.float64, 1e160), (torch.float64, 1e-170)])
def test_normals_are_unit_at_every_scale(dtype, scale):
    """The cross product of the tangents can overflow (NaN normals at 1e20 in float32) or
    underflow (zero normals at 1e-25) unless rescaled; the normals of a tilted planar grid are its
    plane normal, by hand, at every scale."""
    xy = torch.tensor([[c, r] for r in range(4) for c in range(4)], dtype=torch.float64)
    plane = torch.tensor([0.3, -0.2], dtype=torch.float64)  # z = 0.3 x - 0.2 y
    verts = torch.cat([xy, (xy @ plane)[:, None]], 1)
    expected = torch.cat([-plane, torch.ones(1, dtype=torch.float64)])
    expected = (expected / expected.norm()).to(dtype).expand(16 * 4, 3)
    op = catmull_clark_operator(GRID_Q, 16, dtype=dtype)
    normals = limit_frames(op, (verts * scale).to(dtype)).normals
    used = torch.unique(op.faces)
    assert_close(normals[used], expected[used], rtol=0, atol=1e-5 if dtype == torch.float32
                 else 1e-12)


@pytest.mark.parametrize("dtype, size, offset", [(torch.float32, 1e37, 2e38),
                                                 (torch.float64, 1e306, 1e308)])
def test_tangents_of_points_near_the_largest_float_are_finite(dtype, size, offset):
    """Tangent masks are differences (``4 e0 - 4 e2``), which would overflow to
    ``inf - inf = NaN`` for a mesh translated near the largest float although the tangents
    are finite. Tangent masks sum to 0, so translation must not change them (reference:
    the same cube at the origin)."""
    cube = CUBE_V.to(dtype) * 2 - 1
    op = catmull_clark_operator(CUBE_F, 8, dtype=dtype)
    here = limit_frames(op, cube * size)
    far = limit_frames(op, cube * size + offset)
    assert torch.isfinite(far.tangent_u).all() and torch.isfinite(far.tangent_v).all()
    rtol = 1e-4 if dtype == torch.float32 else 1e-12
    for got, want in ((far.tangent_u, here.tangent_u), (far.tangent_v, here.tangent_v)):
        assert_close(got / size, want / size, rtol=rtol, atol=rtol)
    assert_close(far.normals, here.normals, rtol=rtol, atol=rtol)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_gradcheck_frames_at_several_scales(scale):
    """The scale-safe tangents and normals (power-of-two and max-component divisions,
    detached) keep the exact gradient: gradcheck in float64 against finite differences."""
    g = torch.Generator().manual_seed(3)
    x = (CUBE_V * 2 - 1 + 0.1 * torch.randn(8, 3, generator=g, dtype=torch.float64)) * scale
    op = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64)
    x.requires_grad_()
    assert torch.autograd.gradcheck(lambda y: tuple(limit_frames(op, y)), (x,),
                                    eps=1e-6 * scale, atol=1e-5)
