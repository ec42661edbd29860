"""Face-varying subdivision (UV seams) against an independent dense reference.

The reference is written here from OpenSubdiv's face-varying rules (``Vtr::FVarLevel``:
a value is a vertex's value; seams are boundaries of the value mesh; a value is pinned
("sharp") by the linear-interpolation option): plain Python, dictionaries for the
topology, one corner at a time. It refines the position ids and the value ids together
so that child faces are compared corner for corner (``uv[faces]``), never by index.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.mesh import (
    FaceVaryingSubdivision,
    SubdivisionTags,
    apply_operator,
    bilinear_operator,
    catmull_clark_operator,
    face_varying_operator,
    face_varying_subdivide,
    loop_operator,
)
from torchgeo_cg.mesh.subdivision import SchemeOptions

# ----------------------------------------------------------------------------- meshes

CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
OCTA_F = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5],
          [0, 3, 5]]


def torus_grid(n: int, m: int):
    """Closed n x m quad torus and its (n+1) x (m+1) grid UVs (two seam loops)."""
    faces, uv_faces = [], []
    for i in range(n):
        for j in range(m):
            faces.append([i * m + j, (i + 1) % n * m + j, (i + 1) % n * m + (j + 1) % m,
                          i * m + (j + 1) % m])
            uv_faces.append([i * (m + 1) + j, (i + 1) * (m + 1) + j,
                             (i + 1) * (m + 1) + j + 1, i * (m + 1) + j + 1])
    uvs = [[i / n, j / m] for i in range(n + 1) for j in range(m + 1)]
    return faces, uv_faces, n * m, torch.tensor(uvs, dtype=torch.float64)


def open_grid(n: int):
    """n x n quads on (n+1)^2 vertices (open, with boundary corners)."""
    idx = lambda i, j: i * (n + 1) + j  # noqa: E731
    return [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)]
            for i in range(n) for j in range(n)], (n + 1) ** 2


def seam_values(faces, seams):
    """UV indices per corner: corners around a vertex share a value when connected
    across non-seam edges (union-find per vertex); returns (uv_faces, num_values)."""
    parent = {}

    def find(c):
        while parent[c] != c:
            parent[c] = parent[parent[c]]
            c = parent[c]
        return c

    edge_corners = {}
    for f, face in enumerate(faces):
        for k, v in enumerate(face):
            parent[(f, k)] = (f, k)
            w = face[(k + 1) % len(face)]
            edge_corners.setdefault(frozenset((v, w)), []).append((f, k))
    for key, corners in edge_corners.items():
        if len(corners) != 2 or key in seams:
            continue
        (f0, k0), (f1, k1) = corners
        n0, n1 = len(faces[f0]), len(faces[f1])
        # the two faces meet at both ends: corner at v of one with the corner at v of other
        a0, b0 = (f0, k0), (f0, (k0 + 1) % n0)
        a1, b1 = (f1, k1), (f1, (k1 + 1) % n1)
        for x, y in ((a0, b1), (b0, a1)):  # opposite traversal: a0 ~ b1, b0 ~ a1
            parent[find(x)] = find(y)
    ids = {}
    uv_faces = [[ids.setdefault(find((f, k)), len(ids)) for k in range(len(face))]
                for f, face in enumerate(faces)]
    return uv_faces, len(ids)


# ----------------------------------------------------------------------------- reference


def _edges(faces):
    out = {}
    for f, face in enumerate(faces):
        for k, v in enumerate(face):
            out.setdefault(frozenset((v, face[(k + 1) % len(face)])), []).append(f)
    return out


def pinned_values(pos_faces, val_faces, mode, creased_pos_edges=frozenset(),
                  corner_verts=frozenset()):
    """Values pinned by ``mode`` (OpenSubdiv FVarLevel::completeTopologyFromFaceValues)."""
    val_edges = _edges(val_faces)
    pos_edges = _edges(pos_faces)
    vert_of, faces_of = {}, {}
    sharp_at = {}
    for f, (pf, vf) in enumerate(zip(pos_faces, val_faces)):
        for k, (p, v) in enumerate(zip(pf, vf)):
            vert_of[v] = p
            faces_of.setdefault(v, set()).add(f)
            w, q = vf[(k + 1) % len(vf)], pf[(k + 1) % len(pf)]
            key = frozenset((v, w))
            if len(val_edges[key]) != 2 or frozenset((p, q)) in creased_pos_edges:
                sharp_at.setdefault(v, set()).add(key)
                sharp_at.setdefault(w, set()).add(key)
    values_of = {}
    for v, p in vert_of.items():
        values_of.setdefault(p, set()).add(v)
    pos_boundary = {p for e, fs in pos_edges.items() if len(fs) != 2 for p in e}
    pinned = {v for v, p in vert_of.items() if p in corner_verts}
    on_seam = {v for v in vert_of if any(len(val_edges[e]) != 2 for e in sharp_at.get(v, ()))}
    if mode == "none":
        return pinned
    if mode == "boundaries":
        return pinned | on_seam
    corner = {v for v in on_seam if len(faces_of[v]) == 1}
    pinned |= corner
    if mode == "corners_only":
        return pinned
    disjoint = {v for v in vert_of if len(sharp_at.get(v, ())) > 2}
    if mode == "corners_plus2":
        disjoint |= corner
        pinned |= {v for v in on_seam if len(values_of[vert_of[v]]) == 1
                   and vert_of[v] not in pos_boundary}
    for vals in values_of.values():
        if len(vals) >= 3 or (len(vals) == 2 and vals & disjoint):
            pinned |= vals
    return pinned


def refine_catmark(pos_faces, val_faces, values, pinned, creased_pos_edges=frozenset(),
                   linear=False):
    """One Catmark step of the value mesh (dense reference): returns child position
    faces, child value faces (corner order (v, e_next, f, e_prev)) and child values."""
    values = np.asarray(values, dtype=np.float64)
    val_edges = _edges(val_faces)
    vert_of = {v: p for pf, vf in zip(pos_faces, val_faces) for p, v in zip(pf, vf)}
    sharp = set()
    for e, fs in val_edges.items():
        a, b = tuple(e)
        if len(fs) != 2 or frozenset((vert_of[a], vert_of[b])) in creased_pos_edges or linear:
            sharp.add(e)
    fpt = {f: values[vf].mean(0) for f, vf in enumerate(val_faces)}
    ept = {}
    for e, fs in val_edges.items():
        a, b = tuple(e)
        ept[e] = ((values[a] + values[b]) / 2 if e in sharp
                  else (values[a] + values[b] + fpt[fs[0]] + fpt[fs[1]]) / 4)
    vpt = {}
    for v in vert_of:
        inc = [e for e in val_edges if v in e]
        sh = [e for e in inc if e in sharp]
        if v in pinned or len(sh) > 2 or linear:
            vpt[v] = values[v]
        elif len(sh) == 2:
            a, b = (next(iter(e - {v})) for e in sh)
            vpt[v] = 0.75 * values[v] + 0.125 * (values[a] + values[b])
        else:
            n = len(inc)
            fs = [f for f, vf in enumerate(val_faces) if v in vf]
            e_sum = sum(values[next(iter(e - {v}))] for e in inc)
            f_sum = sum(fpt[f] for f in fs)
            vpt[v] = (n - 2) / n * values[v] + e_sum / n**2 + f_sum / n**2
    ids_p, ids_v, out = {}, {}, []

    def pid(key):
        return ids_p.setdefault(key, len(ids_p))

    def vid(key, value):
        if key not in ids_v:
            ids_v[key] = len(ids_v)
            out.append(value)
        return ids_v[key]

    child_p, child_v = [], []
    for f, (pf, vf) in enumerate(zip(pos_faces, val_faces)):
        n = len(pf)
        for k in range(n):
            pe_n, pe_p = frozenset((pf[k], pf[(k + 1) % n])), frozenset((pf[k], pf[k - 1]))
            ve_n, ve_p = frozenset((vf[k], vf[(k + 1) % n])), frozenset((vf[k], vf[k - 1]))
            child_p.append([pid(("v", pf[k])), pid(("e", pe_n)), pid(("f", f)),
                            pid(("e", pe_p))])
            child_v.append([vid(("v", vf[k]), vpt[vf[k]]), vid(("e", ve_n), ept[ve_n]),
                            vid(("f", f), fpt[f]), vid(("e", ve_p), ept[ve_p])])
    return child_p, child_v, np.array(out)


def child_creases(pos_faces, creased):
    """Children of infinitely sharp position edges, in the reference's corner ids."""
    ids = {}
    pid = lambda key: ids.setdefault(key, len(ids))  # noqa: E731
    out = set()
    for f, pf in enumerate(pos_faces):
        n = len(pf)
        for k in range(n):
            pid(("v", pf[k]))
            pid(("e", frozenset((pf[k], pf[(k + 1) % n]))))
            pid(("f", f))
            pid(("e", frozenset((pf[k], pf[k - 1]))))
    for e in creased:
        for v in e:
            out.add(frozenset((ids[("v", v)], ids[("e", e)])))
    return frozenset(out)


