"""Catmull-Clark: exact values, an independent reference, invariants, gradients, bad input."""

from __future__ import annotations

import contextlib
import inspect
import io
import math
from fractions import Fraction

import numpy as np
import pytest
import torch
import trimesh
from hypothesis import given
from hypothesis import strategies as st

from tests.mesh._cc_reference import reference_levels
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.mesh import data as sample_data
from torchgeo_cg.mesh.faces import face_sizes, pad_faces, unpad_faces
from torchgeo_cg.mesh.io import to_trimesh
from torchgeo_cg.mesh.subdivision import (
    CatmullClark,
    SchemeOptions,
    SubdivisionOperator,
    apply_operator,
    catmull_clark,
    catmull_clark_operator,
    limit_positions,
)

# ----------------------------------------------------------------------------- meshes

CUBE_V = [[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)]
CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]


def cube():
    return np.array(CUBE_V), [list(f) for f in CUBE_F]


def tetrahedron():
    v = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    return v, [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]


def pyramid():  # mixed: a quad base and four triangles
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1.2]])
    return v, [[0, 3, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]


def prism(n):  # n-gon caps and quad sides
    t = 2 * np.pi * np.arange(n) / n
    ring = np.stack([np.cos(t), np.sin(t)], 1)
    v = np.concatenate([np.c_[ring, np.zeros(n)], np.c_[ring, np.ones(n)]])
    bottom = list(range(n))[::-1]
    top = list(range(n, 2 * n))
    sides = [[i, (i + 1) % n, n + (i + 1) % n, n + i] for i in range(n)]
    return v, [bottom, top, *sides]


def grid(nx=3, ny=2):  # open, with 4 corners
    xs, ys = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="ij")
    v = np.c_[xs.ravel(), ys.ravel(), 0.1 * (xs.ravel() ** 2)].astype(float)
    idx = lambda i, j: i * (ny + 1) + j  # noqa: E731
    return v, [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)]
               for i in range(nx) for j in range(ny)]


def open_cylinder(n=6):
    v, f = prism(n)
    return v, f[2:]


def fin():  # three quads sharing the edge (0, 1): a non-manifold edge
    v = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [1, 0, 1], [-0.5, 0.8, 0], [-0.5, 0.8, 1],
                  [-0.5, -0.8, 0], [-0.5, -0.8, 1]], dtype=float)
    return v, [[0, 2, 3, 1], [1, 5, 4, 0], [0, 6, 7, 1]]


def bowtie():  # two tetrahedra sharing vertex 0: a non-manifold vertex, plus an unused vertex
    a, fa = tetrahedron()
    b = 2 * a[0] - a[1:]  # point reflection through vertex 0 (flips orientation)
    v = np.concatenate([a, b, [[9.0, 9.0, 9.0]]])
    shift = {0: 0, 1: 4, 2: 5, 3: 6}
    fb = [[shift[i] for i in f[::-1]] for f in fa]
    return v, fa + fb


MESHES = {
    "cube": cube, "tetrahedron": tetrahedron, "pyramid": pyramid,
    "pentagon_prism": lambda: prism(5), "hexagon_prism": lambda: prism(6),
    "grid": grid, "open_cylinder": open_cylinder, "fin": fin, "bowtie": bowtie,
}
CLOSED = ["cube", "tetrahedron", "pyramid", "pentagon_prism", "hexagon_prism"]


# ----------------------------------------------------------------------------- exact values

def test_unit_cube_one_level_exact(dtype, device):
    v = torch.tensor(CUBE_V, dtype=dtype, device=device)
    v1, f1 = catmull_clark(v, torch.tensor(CUBE_F, device=device))
    assert v1.shape == (8 + 6 + 12, 3) and f1.shape == (24, 4)
    v1 = v1.cpu().double().numpy()
    # face points at the face centres
    np.testing.assert_allclose(v1[8:14], np.array(CUBE_V)[np.array(CUBE_F)].mean(1), atol=1e-6)
    # edge points: every coordinate in {1/8, 1/2, 7/8}; vertex points in {2/9, 7/9}
    for rows, allowed in ((v1[14:], (1 / 8, 1 / 2, 7 / 8)), (v1[:8], (2 / 9, 7 / 9))):
        dist = np.abs(rows[..., None] - np.array(allowed)).min(-1)
        assert dist.max() < 1e-6
    # hand-derived: corner (0,0,0) -> (2/9)(1,1,1); edge (0,1) (x=y=0, z from 0 to 1)
    assert Fraction(float(v1[0, 0])).limit_denominator(100) == Fraction(2, 9)
    edge_01 = 14 + 0  # edges sorted by (min, max): (0, 1) comes first
    np.testing.assert_allclose(v1[edge_01], [1 / 8, 1 / 8, 1 / 2], atol=1e-6)


