"""Loop subdivision: trimesh peer (closed meshes), a loop-based reference, invariants, errors."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest
import torch
import trimesh
from hypothesis import given
from hypothesis import strategies as st

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.mesh.io import to_trimesh
from torchgeo_cg.mesh.subdivision import SchemeOptions, apply_operator, limit_positions
from torchgeo_cg.mesh.subdivision.loop import LoopSubdivision, loop_operator, loop_subdivide


def reference_loop(verts, faces, boundary="edge_only"):
    """Independent dict-and-loop implementation of the rules in the module docstring."""
    verts = np.asarray(verts, dtype=np.float64)
    V0 = len(verts)
    edge_opp: dict[tuple[int, int], list[int]] = {}
    for f in faces:
        for k in range(3):
            a, b, c = f[k], f[(k + 1) % 3], f[(k + 2) % 3]
            edge_opp.setdefault((min(a, b), max(a, b)), []).append(c)
    edges = sorted(edge_opp)
    row = {e: V0 + i for i, e in enumerate(edges)}
    edge_pts = []
    for a, b in edges:
        opp = edge_opp[(a, b)]
        if len(opp) == 2:
            edge_pts.append(3 / 8 * (verts[a] + verts[b]) + 1 / 8 * (verts[opp[0]] + verts[opp[1]]))
        else:
            edge_pts.append((verts[a] + verts[b]) / 2)
    vert_pts = []
    for v in range(V0):
        inc = [e for e in edges if v in e]
        sharp = [e for e in inc if len(edge_opp[e]) != 2]
        nbrs = [e[0] if e[1] == v else e[1] for e in inc]
        sharp_nbrs = [e[0] if e[1] == v else e[1] for e in sharp]
        n = len(inc)
        if n == 0 or len(sharp) > 2 or (
            len(sharp) == 2 and boundary == "edge_and_corner" and n == 2
        ):
            vert_pts.append(verts[v])
        elif len(sharp) == 2:
            vert_pts.append(0.75 * verts[v] + 0.125 * verts[sharp_nbrs].sum(0))
        else:
            beta = (5 / 8 - (3 / 8 + math.cos(2 * math.pi / n) / 4) ** 2) / n
            vert_pts.append((1 - n * beta) * verts[v] + beta * verts[nbrs].sum(0))
    new_faces = []
    for a, b, c in faces:
        ab, bc, ca = (row[(min(x, y), max(x, y))] for x, y in ((a, b), (b, c), (c, a)))
        new_faces += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
    return np.concatenate([np.array(vert_pts), np.array(edge_pts)]), new_faces


def tri_grid(n=3):
    xs, ys = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0), indexing="ij")
    v = np.c_[xs.ravel(), ys.ravel(), 0.1 * xs.ravel() * ys.ravel()]
    idx = lambda i, j: i * (n + 1) + j  # noqa: E731
    faces = []
    for i in range(n):
        for j in range(n):
            faces += [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)],
                      [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]]
    return v, faces


def tri_fin():  # three triangles sharing edge (0, 1), plus an unused vertex 5
    v = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0.5], [-0.5, 0.8, 0.5], [-0.5, -0.8, 0.5],
                  [7, 7, 7]], dtype=float)
    return v, [[0, 2, 1], [1, 3, 0], [0, 4, 1]]


def ico():
    m = trimesh.creation.icosphere(subdivisions=1)
    return m.vertices, m.faces.tolist()


MESHES = {"grid": tri_grid, "fin": tri_fin, "icosphere": ico}


@pytest.mark.parametrize("name", list(MESHES))
@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
@pytest.mark.parametrize("levels", [1, 2])
def test_matches_reference(name, boundary, levels):
    v0, f0 = MESHES[name]()
    v_ref, f_ref = v0, f0
    for _ in range(levels):
        v_ref, f_ref = reference_loop(v_ref, f_ref, boundary)
    v, f = loop_subdivide(torch.tensor(v0), f0, levels=levels,
                          options=SchemeOptions(boundary=boundary))
    assert f.tolist() == f_ref
    np.testing.assert_allclose(v.numpy(), v_ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("mesh", [trimesh.creation.icosphere(subdivisions=2),
                                  trimesh.creation.capsule(count=[6, 6]),
                                  trimesh.creation.box()], ids=["ico", "capsule", "box"])
def test_matches_trimesh_on_closed_meshes(mesh):
    """Live peer: trimesh's subdivide_loop uses the same weights on closed meshes."""
    v, f = loop_subdivide(torch.tensor(mesh.vertices), torch.from_numpy(mesh.faces), levels=2)
    tv, tf = trimesh.remesh.subdivide_loop(mesh.vertices, mesh.faces, iterations=2)
    key = lambda a: a[np.lexsort(np.round(a, 9).T[::-1])]  # noqa: E731
    np.testing.assert_allclose(key(v.numpy()), key(tv), atol=1e-12)
    ours, peer = to_trimesh(v, f), trimesh.Trimesh(tv, tf, process=False)
    assert ours.is_watertight and ours.is_winding_consistent
    assert np.isclose(ours.volume, peer.volume) and np.isclose(ours.area, peer.area)