def reference(pos_faces, val_faces, values, mode, levels, creased=frozenset(),
              corner_verts=frozenset()):
    """``levels`` Catmark steps of the reference; returns ``values[faces]`` (F, 4, D)."""
    vals = np.asarray(values, dtype=np.float64)
    for _ in range(levels):
        pins = pinned_values(pos_faces, val_faces, mode, creased, corner_verts)
        new_p, new_v, vals = refine_catmark(pos_faces, val_faces, vals, pins, creased,
                                            linear=mode == "all")
        # infinitely sharp tags keep their children: vertex ids of "v" children are
        # the first ids handed out per vertex in corner order, as in refine_catmark
        creased = child_creases(pos_faces, creased)
        ids = {}
        for f, pf in enumerate(pos_faces):
            for k, p in enumerate(pf):
                ids.setdefault(p, new_p[sum(len(x) for x in pos_faces[:f]) + k][0])
        corner_verts = frozenset(ids[p] for p in corner_verts)
        pos_faces, val_faces = new_p, new_v
    return vals[np.array(val_faces)]


def ours(faces, uv_faces, V, uvs, mode, levels, tags=None, scheme="catmark"):
    fv = FaceVaryingSubdivision(faces, uv_faces, V, uvs.shape[0], levels=levels, tags=tags,
                                scheme=scheme, dtype=torch.float64,
                                options=SchemeOptions(fvar_interpolation=mode))
    return fv(uvs)[fv.faces].numpy(), fv