def test_operator_rows_and_layout():
    op = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64)
    assert isinstance(op, SubdivisionOperator)
    assert (op.num_vertices_in, op.num_faces_in, op.num_edges_in, op.num_vertices_out) == (
        8, 6, 12, 26)
    dense = op.matrix.to_dense()
    assert dense.shape == (26, 8) and op.matrix.layout == torch.sparse_csr
    assert_close(dense.sum(1), torch.ones(26, dtype=torch.float64))
    assert_close(op.matrix_t.to_dense(), dense.T)
    # smooth valence-3 vertex: (n-2)/n = 1/3 self, 1/9 per neighbour + 1/9 * face-point weights
    assert_close(dense[0, 0], torch.tensor(1 / 3 + 3 * (1 / 9) * (1 / 4), dtype=torch.float64))


@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
def test_quad_boundary_rules_hand_derived(boundary):
    op = catmull_clark_operator([[0, 1, 2, 3]], 4,
                                options=SchemeOptions(boundary=boundary), dtype=torch.float64)
    s = op.matrix.to_dense()
    corner = [1.0, 0, 0, 0] if boundary == "edge_and_corner" else [0.75, 0.125, 0, 0.125]
    assert s[0].tolist() == corner
    assert s[5].tolist() == [0.5, 0.5, 0, 0]  # boundary edge (0, 1): midpoint


# ----------------------------------------------------------------------------- reference

@pytest.mark.parametrize("name", list(MESHES))
@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
@pytest.mark.parametrize("levels", [1, 2, 3])
def test_matches_reference(name, boundary, levels):
    v0, f0 = MESHES[name]()
    v_ref, f_ref = reference_levels(v0, f0, levels, boundary)
    v_ours, f_ours = catmull_clark(torch.tensor(v0), f0, levels=levels,
                                   options=SchemeOptions(boundary=boundary))
    assert f_ours.tolist() == f_ref
    np.testing.assert_allclose(v_ours.numpy(), v_ref, rtol=1e-12, atol=1e-12)


def test_reference_with_features_and_batch():
    v0, f0 = pyramid()
    feats = np.random.default_rng(0).normal(size=(3, len(v0), 5))
    cc = CatmullClark(f0, len(v0), levels=2, dtype=torch.float64)
    out = cc(torch.tensor(feats))
    for b in range(3):
        np.testing.assert_allclose(out[b].numpy(), reference_levels(feats[b], f0, 2)[0],
                                   atol=1e-12)
    out2 = cc(torch.tensor(feats).reshape(3, 1, len(v0), 5))
    assert out2.shape == (3, 1, cc.num_vertices_out, 5)
    assert_close(out2[:, 0], out)


def test_pymeshlab_peer_agrees_on_face_and_edge_points():
    """Live peer: pymeshlab's filter gives the same face and edge points on the unit cube;
    its vertex points differ (7/36 instead of the rules' 2/9), as pymeshlab documents."""
    pymeshlab = pytest.importorskip("pymeshlab")
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.array(CUBE_V),
                               face_list_of_indices=np.array(CUBE_F)))
    with contextlib.redirect_stdout(io.StringIO()):
        ms.meshing_surface_subdivision_catmull_clark(iterations=1)
    peer = ms.current_mesh().vertex_matrix()
    ours = catmull_clark(torch.tensor(CUBE_V, dtype=torch.float64), CUBE_F)[0].numpy()
    assert len(peer) == len(ours)
    key = lambda a: a[np.lexsort(a.T[::-1])]  # noqa: E731
    np.testing.assert_allclose(key(peer[8:]), key(ours[8:]), atol=1e-6)
    assert np.allclose(peer[0], 7 / 36) and np.allclose(ours[0], 2 / 9)