@given(seed=st.integers(0, 2**16), name=st.sampled_from(list(MESHES)))
def test_rigid_equivariance_on_open_meshes(seed, name):
    v0, f0 = MESHES[name]()
    rng = np.random.default_rng(seed)
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    rot, t = torch.tensor(rot * np.sign(np.linalg.det(rot))), torch.tensor(rng.normal(size=3))
    loop = LoopSubdivision(f0, len(v0), levels=2, dtype=torch.float64)
    v = torch.tensor(v0)
    assert_close(loop(v @ rot.T + t), loop(v) @ rot.T + t, scale=1e3)


def test_rows_sum_to_one_counts_and_passthrough():
    v0, f0 = tri_fin()
    op = loop_operator(f0, len(v0), dtype=torch.float64)
    dense = op.matrix.to_dense()
    assert_close(dense.sum(1), torch.ones(op.num_vertices_out, dtype=torch.float64))
    assert op.num_vertices_out == len(v0) + op.num_edges_in and op.faces.shape == (12, 3)
    assert dense[5].tolist() == [0, 0, 0, 0, 0, 1.0]  # unreferenced vertex passes through
    assert_close(op.matrix_t.to_dense(), dense.T)


def test_gradcheck_and_module_defaults():
    v0, f0 = tri_grid(2)
    loop = LoopSubdivision(f0, len(v0), levels=2, dtype=torch.float64)
    assert torch.autograd.gradcheck(loop, (torch.tensor(v0, requires_grad=True),))
    fn = inspect.signature(loop_subdivide).parameters
    mod = inspect.signature(LoopSubdivision.__init__).parameters
    assert all(fn[k].default == mod[k].default for k in ("levels", "options"))
    v = torch.tensor(v0)
    out, faces = loop_subdivide(v, f0, levels=2)
    assert_close(loop(v), out)
    assert torch.equal(loop.faces, faces)


def test_device_dtype(device, dtype):
    v0, f0 = ico()
    v = torch.tensor(v0, dtype=dtype, device=device)
    out, faces = loop_subdivide(v, torch.tensor(f0, device=device))
    assert out.dtype == dtype and out.device.type == device.type
    assert faces.device.type == device.type


def test_errors():
    with pytest.raises(ShapeError, match="triangles"):
        loop_operator([[0, 1, 2, 3]], 4)
    with pytest.raises(ShapeError, match="triangles"):
        loop_operator([[0, 1, 2], [0, 2, 3, 4]], 5)
    with pytest.raises(ValueError, match="face 1 has index 9"):
        loop_operator([[0, 1, 2], [0, 2, 9]], 4)
    with pytest.raises(ValueError, match="boundary"):
        loop_operator([[0, 1, 2]], 3, options=SchemeOptions(boundary="smooth"))
    with pytest.raises(ValueError, match="same device"):
        loop_subdivide(torch.zeros(3, 3), torch.tensor([[0, 1, 2]], device="meta"))
    with pytest.raises(ShapeError, match="verts"):
        loop_subdivide(torch.zeros(3), [[0, 1, 2]])
    with pytest.raises(TypeError, match="verts"):
        loop_subdivide([[0.0, 0, 0]] * 3, [[0, 1, 2]])


# ---------------------------------------------------------------- limit positions ----------


def _octahedron():
    verts = torch.tensor([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                         dtype=torch.float64)
    faces = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5],
             [0, 3, 5]]
    return verts, faces


def _one_ring(faces, v):
    """Neighbours of interior vertex ``v`` in cyclic order (walk the fan, plain Python)."""
    nxt = {}
    for f in faces:
        for k in range(3):
            if f[k] == v:
                nxt[f[(k + 1) % 3]] = f[(k + 2) % 3]
    ring = [next(iter(nxt))]
    while len(ring) < len(nxt):
        ring.append(nxt[ring[-1]])
    return ring


