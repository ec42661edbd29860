"""limit_surface / limit_stencils / sample_limit_surface against OpenSubdiv's Far::PatchTable
(run live), the closed-form bicubic B-spline patch, uniform subdivision and limit_positions."""

from pathlib import Path

import numpy as np
import pytest
import torch

import torchgeo_cg.mesh as mesh_pkg
from tests.mesh._osd import run_osd
from torchgeo_cg.mesh import (
    SubdivisionTags,
    apply_stencils,
    bilinear_operator,
    catmull_clark_operator,
    limit_positions,
    limit_stencils,
    limit_surface,
    load_mesh,
    sample_limit_surface,
)
from torchgeo_cg.mesh.subdivision import CatmullClark, SchemeOptions

RABBIT = Path(mesh_pkg.__file__).parent / "data" / "rabbit.obj"
CUBE_V = [[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)]
CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
MIXED_V = [[0, 0, 0], [1, 0, 0.2], [1, 1, 0], [0, 1, 0.1], [2, 0, 0], [2, 1, 0.3], [1.5, 2, 0],
           [0.5, 1.8, 0.2], [-0.5, 0.5, 0.1]]
MIXED_F = [[0, 1, 2, 3], [1, 4, 5, 2], [2, 5, 6], [3, 2, 6, 7], [0, 3, 8]]
F64 = torch.float64


def grid(n=5):
    v = [[c, r, 0.1 * ((r * 7 + c * 3) % 5)] for r in range(n) for c in range(n)]
    f = [[r * n + c, r * n + c + 1, (r + 1) * n + c + 1, (r + 1) * n + c]
         for r in range(n - 1) for c in range(n - 1)]
    return v, f


def cube_tags():
    return SubdivisionTags(torch.tensor([[0, 1], [1, 3], [4, 6]]),
                           torch.tensor([10.0, 10.0, 2.5]), torch.tensor([7]),
                           torch.tensor([10.0]), torch.tensor([3]))


def rabbit():
    m = load_mesh(RABBIT)
    return m.verts.double().tolist(), m.faces.tolist()


def num_ptex(faces):
    return sum(1 if len(f) == 4 else len(f) for f in faces)


def random_points(faces, n, seed, allowed=None, margin=2.0 ** -6):
    """Points away from the ptex faces' corners by ``margin`` (OpenSubdiv's Gregory end
    caps and ours differ only there)."""
    g = torch.Generator().manual_seed(seed)
    ids = torch.tensor(allowed if allowed is not None else range(num_ptex(faces)))
    fid = ids[torch.randint(0, len(ids), (n,), generator=g)]
    uv = margin + (1 - 2 * margin) * torch.rand(n, 2, generator=g, dtype=F64)
    return fid, uv


CASES = {
    "cube": (lambda: (CUBE_V, CUBE_F), "edge_only", None, None),
    "grid_edge_only": (grid, "edge_only", None, None),
    "grid_edge_and_corner": (grid, "edge_and_corner", None, None),
    "grid_none": (grid, "none", None, [5, 6, 9, 10]),
    "tagged_cube": (lambda: (CUBE_V, CUBE_F), "edge_only", cube_tags, [0, 1, 2, 4, 5]),
    "rabbit": (rabbit, "edge_only", None, None),
    "mixed": (lambda: (MIXED_V, MIXED_F), "edge_and_corner", None, None),
}


@pytest.mark.parametrize("name", list(CASES))
def test_matches_opensubdiv_patch_table(name):
    make, boundary, make_tags, allowed = CASES[name]
    verts, faces = make()
    tags = make_tags() if make_tags else None
    op = catmull_clark_operator(faces, len(verts), dtype=F64, tags=tags,
                                options=SchemeOptions(boundary=boundary))
    fid, uv = random_points(faces, 300, 1, allowed)
    ours = limit_surface(op, torch.tensor(verts, dtype=F64), fid, uv)
    ref = run_osd(verts, faces, "patch 10", tags=tags, boundary=boundary,
                  samples=np.c_[fid.numpy(), uv.numpy()])
    # OpenSubdiv's derivatives on the sub-faces of a non-quad are twice those in the
    # sub-face's own (u, v) (its patch parameter is scaled as if the sub-face were half
    # the size); positions agree, and ours are the true derivatives (finite differences)
    sizes = [len(f) for f in faces]
    sub = torch.tensor([s != 4 for s in sizes for _ in range(1 if s == 4 else s)])[fid]
    scale = torch.where(sub, 0.5, 1.0)[:, None].numpy()
    scale_xyz = np.abs(np.asarray(verts)).max()
    np.testing.assert_allclose(ours.positions.numpy(), ref[:, :3], atol=1e-12 * scale_xyz)
    np.testing.assert_allclose(ours.du.numpy(), scale * ref[:, 3:6], atol=1e-11 * scale_xyz)
    np.testing.assert_allclose(ours.dv.numpy(), scale * ref[:, 6:9], atol=1e-11 * scale_xyz)