# ----------------------------------------------------------------------------- invariants

def _random_rotation(seed):
    q = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))[0]
    return q * np.sign(np.linalg.det(q))


@given(seed=st.integers(0, 2**16), name=st.sampled_from(list(MESHES)),
       boundary=st.sampled_from(["edge_only", "edge_and_corner"]))
def test_rigid_equivariance(seed, name, boundary):
    v0, f0 = MESHES[name]()
    rot = torch.tensor(_random_rotation(seed))
    t = torch.tensor(np.random.default_rng(seed + 1).normal(size=3) * 10)
    v = torch.tensor(v0)
    cc = CatmullClark(f0, len(v0), levels=2,
                      options=SchemeOptions(boundary=boundary), dtype=torch.float64)
    assert_close(cc(v @ rot.T + t), cc(v) @ rot.T + t, scale=1e3)


@pytest.mark.parametrize("name", list(MESHES))
def test_rows_sum_to_one_and_counts(name):
    v0, f0 = MESHES[name]()
    op = catmull_clark_operator(f0, len(v0), dtype=torch.float64)
    assert_close(op.matrix.to_dense().sum(1), torch.ones(op.num_vertices_out, dtype=torch.float64))
    edges = {tuple(sorted((f[k], f[(k + 1) % len(f)]))) for f in f0 for k in range(len(f))}
    assert op.num_edges_in == len(edges)
    assert op.num_vertices_out == len(v0) + len(f0) + len(edges)
    assert op.faces.shape == (sum(map(len, f0)), 4)
    assert int(face_sizes(pad_faces(f0)).sum()) == op.faces.shape[0]


@pytest.mark.parametrize("name", CLOSED)
def test_closed_stays_watertight(name):
    v0, f0 = MESHES[name]()
    before = to_trimesh(torch.tensor(v0), f0)
    v, f = catmull_clark(torch.tensor(v0), f0, levels=2)
    after = to_trimesh(v, f)
    assert after.is_watertight and after.is_winding_consistent
    assert after.euler_number == before.euler_number == 2
    assert after.volume > 0  # outward winding kept
    assert 0 < after.volume < before.volume  # Catmull-Clark shrinks convex shapes


def test_rabbit_loads_and_subdivides():
    rabbit = sample_data.rabbit(dtype=torch.float64)
    assert 200 <= rabbit.faces.shape[0] <= 600 and rabbit.faces.shape[1] == 4
    v, f = catmull_clark(rabbit.verts, rabbit.faces, levels=2)
    mesh = to_trimesh(v, f)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0


# ----------------------------------------------------------------------------- limit

@pytest.mark.parametrize("name", ["cube", "pyramid", "grid", "fin", "open_cylinder"])
@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
def test_limit_positions_invariant_under_refinement(name, boundary):
    """The limit surface does not change when refining: limit(level 1)[:V1] == limit(level 2)."""
    v0, f0 = MESHES[name]()
    v = torch.tensor(v0)
    options = SchemeOptions(boundary=boundary)
    op1 = catmull_clark_operator(f0, len(v0), dtype=torch.float64, options=options)
    op2 = catmull_clark_operator(op1.faces, op1.num_vertices_out, dtype=torch.float64,
                                 options=options)
    lim1 = limit_positions(op1, v)
    lim2 = limit_positions(op2, apply_operator(op1, v))
    assert_close(lim2[: op1.num_vertices_out], lim1, scale=100)


def test_limit_positions_converge():
    v0, f0 = pyramid()
    v = torch.tensor(v0)
    op = catmull_clark_operator(f0, len(v0), dtype=torch.float64)
    target = limit_positions(op, v)
    cc = CatmullClark(f0, len(v0), levels=7, dtype=torch.float64)
    errors, x = [], v
    for level in range(7):
        x = apply_operator(cc.operator(level), x)
        errors.append(float((x[: op.num_vertices_out] - target).norm(dim=1).max()))
    assert all(b < 0.6 * a for a, b in zip(errors, errors[1:]))
    assert errors[-1] < 2e-2 * errors[0]