def _reference_loop_limit(verts, faces, v):
    """Limit of interior vertex ``v``: the local subdivision matrix ``A`` (1-ring to 1-ring,
    written from Loop's rules) raised to a high power, applied to the 1-ring."""
    ring = _one_ring(faces, v)
    n = len(ring)
    beta = (5 / 8 - (3 / 8 + 1 / 4 * math.cos(2 * math.pi / n)) ** 2) / n
    a = torch.zeros(n + 1, n + 1, dtype=torch.float64)
    a[0, 0], a[0, 1:] = 1 - n * beta, beta
    for i in range(n):  # the child of edge (v, ring[i]): 3/8, 3/8 and the two opposite
        a[1 + i, 0] = a[1 + i, 1 + i] = 3 / 8
        a[1 + i, 1 + (i - 1) % n] += 1 / 8
        a[1 + i, 1 + (i + 1) % n] += 1 / 8
    mask = torch.linalg.matrix_power(a, 200)[0]
    return mask @ verts[[v] + ring]


@pytest.mark.parametrize("name", ["tetrahedron", "octahedron", "icosahedron", "icosphere1"])
def test_loop_limit_positions_match_local_matrix_power(name):
    if name == "octahedron":
        verts, faces = _octahedron()
    else:
        mesh = {
            "icosphere1": lambda: trimesh.creation.icosphere(subdivisions=1),
            "icosahedron": trimesh.creation.icosahedron,
            "tetrahedron": lambda: trimesh.Trimesh(
                [[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]],
                [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]], process=False),
        }[name]()
        verts = torch.from_numpy(np.asarray(mesh.vertices)).double()
        faces = np.asarray(mesh.faces).tolist()
    g = torch.Generator().manual_seed(0)
    verts = verts + 0.1 * torch.randn(verts.shape, generator=g, dtype=torch.float64)
    op = loop_operator(faces, len(verts), dtype=torch.float64)
    limit = limit_positions(op, verts)
    expected = torch.stack([_reference_loop_limit(verts, faces, v) for v in range(len(verts))])
    assert_close(limit[: len(verts)], expected, rtol=1e-12, atol=1e-12)


def test_loop_limit_is_invariant_under_refinement():
    mesh = trimesh.creation.icosahedron()
    verts = torch.from_numpy(np.asarray(mesh.vertices)).double()
    loop2 = LoopSubdivision(torch.from_numpy(mesh.faces).long(), len(verts), levels=2,
                            dtype=torch.float64)
    op0, op1 = loop2.operator(0), loop2.operator(1)
    first = limit_positions(op0, verts)
    second = limit_positions(op1, apply_operator(op0, verts))
    assert_close(second[: op0.num_vertices_out], first, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
def test_loop_limit_on_the_boundary_is_the_cubic_bspline(boundary):
    verts = torch.tensor([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]], dtype=torch.float64)
    op = loop_operator([[0, 1, 2], [0, 2, 3]], 4,
                       options=SchemeOptions(boundary=boundary), dtype=torch.float64)
    limit = limit_positions(op, verts)
    # vertex 0 has valence 3 (neighbours 1, 2, 3), boundary neighbours 1 and 3
    assert_close(limit[0], (verts[1] + 4 * verts[0] + verts[3]) / 6)
    if boundary == "edge_and_corner":  # valence-2 vertex 1 is a corner: kept
        assert_close(limit[1], verts[1])
    else:  # the cubic B-spline of the boundary polygon 0-1-2-3
        assert_close(limit[1], (verts[0] + 4 * verts[1] + verts[2]) / 6)


def test_limit_positions_differ_by_scheme_and_refuse_others():
    """An operator records its scheme, so a Loop operator gets Loop masks, not
    Catmull-Clark ones."""
    verts, faces = _octahedron()
    op = loop_operator(faces, 6, dtype=torch.float64)
    assert op.scheme == "loop"
    limit = limit_positions(op, verts)
    assert_close(limit[4], _reference_loop_limit(verts, faces, 4))
    # by hand: valence 4, beta = (5/8 - (3/8)^2) / 4, chi = 1 / (4 + 3 / (8 beta)); the
    # four neighbours sum to 0, so the apex (0, 0, 1) goes to (0, 0, 1 - 4 chi)
    chi = 1 / (4 + 3 / (8 * (5 / 8 - 9 / 64) / 4))
    assert_close(limit[4], torch.tensor([0.0, 0.0, 1 - 4 * chi], dtype=torch.float64))
    with pytest.raises(ValueError, match="scheme 'bilinear'"):
        limit_positions(op._replace(scheme="bilinear"), verts)