def test_derivatives_are_those_of_the_ptex_parametrisation():
    verts, faces = MIXED_V, MIXED_F
    op = catmull_clark_operator(faces, len(verts), dtype=F64,
                                options=SchemeOptions(boundary="edge_and_corner"))
    v = torch.tensor(verts, dtype=F64)
    fid, uv = random_points(faces, 50, 2, margin=0.05)
    h = 1e-6
    out = limit_surface(op, v, fid, uv)
    for k, d in ((0, out.du), (1, out.dv)):
        step = torch.zeros(2, dtype=F64)
        step[k] = h
        fd = (limit_surface(op, v, fid, uv + step).positions
              - limit_surface(op, v, fid, uv - step).positions) / (2 * h)
        torch.testing.assert_close(d, fd, atol=1e-7, rtol=0)


def bspline_patch(P, s, t):
    """Closed-form uniform bicubic B-spline patch of a 4 x 4 grid ``P[j][k]`` (j along v)."""
    M = np.array([[-1, 3, -3, 1], [3, -6, 3, 0], [-3, 0, 3, 0], [1, 4, 1, 0]]) / 6.0
    bu = np.array([s ** 3, s ** 2, s, 1.0]) @ M
    bv = np.array([t ** 3, t ** 2, t, 1.0]) @ M
    return np.einsum("j,k,jkd->d", bv, bu, P)


def test_regular_face_is_the_closed_form_bicubic_patch():
    n = 6
    verts, faces = grid(n)
    v = np.asarray(verts, dtype=np.float64)
    v[:, 2] = np.sin(v[:, 0]) * np.cos(0.7 * v[:, 1])
    face = 2 * (n - 1) + 2  # row 2, column 2: an interior face, every corner of valence 4
    op = catmull_clark_operator(faces, len(verts), dtype=F64)
    fid, uv = random_points(faces, 40, 3, allowed=[face], margin=0.0)
    out = limit_surface(op, torch.tensor(v), fid, uv).positions.numpy()
    grid_ids = np.array([[(2 + j - 1) * n + (2 + k - 1) for k in range(4)] for j in range(4)])
    expected = np.stack([bspline_patch(v[grid_ids], s, t) for s, t in uv.numpy()])
    np.testing.assert_allclose(out, expected, atol=1e-13)


@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
@pytest.mark.parametrize("name", ["cube", "tagged_cube", "grid", "rabbit", "mixed"])
def test_corners_equal_limit_positions(name, boundary):
    verts, faces = {"cube": (CUBE_V, CUBE_F), "tagged_cube": (CUBE_V, CUBE_F),
                    "grid": grid(), "rabbit": rabbit(), "mixed": (MIXED_V, MIXED_F)}[name]
    # a closed loop of infinitely sharp creases and an infinitely sharp corner; no darts:
    # at a dart, limit_positions (like OpenSubdiv's PrimvarRefiner::Limit) applies the
    # smooth mask, which is not the limit there (Far::PatchTable and this agree)
    tags = SubdivisionTags(torch.tensor([[0, 1], [1, 3], [3, 2], [2, 0]]),
                           torch.full((4,), 10.0), torch.tensor([7]), torch.tensor([10.0]),
                           torch.zeros(0, dtype=torch.long)) if name == "tagged_cube" else None
    v = torch.tensor(verts, dtype=F64)
    op = catmull_clark_operator(faces, len(verts), dtype=F64, tags=tags,
                                options=SchemeOptions(boundary=boundary))
    limit = limit_positions(op, v)
    ids, uvs, want = [], [], []
    ptex = 0
    for f in faces:
        if len(f) == 4:
            for corner, uv in zip(f, [(0, 0), (1, 0), (1, 1), (0, 1)]):
                ids.append(ptex), uvs.append(uv), want.append(corner)
            ptex += 1
        else:
            for corner in f:
                ids.append(ptex), uvs.append((0, 0)), want.append(corner)
                ptex += 1
    out = limit_surface(op, v, torch.tensor(ids), torch.tensor(uvs, dtype=F64))
    torch.testing.assert_close(out.positions, limit[want], atol=1e-12, rtol=0)