def test_limit_regular_boundary_is_cubic_bspline():
    """On a boundary the limit is the uniform cubic B-spline mask (a + 4 V + b) / 6."""
    v0, f0 = grid(4, 1)
    v = torch.tensor(v0)
    op = catmull_clark_operator(f0, len(v0), dtype=torch.float64,
                                options=SchemeOptions(boundary="edge_and_corner"))
    lim = limit_positions(op, v)
    vp = apply_operator(op, v)
    edges = sorted({tuple(sorted((f[k], f[(k + 1) % 4]))) for f in f0 for k in range(4)})
    first_edge = op.num_vertices_in + op.num_faces_in
    a, b = first_edge + edges.index((0, 2)), first_edge + edges.index((2, 4))
    assert_close(lim[2], (vp[a] + 4 * vp[2] + vp[b]) / 6)  # vertex 2 = grid point (1, 0)


# ----------------------------------------------------------------------------- gradients

@pytest.mark.slow
@pytest.mark.grad
def test_gradcheck():
    v0, f0 = pyramid()
    cc = CatmullClark(f0, len(v0), levels=2, dtype=torch.float64)
    x = torch.tensor(v0, requires_grad=True)
    assert torch.autograd.gradcheck(cc, (x,))
    op = catmull_clark_operator(f0, len(v0), dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda y: limit_positions(op, y), (x,))


def test_custom_backward_equals_autograd(dtype, device):
    v0, f0 = MESHES["hexagon_prism"]()
    cc = CatmullClark(f0, len(v0), levels=2).to(device=device, dtype=dtype)
    x = torch.tensor(v0, dtype=dtype, device=device).expand(2, -1, -1).clone().requires_grad_()
    g = torch.randn(2, cc.num_vertices_out, 3, dtype=dtype, device=device)
    (cc(x) * g).sum().backward()
    dense = [cc.operator(level).matrix.to_dense() for level in range(2)]
    x_ref = x.detach().clone().requires_grad_()
    y_ref = dense[1] @ (dense[0] @ x_ref)
    (y_ref * g).sum().backward()
    assert_close(x.grad, x_ref.grad, scale=10)
    assert_close(cc(x).detach(), y_ref.detach(), scale=10)


# ----------------------------------------------------------------------------- module

def test_module_equals_function_and_defaults():
    fn = inspect.signature(catmull_clark).parameters
    mod = inspect.signature(CatmullClark.__init__).parameters
    for name in ("levels", "options"):
        assert fn[name].default == mod[name].default
    assert inspect.signature(catmull_clark_operator).parameters["options"].default == (
        mod["options"].default)
    v0, f0 = MESHES["fin"]()
    v = torch.tensor(v0)
    out_fn, faces_fn = catmull_clark(v, f0, levels=2)
    cc = CatmullClark(f0, len(v0), levels=2).double()
    assert_close(cc(v), out_fn)
    assert torch.equal(cc.faces, faces_fn)
    assert "levels=2" in repr(cc)


def test_module_to_moves_buffers(device):
    cc = CatmullClark(CUBE_F, 8, levels=2).to(device=device, dtype=torch.float64)
    for level in range(2):
        op = cc.operator(level)
        assert op.matrix.device.type == device.type and op.matrix.dtype == torch.float64
        assert op.faces.dtype == torch.long
    out = cc(torch.tensor(CUBE_V, dtype=torch.float64, device=device))
    assert out.device.type == device.type and out.dtype == torch.float64
    assert list(cc.state_dict()) == []  # non-persistent buffers
    with pytest.raises(IndexError, match="level"):
        cc.operator(2)


def test_levels_zero_and_dtype_follow_input(dtype):
    v = torch.tensor(CUBE_V, dtype=dtype)
    v0, f0 = catmull_clark(v, CUBE_F, levels=0)
    assert torch.equal(v0, v) and f0.tolist() == CUBE_F
    v1, _ = catmull_clark(v, CUBE_F)
    assert v1.dtype == dtype
    op = catmull_clark_operator(CUBE_F, 8)  # default dtype, applied to any dtype
    assert apply_operator(op, v).dtype == dtype