MODES = ["none", "corners_only", "corners_plus1", "corners_plus2", "boundaries", "all"]


# ----------------------------------------------------------------------------- tests


@pytest.mark.parametrize("mode", MODES)
def test_torus_with_seams_matches_reference_two_levels(mode):
    faces, uv_faces, V, uvs = torus_grid(4, 3)
    got, _ = ours(faces, uv_faces, V, uvs, mode, 2)
    want = reference(faces, uv_faces, uvs.numpy(), mode, 2)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("mode", MODES)
def test_cube_cross_layout_matches_reference(mode):
    # a cross-shaped UV layout: seams on 7 of the 12 cube edges
    seams = {frozenset(e) for e in [(0, 1), (1, 5), (4, 5), (2, 3), (3, 7), (6, 7), (1, 3)]}
    uv_faces, T = seam_values(CUBE_F, seams)
    uvs = torch.rand(T, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    got, _ = ours(CUBE_F, uv_faces, 8, uvs, mode, 2)
    want = reference(CUBE_F, uv_faces, uvs.numpy(), mode, 2)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(seam_bits=st.integers(0, 2**24 - 1), mode=st.sampled_from(MODES),
       mesh=st.sampled_from(["torus", "grid"]))
def test_random_seams_match_reference(seam_bits, mode, mesh):
    if mesh == "torus":
        faces, _, V, _ = torus_grid(4, 4)
    else:
        faces, V = open_grid(3)
    edges = sorted(_edges(faces), key=sorted)
    seams = {e for i, e in enumerate(edges) if seam_bits >> (i % 24) & 1 and i < 24}
    uv_faces, T = seam_values(faces, seams)
    uvs = torch.rand(T, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(T))
    got, _ = ours(faces, uv_faces, V, uvs, mode, 1)
    want = reference(faces, uv_faces, uvs.numpy(), mode, 1)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("mode", ["none", "corners_only", "boundaries"])
def test_infinite_crease_and_corner_tags_carry_to_values(mode):
    faces, uv_faces, V, uvs = torus_grid(4, 4)
    creased = [(5, 6), (6, 7)]  # an interior crease path, not on a seam
    tags = SubdivisionTags.empty(torch.float64)._replace(
        creases=torch.tensor(creased), crease_sharpness=torch.tensor([10.0, 10.0],
                                                                     dtype=torch.float64),
        corners=torch.tensor([10]), corner_sharpness=torch.tensor([10.0], dtype=torch.float64))
    got, _ = ours(faces, uv_faces, V, uvs, mode, 2, tags=tags)
    want = reference(faces, uv_faces, uvs.numpy(), mode, 2,
                     creased=frozenset(frozenset(e) for e in creased),
                     corner_verts=frozenset([10]))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("mode", ["none", "corners_only", "boundaries", "corners_plus2"])
@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_no_seam_equals_vertex_operator(mode, scheme):
    """uv_faces == faces on a closed mesh: the value operator is the position operator,
    with the same tags (semi-sharp too), and the child faces are identical."""
    faces, V = (CUBE_F, 8) if scheme == "catmark" else (OCTA_F, 6)
    tags = SubdivisionTags.empty(torch.float64)._replace(
        creases=torch.tensor([[0, 2]]), crease_sharpness=torch.tensor([1.7], dtype=torch.float64),
        corners=torch.tensor([1]), corner_sharpness=torch.tensor([0.5], dtype=torch.float64))
    build = catmull_clark_operator if scheme == "catmark" else loop_operator
    pos = build(faces, V, dtype=torch.float64, tags=tags)
    fv = face_varying_operator(faces, faces, V, V, scheme=scheme,
                               options=SchemeOptions(fvar_interpolation=mode), tags=tags,
                               dtype=torch.float64)
    torch.testing.assert_close(fv.stencils.dense(), pos.stencils.dense(), rtol=0, atol=1e-15)
    assert torch.equal(fv.faces, pos.faces)


def test_no_seam_open_grid_boundary_modes():
    """Open mesh, no seam: "none" is the position operator with edge_only, "corners_only"
    pins the mesh corners like edge_and_corner (OpenSubdiv sharpens fvar corners), and
    geometric corners pinned by boundary="edge_and_corner" stay pinned in "none"."""
    faces, V = open_grid(3)
    cases = (("none", "edge_only", "edge_only"), ("corners_only", "edge_only", "edge_and_corner"),
             ("none", "edge_and_corner", "edge_and_corner"))
    for mode, geometry, boundary in cases:
        pos = catmull_clark_operator(faces, V,
                                     options=SchemeOptions(boundary=boundary), dtype=torch.float64)
        fv = face_varying_operator(faces, faces, V, V, dtype=torch.float64,
                                   options=SchemeOptions(fvar_interpolation=mode,
                                                         boundary=geometry))
        torch.testing.assert_close(fv.stencils.dense(), pos.stencils.dense(), rtol=0, atol=0)


def test_all_is_bilinear():
    faces, uv_faces, V, uvs = torus_grid(3, 3)
    fv = face_varying_operator(faces, uv_faces, V, uvs.shape[0],
                               options=SchemeOptions(fvar_interpolation="all"),
                               dtype=torch.float64)
    bil = bilinear_operator(uv_faces, uvs.shape[0], dtype=torch.float64)
    torch.testing.assert_close(fv.stencils.dense(), bil.stencils.dense(), rtol=0, atol=0)
    loop = face_varying_operator(OCTA_F, OCTA_F, 6, 6, scheme="loop",
                                 options=SchemeOptions(fvar_interpolation="all"),
                                 dtype=torch.float64)
    pts = torch.randn(6, 3, dtype=torch.float64)
    out = apply_operator(loop, pts)
    edges = sorted({tuple(sorted((f[k], f[(k + 1) % 3]))) for f in OCTA_F for k in range(3)})
    want = torch.cat([pts, torch.stack([(pts[a] + pts[b]) / 2 for a, b in edges])])
    torch.testing.assert_close(out, want, rtol=0, atol=1e-15)


def test_loop_seam_matches_dense_reference():
    """Loop on the octahedron with a seam along the path 0-4-1: dense reference."""
    seams = {frozenset((0, 4)), frozenset((4, 1))}
    uv_faces, T = seam_values(OCTA_F, seams)
    uvs = torch.rand(T, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    op = face_varying_operator(OCTA_F, uv_faces, 6, T, scheme="loop",
                               options=SchemeOptions(fvar_interpolation="none"),
                               dtype=torch.float64)
    got = apply_operator(op, uvs)[op.faces].numpy()
    # reference: the value mesh, boundaries (seams) use the crease rules
    vals = uvs.numpy()
    edges = _edges(uv_faces)
    beta = lambda n: (0.625 - (0.375 + 0.25 * math.cos(2 * math.pi / n)) ** 2) / n  # noqa: E731
    child = {}
    for v in range(T):
        inc = [e for e in edges if v in e]
        sh = [e for e in inc if len(edges[e]) == 1]
        nb = [next(iter(e - {v})) for e in inc]
        if len(sh) == 2:
            child[("v", v)] = 0.75 * vals[v] + 0.125 * sum(vals[next(iter(e - {v}))] for e in sh)
        else:
            n = len(inc)
            child[("v", v)] = (1 - n * beta(n)) * vals[v] + beta(n) * sum(vals[w] for w in nb)
    for e, fs in edges.items():
        a, b = tuple(e)
        if len(fs) == 1:
            child[("e", e)] = (vals[a] + vals[b]) / 2
        else:
            opp = [next(iter(set(uv_faces[f]) - e)) for f in fs]
            child[("e", e)] = 0.375 * (vals[a] + vals[b]) + 0.125 * (vals[opp[0]] + vals[opp[1]])
    want = []
    for f in uv_faces:
        e = [frozenset((f[k], f[(k + 1) % 3])) for k in range(3)]
        v = [child[("v", x)] for x in f]
        ce = [child[("e", x)] for x in e]
        want += [[v[0], ce[0], ce[2]], [v[1], ce[1], ce[0]], [v[2], ce[2], ce[1]], ce]
    np.testing.assert_allclose(got, np.array(want), rtol=0, atol=1e-12)


def test_child_faces_line_up_with_positions():
    """Every child value belongs to one child vertex, and holes drop the same faces."""
    faces, uv_faces, V, _ = torus_grid(4, 3)
    tags = SubdivisionTags.empty()._replace(holes=torch.tensor([2, 7]))
    pos = catmull_clark_operator(faces, V, tags=tags)
    fv = face_varying_operator(faces, uv_faces, V, 20, tags=tags)
    assert fv.faces.shape == pos.faces.shape == (40, 4)
    pairs = torch.stack([fv.faces.flatten(), pos.faces.flatten()], 1).unique(dim=0)
    assert pairs[:, 0].unique().numel() == pairs.shape[0]  # value -> one vertex


@pytest.mark.parametrize("boundary", ["none", "edge_and_corner"])
def test_levels_line_up_with_position_module(boundary):
    """Across 2 levels, with boundary "none" (boundary faces become holes) and with a
    semi-sharp crease decaying: same faces kept, each child value on one child vertex."""
    from torchgeo_cg.mesh import CatmullClark

    faces, V = open_grid(4)
    seams = {frozenset((6, 7)), frozenset((7, 8)), frozenset((7, 12))}
    uv_faces, T = seam_values(faces, seams)
    tags = SubdivisionTags.empty()._replace(creases=torch.tensor([[11, 12]]),
                                            crease_sharpness=torch.tensor([1.5]))
    cc = CatmullClark(faces, V, levels=2, options=SchemeOptions(boundary=boundary), tags=tags)
    fv = FaceVaryingSubdivision(faces, uv_faces, V, T, levels=2,
                                options=SchemeOptions(boundary=boundary), tags=tags)
    assert fv.faces.shape == cc.faces.shape and fv.faces.shape[0] > 0
    pairs = torch.stack([fv.faces.flatten(), cc.faces.flatten()], 1).unique(dim=0)
    assert pairs[:, 0].unique().numel() == pairs.shape[0]


def test_uv_index_shared_by_two_vertices_is_split():
    """OpenSubdiv: a value belongs to a vertex. Reusing one UV index at two vertices
    gives the same result as two copies of it."""
    faces, uv_faces, V, uvs = torus_grid(4, 3)
    # uv 5 sits at vertex 4 and uv 0 at vertex 0: let vertex 4 use uv 0 instead
    shared = [[0 if x == 5 else x for x in f] for f in uv_faces]
    copied = uvs.clone()
    copied[5] = uvs[0]
    for mode in ("none", "corners_only"):
        a = face_varying_subdivide(uvs, faces, shared, V, levels=2,
                                   options=SchemeOptions(fvar_interpolation=mode))
        b = face_varying_subdivide(copied, faces, uv_faces, V, levels=2,
                                   options=SchemeOptions(fvar_interpolation=mode))
        np.testing.assert_allclose(a[0][a[1]].numpy(), b[0][b[1]].numpy(), rtol=0,
                                   atol=1e-12)
    op = face_varying_operator(faces, shared, V, 20)
    assert op.num_vertices_in == 20 and op.stencils.shape[1] == 20


def test_module_function_defaults_agree_and_to_deepcopy():
    import inspect

    sig_m = inspect.signature(FaceVaryingSubdivision.__init__).parameters
    sig_f = inspect.signature(face_varying_subdivide).parameters
    sig_o = inspect.signature(face_varying_operator).parameters
    for name in ("levels", "scheme", "tags", "options"):
        assert sig_m[name].default == sig_f[name].default
        if name in sig_o:
            assert sig_o[name].default == sig_m[name].default
    faces, uv_faces, V, uvs = torus_grid(3, 3)
    fv = FaceVaryingSubdivision(faces, uv_faces, V, 16, levels=2)
    out, out_f = face_varying_subdivide(uvs, faces, uv_faces, V, levels=2)
    torch.testing.assert_close(fv.to(torch.float64)(uvs), out)
    assert torch.equal(fv.faces, out_f)
    torch.testing.assert_close(copy.deepcopy(fv)(uvs), out)
    assert fv.state_dict() == {}  # buffers are derived, non-persistent


@pytest.mark.grad
def test_gradcheck_and_batch():
    faces, uv_faces, V, uvs = torus_grid(3, 3)
    fv = FaceVaryingSubdivision(faces, uv_faces, V, 16, levels=1, dtype=torch.float64)
    x = uvs.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(fv, (x,))
    batch = torch.randn(3, 16, 2, dtype=torch.float64)
    torch.testing.assert_close(fv(batch)[1], fv(batch[1]))


def test_empty_and_nan():
    op = face_varying_operator(torch.zeros(0, 4, dtype=torch.long),
                               torch.zeros(0, 4, dtype=torch.long), 0, 0)
    assert op.faces.shape[0] == 0 and op.num_vertices_out == 0
    faces, uv_faces, V, uvs = torus_grid(3, 3)
    uvs = uvs.clone()
    uvs[0, 0] = float("nan")
    out = face_varying_subdivide(uvs, faces, uv_faces, V)[0]
    assert torch.isnan(out).any() and torch.isfinite(out).any()


def test_errors_name_the_argument():
    faces, uv_faces, V, _ = torus_grid(3, 3)
    with pytest.raises(ValueError, match="interpolation"):
        face_varying_operator(faces, uv_faces, V, 16,
                              options=SchemeOptions(fvar_interpolation="linear"))
    with pytest.raises(ValueError, match="scheme"):
        face_varying_operator(faces, uv_faces, V, 16, scheme="bilinear")
    with pytest.raises(ValueError, match="uv_faces: face 0 has index 16"):
        face_varying_operator(faces, [[16, 1, 2, 3]] + uv_faces[1:], V, 16)
    with pytest.raises(ShapeError, match="uv_faces"):
        face_varying_operator(faces, uv_faces[:-1], V, 16)
    with pytest.raises(ValueError, match="uv_faces: face 1 has 3 values"):
        face_varying_operator(faces, [uv_faces[0], uv_faces[1][:3]] + uv_faces[2:], V, 16)
    with pytest.raises(ValueError, match="num_uvs"):
        face_varying_operator(faces, uv_faces, V, -1)
    with pytest.raises(ValueError, match="levels"):
        FaceVaryingSubdivision(faces, uv_faces, V, 16, levels=-1)


def test_integer_uvs_raise_type_error():
    """Integer uvs are rejected up front with a TypeError naming ``uvs`` (the sparse
    matmul would raise a raw NotImplementedError)."""
    uvs = torch.zeros(4, 2, dtype=torch.long)
    with pytest.raises(TypeError, match="uvs: expected a floating-point tensor"):
        face_varying_subdivide(uvs, [[0, 1, 2, 3]], [[0, 1, 2, 3]], 4)
    module = FaceVaryingSubdivision([[0, 1, 2, 3]], [[0, 1, 2, 3]], 4, 4)
    with pytest.raises(TypeError, match="uvs: expected a floating-point tensor"):
        module(uvs)
    assert module.double()(uvs.double()).dtype == torch.float64  # state and input share one dtype