def test_uniform_subdivision_converges_to_it():
    """At the vertices of uniform level k, the limit surface is the limit position of that
    vertex (exactly), and the refined vertices approach it as k grows."""
    verts, faces = rabbit()
    v = torch.tensor(verts, dtype=F64)
    op = catmull_clark_operator(faces, len(verts), dtype=F64)
    errors = []
    for k in (1, 2, 3):
        m = 2 ** k
        grid_uv = torch.tensor([(i / m, j / m) for i in range(m + 1) for j in range(m + 1)],
                               dtype=F64)
        fid = torch.arange(12).repeat_interleave(len(grid_uv))
        on = limit_surface(op, v, fid, grid_uv.repeat(12, 1)).positions
        cc = CatmullClark(faces, len(verts), levels=k, dtype=F64)
        refined = cc(v)
        lim = limit_positions(cc.operator(k - 1), CatmullClark(faces, len(verts), levels=k - 1,
                                                                  dtype=F64)(v))
        nearest = torch.cdist(on, lim).argmin(1)
        torch.testing.assert_close(on, lim[nearest], atol=1e-12, rtol=0)
        errors.append(float((refined[nearest] - on).norm(dim=-1).max()))
    assert errors[0] > 2 * errors[1] > 4 * errors[2] > 0, errors


def test_positions_and_normals_are_continuous_across_edges():
    verts, faces = rabbit()
    v = torch.tensor(verts, dtype=F64)
    op = catmull_clark_operator(faces, len(verts), dtype=F64)
    where = {}
    for f, face in enumerate(faces):
        for i in range(4):
            where[(face[i], face[(i + 1) % 4])] = (f, i)
    w = torch.tensor([0.0, 2.0 ** -20, 0.13, 0.5, 0.77, 1 - 2.0 ** -20, 1.0], dtype=F64)
    along = [lambda w: (w, 0 * w), lambda w: (1 + 0 * w, w), lambda w: (1 - w, 1 + 0 * w),
             lambda w: (0 * w, 1 - w)]
    fa, uva, fb, uvb = [], [], [], []
    for (a, b), (f, i) in where.items():
        g, j = where[(b, a)]
        fa.append(torch.full_like(w, f, dtype=torch.long))
        uva.append(torch.stack(along[i](w), -1))
        fb.append(torch.full_like(w, g, dtype=torch.long))
        uvb.append(torch.stack(along[j](1 - w), -1))
    one = limit_surface(op, v, torch.cat(fa), torch.cat(uva))
    two = limit_surface(op, v, torch.cat(fb), torch.cat(uvb))
    torch.testing.assert_close(one.positions, two.positions, atol=1e-12, rtol=0)
    # the normals too, at the edge's ends (extraordinary vertices of valence 3, 5 and 6
    # included) and within 2**-20 of them
    torch.testing.assert_close(one.normals, two.normals, atol=1e-9, rtol=0)


@pytest.mark.grad
def test_gradcheck_through_limit_stencils():
    verts, faces = MIXED_V, MIXED_F
    op = catmull_clark_operator(faces, len(verts), dtype=F64)
    fid, uv = random_points(faces, 12, 4, margin=0.0)
    st = limit_stencils(op, fid, uv)
    v = torch.tensor(verts, dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x: tuple(apply_stencils(m, x) for m in st), (v,))
    assert torch.autograd.gradcheck(lambda x: limit_surface(op, x, fid, uv).normals, (v,))


def test_batches_share_one_stencil_and_scale():
    verts, faces = rabbit()
    v = torch.tensor(verts, dtype=F64)
    batch = torch.stack([v, 2 * v + 1, v.flip(-1)])
    op = catmull_clark_operator(faces, len(verts), dtype=F64)
    fid, uv = random_points(faces, 30, 5)
    out = limit_surface(op, batch, fid.reshape(3, 10), uv.reshape(3, 10, 2))
    assert out.positions.shape == (3, 3, 10, 3)
    single = limit_surface(op, batch[1], fid, uv)
    torch.testing.assert_close(out.positions[1].reshape(30, 3), single.positions)
    torch.testing.assert_close(single.positions, 2 * limit_surface(op, v, fid, uv).positions + 1)
    for k in (1e-6, 1e6):
        torch.testing.assert_close(limit_surface(op, v * k, fid, uv).normals,
                                   limit_surface(op, v, fid, uv).normals)


def test_stencil_rows_sum_to_one_and_regular_rows_have_16_entries():
    verts, faces = grid(6)
    op = catmull_clark_operator(faces, len(verts), dtype=F64)
    fid, uv = random_points(faces, 20, 6, allowed=[12])
    st = limit_stencils(op, fid, uv)
    torch.testing.assert_close(st.positions.sparse().to_dense().sum(1), torch.ones(20, dtype=F64))
    torch.testing.assert_close(st.du.sparse().to_dense().sum(1), torch.zeros(20, dtype=F64))
    assert (st.positions.crow[1:] - st.positions.crow[:-1]).tolist() == [16] * 20