# ----------------------------------------------------------------------------- edge cases

def test_unreferenced_vertices_pass_through():
    v0, f0 = bowtie()  # vertex 7 is not used by any face
    op = catmull_clark_operator(f0, len(v0), dtype=torch.float64)
    row = op.matrix.to_dense()[7]
    assert row.tolist() == [0.0] * 7 + [1.0]
    out = apply_operator(op, torch.tensor(v0))
    assert out[7].tolist() == [9.0, 9.0, 9.0]
    assert torch.isfinite(out).all()


def test_non_manifold_fin_vertices_are_corners():
    v0, f0 = fin()
    out, _ = catmull_clark(torch.tensor(v0), f0)
    assert_close(out[:2], torch.tensor(v0[:2]))  # endpoints of the 3-face edge are kept


def test_degenerate_zero_area_face_is_finite():
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 0, 0.0], [0.5, 1, 0]],
                     dtype=torch.float64, requires_grad=True)
    faces = [[0, 1, 2, 3], [0, 4, 1]]  # the quad is collinear (zero area), vertex 3 == vertex 1
    out, _ = catmull_clark(v, faces, levels=2)
    out.sum().backward()
    assert torch.isfinite(out).all() and torch.isfinite(v.grad).all()


@pytest.mark.parametrize(
    "faces, match",
    [
        ([[0, 1, 2], [0, 2, 8]], "face 1 has index 8"),
        ([[0, 1, 2], [0, 2, -2]], "face 1 has index -2"),
        ([[0, 1, 2, -1], [0, -1, 2, 3]], "face 1 has -1 padding before a vertex"),
    ],
)
def test_bad_faces_name_the_face(faces, match):
    """Strictly invalid faces raise; repeated vertices and repeated faces do not (OpenSubdiv
    refines them: tests/mesh/test_degenerate_faces_live.py)."""
    with pytest.raises(ValueError, match=match):
        catmull_clark_operator(faces, 4)
    with pytest.raises(ValueError, match=match):
        catmull_clark(torch.zeros(4, 3), faces)
    with pytest.raises(ValueError, match=match):
        CatmullClark(faces, 4)


def test_bad_arguments():
    v = torch.tensor(CUBE_V)
    with pytest.raises(ValueError, match="boundary"):
        catmull_clark_operator(CUBE_F, 8, options=SchemeOptions(boundary="corner"))
    with pytest.raises(ValueError, match="boundary"):
        CatmullClark(CUBE_F, 8, options=SchemeOptions(boundary="smooth"))
    with pytest.raises(ValueError, match="levels"):
        CatmullClark(CUBE_F, 8, levels=-1)
    with pytest.raises(ValueError, match="levels"):
        catmull_clark(v, CUBE_F, levels=1.5)
    with pytest.raises(ShapeError, match="verts"):
        CatmullClark(CUBE_F, 8)(v[:7])
    with pytest.raises(ShapeError, match="verts"):
        apply_operator(catmull_clark_operator(CUBE_F, 8), v[:, None, :][:7])
    with pytest.raises(TypeError, match="verts"):
        CatmullClark(CUBE_F, 8)(v.long())
    with pytest.raises(TypeError, match="verts"):
        catmull_clark(v.tolist(), CUBE_F)
    with pytest.raises(ValueError, match="same device"):
        catmull_clark(v, torch.tensor(CUBE_F, device="meta"))


def test_icosphere_counts_match_euler():
    ico = trimesh.creation.icosphere(subdivisions=2)
    op = catmull_clark_operator(torch.from_numpy(ico.faces), len(ico.vertices))
    V, F, E = len(ico.vertices), len(ico.faces), len(ico.edges_unique)
    assert (op.num_vertices_out, op.faces.shape[0]) == (V + F + E, 3 * F)
    # Euler characteristic V - E + F of the quad mesh: 2
    e1 = 2 * op.faces.shape[0]  # each quad has 4 edges, each shared by 2 quads
    assert op.num_vertices_out - e1 + op.faces.shape[0] == 2
    assert math.isclose(float(op.matrix.to_dense().sum()), op.num_vertices_out, rel_tol=1e-5)
    assert unpad_faces(op.faces[:1])[0][0] == int(ico.faces[0, 0])


@pytest.mark.parametrize("levels", [1, 2])
def test_empty_in_empty_out(levels):
    """No vertices (and no faces) in gives no vertices and no faces out."""
    from torchgeo_cg.mesh import loop_subdivide

    for fn, k in ((catmull_clark, 4), (loop_subdivide, 3)):
        for faces in (torch.zeros(0, k, dtype=torch.long), []):
            verts, faces_out = fn(torch.zeros(0, 3), faces, levels=levels)
            assert verts.shape == (0, 3) and faces_out.shape == (0, k)
            assert faces_out.dtype == torch.long
        batch, _ = fn(torch.zeros(2, 0, 3, dtype=torch.float64), [], levels=levels)
        assert batch.shape == (2, 0, 3) and batch.dtype == torch.float64
        # vertices without faces pass through, batch of zero shapes stays empty
        lone = torch.arange(12.0).reshape(4, 3)
        verts, faces_out = fn(lone, torch.zeros(0, k, dtype=torch.long), levels=levels)
        assert torch.equal(verts, lone) and faces_out.shape == (0, k)
        none, _ = fn(torch.zeros(0, 3, 2), [[0, 1, 2]], levels=levels)
        assert none.shape[0] == 0 and none.shape[-1] == 2


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16])
def test_half_precision_is_refined_in_float32(low):
    """float16/bfloat16 verts (torch has no half sparse kernel) are refined in float32 and
    cast back: the cube corner moves to (2/9)^3
    (hand-derived), every value equals the float32 result rounded once, and the gradient
    (S^T applied to ones) comes back in the input dtype."""
    from torchgeo_cg.mesh import loop_subdivide

    v = torch.tensor(CUBE_V)
    want32, _ = catmull_clark(v, CUBE_F)
    verts = v.to(low).requires_grad_()
    got, _ = catmull_clark(verts, CUBE_F)
    assert got.dtype == low
    assert torch.equal(got, want32.to(low))
    assert_close(got[0].float(), torch.full((3,), 2 / 9), rtol=0, atol=4e-3)
    got.sum().backward()
    assert verts.grad.dtype == low
    # 26 rows summing to 1, shared by 8 symmetric vertices: every column sums to 26 / 8
    assert_close(verts.grad.float(), torch.full((8, 3), 26 / 8), rtol=1e-2, atol=0)
    op = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64)
    assert torch.equal(apply_operator(op, v.to(low)), apply_operator(op, v).to(low))
    tri = torch.tensor([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]])
    loop_v, _ = loop_subdivide(tri.to(low), [[0, 1, 2]])
    assert torch.equal(loop_v[3:], torch.tensor([[2.0, 0.0], [0.0, 2.0], [2.0, 2.0]]).to(low))


def test_integer_weight_dtype_raises_type_error():
    """``dtype=torch.long`` is not a weight dtype: every builder and module rejects a
    non-float weight dtype, naming it, rather than promoting it to float32."""
    from torchgeo_cg.mesh import (
        FaceVaryingSubdivision,
        LoopSubdivision,
        bilinear_operator,
        face_varying_operator,
        loop_operator,
    )

    quad, tris = [[0, 1, 2, 3]], [[0, 1, 2], [0, 2, 3]]
    calls = [
        lambda d: catmull_clark_operator(quad, 4, dtype=d),
        lambda d: CatmullClark(quad, 4, dtype=d),
        lambda d: loop_operator(tris, 4, dtype=d),
        lambda d: LoopSubdivision(tris, 4, dtype=d),
        lambda d: bilinear_operator(quad, 4, dtype=d),
        lambda d: face_varying_operator(quad, quad, 4, 4, dtype=d),
        lambda d: FaceVaryingSubdivision(quad, quad, 4, 4, dtype=d),
    ]
    for call in calls:
        with pytest.raises(TypeError, match="dtype: expected a floating-point"):
            call(torch.long)
        assert call(torch.float64) is not None
    assert catmull_clark_operator(quad, 4, dtype=torch.float64).stencils.weights.dtype == (
        torch.float64)