@pytest.mark.parametrize("lattice", [False, True])
def test_stencils_hold_their_transposes_and_no_zeros(lattice):
    """The three matrices against a dense brute force of their own entries: one shared
    pattern in CSR order with increasing columns, the transposes equal to the transposed
    matrices, no entry zero in all three (on knot lines, ``lattice``, whole columns of the
    bicubic basis vanish and are dropped), on the rabbit (patches of several levels, end
    caps)."""
    verts, faces = rabbit()
    op = catmull_clark_operator(faces, len(verts), dtype=F64)
    fid, uv = random_points(faces, 400, 8, margin=0.0)
    if lattice:  # corners, edge middles and centres of the child patches
        uv = torch.randint(0, 5, uv.shape, generator=torch.Generator().manual_seed(1)) / 4.0
        uv = uv.to(F64)
    st = limit_stencils(op, fid, uv)
    assert st.du.col is st.positions.col and st.dv.col_t is st.positions.col_t
    union = sum((m.dense() != 0).to(torch.int64) for m in st) > 0
    assert st.positions.col.numel() == int(union.sum())
    nonzero = torch.stack([m.weights for m in st]) != 0
    assert bool(nonzero.any(0).all())
    for m in st:
        torch.testing.assert_close(m.sparse_t().to_dense(), m.dense().t(), rtol=0, atol=0)
    crow, col = st.positions.crow, st.positions.col
    for r in torch.randint(0, 400, (20,)).tolist():  # each row's columns increase
        cols = col[crow[r]:crow[r + 1]]
        assert bool((cols[1:] > cols[:-1]).all())
    full = 400 * 16 if lattice else 0
    assert (col.numel() < full) == lattice  # the lattice dropped entries


def test_bad_input_raises():
    op = catmull_clark_operator(CUBE_F, 8, dtype=F64)
    v = torch.tensor(CUBE_V, dtype=F64)
    uv = torch.tensor([[0.5, 0.5]], dtype=F64)
    with pytest.raises(ValueError, match=r"face_ids: expected ptex face ids in \[0, 6\)"):
        limit_surface(op, v, torch.tensor([6]), uv)
    with pytest.raises(ValueError, match=r"uv: expected coordinates in \[0, 1\]"):
        limit_surface(op, v, torch.tensor([0]), uv + 1)
    with pytest.raises(TypeError, match="face_ids"):
        limit_surface(op, v, torch.tensor([0.0]), uv)
    with pytest.raises(ValueError, match="'catmark' or 'loop' operator"):
        limit_stencils(bilinear_operator(CUBE_F, 8), torch.tensor([0]), uv)
    holed = catmull_clark_operator(CUBE_F, 8, dtype=F64, tags=cube_tags())
    with pytest.raises(ValueError, match="on a hole"):
        limit_surface(holed, v, torch.tensor([3]), uv)
    with pytest.raises(ValueError, match="max_level"):
        limit_stencils(op, torch.tensor([0]), uv, max_level=0)
    module = CatmullClark(torch.tensor(CUBE_F), 8)  # holds per-level operators, not one
    for call in (lambda: limit_surface(module, v, torch.tensor([0]), uv),
                 lambda: limit_stencils(module, torch.tensor([0]), uv),
                 lambda: sample_limit_surface(module, v, 4)):
        with pytest.raises(TypeError, match="operator: expected a SubdivisionOperator"):
            call()
    empty = limit_surface(op, v, torch.zeros(0, dtype=torch.long), torch.zeros(0, 2, dtype=F64))
    assert empty.positions.shape == (0, 3)


def test_samples_are_uniform_by_area():
    op = catmull_clark_operator(CUBE_F, 8, dtype=F64)
    v = torch.tensor(CUBE_V, dtype=F64)
    n = 6000
    out = sample_limit_surface(op, v, n, generator=torch.Generator().manual_seed(0))
    assert out.positions.shape == (n, 3) and out.normals.shape == (n, 3)
    counts = torch.bincount(out.face_ids, minlength=6).double()
    assert (counts - n / 6).abs().max() < 4 * (n / 6 * 5 / 6) ** 0.5  # equal areas by symmetry
    at = limit_surface(op, v, out.face_ids, out.uv)
    torch.testing.assert_close(out.positions, at.positions)
    # within a face, the density is |du x dv|: the centre quarter gets less than a quarter
    centre = ((out.uv - 0.5).abs() < 0.25).all(1).double().mean()
    g = torch.linspace(0.0025, 0.9975, 200, dtype=F64)
    uu, vv = torch.meshgrid(g, g, indexing="ij")
    fine = limit_surface(op, v, torch.zeros(40000, dtype=torch.long),
                         torch.stack([uu, vv], -1).reshape(-1, 2))
    area = torch.linalg.cross(fine.du, fine.dv).norm(dim=-1).reshape(200, 200)
    inner = ((uu - 0.5).abs() < 0.25) & ((vv - 0.5).abs() < 0.25)
    expected = float(area[inner].sum() / area.sum())
    assert abs(float(centre) - expected) < 4 * (expected * (1 - expected) / n) ** 0.5
