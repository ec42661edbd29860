"""Creases, corners, holes, boundary modes and non-manifold rules against an
independent dense reference written here from OpenSubdiv's documented rules
(``Sdc::Crease``, ``Sdc::Scheme::ComputeEdgeVertexMask`` / ``ComputeVertexVertexMask``,
``Far::TopologyRefinerFactoryBase::prepareComponentTagsAndSharpness``): plain Python,
one vertex at a time, dictionaries for the topology, a dense matrix per level."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.mesh import (
    CatmullClark,
    LoopSubdivision,
    SubdivisionTags,
    bilinear_operator,
    catmull_clark,
    catmull_clark_operator,
    loop_operator,
    loop_subdivide,
)
from torchgeo_cg.mesh.subdivision import SchemeOptions

INF = 10.0

# ----------------------------------------------------------------------------- reference


def _decrement(s):
    if s <= 0:
        return 0.0
    if s >= INF:
        return INF
    return s - 1.0 if s > 1.0 else 0.0


def _topology(faces):
    """Edges (sorted keys), their faces with direction, and per-vertex incident lists."""
    edge_faces: dict[tuple[int, int], list[tuple[int, bool]]] = {}
    for f, face in enumerate(faces):
        for k in range(len(face)):
            a, b = face[k], face[(k + 1) % len(face)]
            edge_faces.setdefault((min(a, b), max(a, b)), []).append((f, a < b))
    return sorted(edge_faces), edge_faces


def _fans(v, faces, vfaces, edge_faces, manifold):
    """Number of connected face fans around ``v`` (depth-first search)."""
    seen, fans = set(), 0
    for start in vfaces:
        if start in seen:
            continue
        fans += 1
        stack = [start]
        while stack:
            f = stack.pop()
            if f in seen:
                continue
            seen.add(f)
            face = faces[f]
            k = face.index(v)
            for u in (face[(k + 1) % len(face)], face[k - 1]):
                key = (min(u, v), max(u, v))
                if manifold[key]:
                    stack.extend(g for g, _ in edge_faces[key] if g != f)
    return fans


def _sharpness(faces, V, tags, boundary, inherited=None):
    """Effective sharpness. ``inherited`` (a refined level: the parent's non-manifold
    edges' children and non-manifold-sharpened vertices) replaces the base level's
    derivation from the topology, as OpenSubdiv's refinement inherits its tags."""
    edges, edge_faces = _topology(faces)
    count = {e: len(edge_faces[e]) for e in edges}
    inconsistent = {e: count[e] == 2 and edge_faces[e][0][1] == edge_faces[e][1][1]
                    for e in edges}
    nonman = {e: count[e] > 2 or inconsistent[e] for e in edges}
    if inherited is not None:
        nonman = {e: nonman[e] or e in inherited["edges"] for e in edges}
    manifold = {e: count[e] == 2 and not inconsistent[e] for e in edges}
    v_edges = {v: [] for v in range(V)}
    for e in edges:
        v_edges[e[0]].append(e)
        v_edges[e[1]].append(e)
    v_faces = {v: [f for f, face in enumerate(faces) if v in face] for v in range(V)}
    holes = set(tags.get("holes", ()))
    crease_tag = {(min(a, b), max(a, b)): s for (a, b), s in tags.get("creases", {}).items()}
    if boundary == "none":
        for v in range(V):
            if any(count[e] == 1 and crease_tag.get(e, 0.0) < INF for e in v_edges[v]):
                holes.update(v_faces[v])
    es = {e: (INF if count[e] == 1 or nonman[e] else crease_tag.get(e, 0.0)) for e in edges}
    vs, nm_sharp = {}, set()
    for v in range(V):
        s = tags.get("corners", {}).get(v, 0.0)
        n_e, n_f = len(v_edges[v]), len(v_faces[v])
        n_nm = sum(nonman[e] for e in v_edges[v])
        n_b = sum(count[e] == 1 for e in v_edges[v])
        if inherited is not None:
            sharpened = v in inherited["vertices"]
        else:
            nonmanifold_v = n_nm > 0 or (n_f and _fans(v, faces, v_faces[v], edge_faces,
                                                        manifold) > 1)
            sharpened = nonmanifold_v and not (n_nm == 2 and n_b == 0 and n_f > n_e)
        if sharpened:
            s = INF
            nm_sharp.add(v)
        if boundary == "edge_and_corner" and n_f == 1 and n_e == 2:
            s = INF
        if n_e == 0:
            s = INF
        vs[v] = s
    nm_edges = {e for e in edges if nonman[e] and count[e] > 1}
    return edges, edge_faces, v_edges, v_faces, es, vs, holes, crease_tag, nm_edges, nm_sharp


def _child_edge_sharpness(e, v, es, v_edges, method):
    """Sharpness of the child of edge ``e`` at its end ``v``."""
    s = es[e]
    if method == "uniform" or len(v_edges[v]) < 2 or s <= 0 or s >= INF:
        return _decrement(s)
    semi = [es[x] for x in v_edges[v] if 0 < es[x] < INF]
    if len(semi) <= 1:
        return _decrement(s)
    avg = (sum(semi) - s) / (len(semi) - 1)
    c = 0.75 * s + 0.25 * avg - 1.0
    return c if c > 0 else 0.0


def _rule(vsharp, edge_sharpness):
    if vsharp > 0:
        return "corner"
    n = sum(s > 0 for s in edge_sharpness)
    return "smooth" if n < 2 else ("crease" if n == 2 else "corner")


def _vertex_mask(v, rule, sharp_of, smooth_mask):
    """Mask (dict col -> weight) of vertex ``v`` for one rule."""
    if rule == "smooth":
        return smooth_mask
    if rule == "corner":
        return {v: 1.0}
    ends = [u for u, s in sharp_of if s > 0]
    mask = {v: 0.75}
    for u in ends:
        mask[u] = mask.get(u, 0.0) + 0.125
    return mask


def _blend(a, b, wa):
    out = {}
    for k, x in a.items():
        out[k] = out.get(k, 0.0) + wa * x
    for k, x in b.items():
        out[k] = out.get(k, 0.0) + (1 - wa) * x
    return out


def reference_level(verts_count, faces, tags, boundary, method, scheme, triangle_rule="catmark",
                    inherited=None):
    """One level: dense ``(V1, V0)`` matrix, child faces (all), visible faces, child tags
    and what the children inherit."""
    V = verts_count
    F = len(faces)
    edges, edge_faces, v_edges, v_faces, es, vs, holes, crease_tag, nm_edges, nm_sharp = (
        _sharpness(faces, V, tags, boundary, inherited))
    E = len(edges)
    eid = {e: i for i, e in enumerate(edges)}
    V1 = V + (F if scheme == "catmark" else 0) + E
    row_edge = V + (F if scheme == "catmark" else 0)
    S = np.zeros((V1, V))

    def face_point(f):
        return {u: 1.0 / len(faces[f]) for u in faces[f]}

    if scheme == "catmark":
        for f in range(F):
            for u, x in face_point(f).items():
                S[V + f, u] += x
    for e in edges:
        a, b = e
        if len(edge_faces[e]) == 2:
            if scheme == "catmark":
                tri = [len(faces[f]) == 3 for f, _ in edge_faces[e]]
                fw = 0.25
                if triangle_rule == "smooth" and any(tri):  # TRI_SUB_SMOOTH
                    fw = 0.5 * sum(0.47 if t else 0.25 for t in tri)
                smooth = {a: 0.5 * (1 - 2 * fw), b: 0.5 * (1 - 2 * fw)}
                for f, _ in edge_faces[e]:
                    for u, x in face_point(f).items():
                        smooth[u] = smooth.get(u, 0.0) + fw * x
            else:
                smooth = {a: 0.375, b: 0.375}
                for f, _ in edge_faces[e]:
                    (opp,) = [u for u in faces[f] if u not in e]
                    smooth[opp] = smooth.get(opp, 0.0) + 0.125
        else:
            smooth = None
        s = es[e]
        crease = {a: 0.5, b: 0.5}
        if s <= 0:
            mask = smooth
        elif s >= 1 or (method == "chaikin" and _child_edge_sharpness(e, a, es, v_edges, method)
                        > 0 and _child_edge_sharpness(e, b, es, v_edges, method) > 0):
            mask = crease
        else:
            mask = _blend(crease, smooth, s)
        for u, x in mask.items():
            S[row_edge + eid[e], u] += x
    for v in range(V):
        n = len(v_edges[v])
        nbrs = [(e[0] if e[1] == v else e[1]) for e in v_edges[v]]
        if n == 0:
            S[v, v] = 1.0
            continue
        if scheme == "catmark":
            smooth = {v: (n - 2) / n}
            for u in nbrs:
                smooth[u] = smooth.get(u, 0.0) + 1.0 / n**2
            for f in v_faces[v]:
                for u, x in face_point(f).items():
                    smooth[u] = smooth.get(u, 0.0) + x / n**2
        else:
            beta = (5 / 8 - (3 / 8 + 1 / 4 * math.cos(2 * math.pi / n)) ** 2) / n
            smooth = {v: 1 - n * beta}
            for u in nbrs:
                smooth[u] = smooth.get(u, 0.0) + beta
        parent_sharp = [(u, es[e]) for u, e in zip(nbrs, v_edges[v])]
        child_sharp = [(u, _child_edge_sharpness(e, v, es, v_edges, method))
                       for u, e in zip(nbrs, v_edges[v])]
        cvs = _decrement(vs[v])
        p_rule = _rule(vs[v], [s for _, s in parent_sharp])
        mask = _vertex_mask(v, p_rule, parent_sharp, smooth)
        if p_rule != "smooth":
            c_rule = _rule(cvs, [s for _, s in child_sharp])
            if c_rule != p_rule:  # ComputeFractionalWeightAtVertex
                total, cnt = 0.0, 0
                if vs[v] > 0 and cvs <= 0:
                    total, cnt = vs[v], 1
                for (_, ps), (_, cs) in zip(parent_sharp, child_sharp):
                    decays = ps <= 1.0 if method == "uniform" else cs <= 0
                    if ps > 0 and decays:
                        total, cnt = total + ps, cnt + 1
                w = min(total / cnt, 1.0) if cnt else 0.0
                mask = _blend(mask, _vertex_mask(v, c_rule, child_sharp, smooth), w)
        for u, x in mask.items():
            S[v, u] += x
    # child faces and tags
    child_faces, hole_child = [], []
    for f, face in enumerate(faces):
        k = len(face)
        ep = [row_edge + eid[(min(face[i], face[(i + 1) % k]), max(face[i], face[(i + 1) % k]))]
              for i in range(k)]
        if scheme == "catmark":
            kids = [[face[i], ep[i], V + f, ep[i - 1]] for i in range(k)]
        else:
            kids = [[face[0], ep[0], ep[2]], [face[1], ep[1], ep[0]], [face[2], ep[2], ep[1]],
                    ep]
        child_faces += kids
        hole_child += [f in holes] * len(kids)
    creases = {}
    for e, tag in crease_tag.items():
        if tag <= 0:
            continue
        p = row_edge + eid[e]
        for end, pair in ((e[0], (e[0], p)), (e[1], (p, e[1]))):
            cs = _child_edge_sharpness(e, end, es, v_edges, method)
            if cs > 0:
                creases[pair] = cs
    corners = {v: _decrement(s) for v, s in tags.get("corners", {}).items() if _decrement(s) > 0}
    child = {"creases": creases, "corners": corners,
             "holes": [i for i, h in enumerate(hole_child) if h]}
    visible = [c for c, h in zip(child_faces, hole_child) if not h]
    kids = {"edges": {(min(e[i], p), max(e[i], p)) for e in nm_edges
                      for i, p in ((0, row_edge + eid[e]), (1, row_edge + eid[e]))},
            "vertices": nm_sharp}
    return S, child_faces, visible, child, kids


def reference_levels(V, faces, tags, boundary, method, scheme, levels, triangle_rule="catmark"):
    out, inherited = [], None
    for level in range(levels):
        S, child_faces, visible, tags, inherited = reference_level(
            V, faces, tags, boundary if level == 0 else
            ("edge_only" if boundary == "none" else boundary), method, scheme, triangle_rule,
            inherited)
        out.append((S, visible))
        V, faces = S.shape[0], child_faces
    return out


def _tags_tensor(tags, dtype=torch.float64):
    creases = list(tags.get("creases", {}).items())
    corners = list(tags.get("corners", {}).items())
    return SubdivisionTags(
        torch.tensor([list(c) for c, _ in creases], dtype=torch.long).reshape(-1, 2),
        torch.tensor([s for _, s in creases], dtype=dtype),
        torch.tensor([c for c, _ in corners], dtype=torch.long),
        torch.tensor([s for _, s in corners], dtype=dtype),
        torch.tensor(sorted(tags.get("holes", ())), dtype=torch.long),
    )


def _check_against_reference(module_cls, V, faces, tags, boundary, method, scheme, levels,
                             **options):
    module = module_cls(faces, V, levels=levels, dtype=torch.float64, tags=_tags_tensor(tags),
                        options=SchemeOptions(boundary=boundary, crease_method=method, **options))
    expected = reference_levels(V, faces, tags, boundary, method, scheme, levels, **options)
    for level, (S, visible) in enumerate(expected):
        op = module.operator(level)
        assert_close(op.matrix.to_dense(), torch.from_numpy(S), rtol=0, atol=1e-13)
        assert op.faces.tolist() == visible
    return module


# ----------------------------------------------------------------------------- meshes

CUBE_V = torch.tensor([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)],
                      dtype=torch.float64)
CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
OCTA_V = torch.tensor([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                      dtype=torch.float64)
OCTA_F = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5],
          [0, 3, 5]]
GRID_F = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]]  # 3x3 vertices, open


# ----------------------------------------------------------------------------- tests


@pytest.mark.parametrize("sharpness", [0.5, 1.0, 2.3, INF])
@pytest.mark.parametrize("method", ["uniform", "chaikin"])
def test_cube_creases_three_levels_match_reference(sharpness, method):
    tags = {"creases": {(0, 1): sharpness, (1, 3): sharpness, (3, 2): 0.7 * sharpness,
                        (4, 5): 1.6}}
    _check_against_reference(CatmullClark, 8, CUBE_F, tags, "edge_only", method, "catmark", 3)


@pytest.mark.parametrize("method", ["uniform", "chaikin"])
def test_octahedron_loop_creases_and_corner_match_reference(method):
    tags = {"creases": {(0, 2): 2.3, (2, 1): 0.5, (1, 3): INF, (3, 0): 1.0},
            "corners": {4: 1.5}}
    _check_against_reference(LoopSubdivision, 6, OCTA_F, tags, "edge_only", method, "loop", 3)


@pytest.mark.parametrize("sharpness", [0.4, 2.0, INF])
def test_cube_corners_match_reference(sharpness):
    tags = {"corners": {0: sharpness, 7: 1.0}, "creases": {(0, 4): 0.6}}
    _check_against_reference(CatmullClark, 8, CUBE_F, tags, "edge_only", "uniform", "catmark",
                             3)


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_holes_have_no_children_but_keep_the_rules(scheme):
    crease = {(0, 1): 1.5} if scheme == "catmark" else {(0, 2): 1.5}
    tags = {"holes": [1], "creases": crease}
    if scheme == "catmark":
        module = _check_against_reference(CatmullClark, 8, CUBE_F, tags, "edge_only", "uniform",
                                          scheme, 2)
        untagged = CatmullClark(CUBE_F, 8, levels=2, dtype=torch.float64,
                                tags=_tags_tensor({"creases": crease}))
        per_face = 16
    else:
        module = _check_against_reference(LoopSubdivision, 6, OCTA_F, tags, "edge_only",
                                          "uniform", scheme, 2)
        untagged = LoopSubdivision(OCTA_F, 6, levels=2, dtype=torch.float64,
                                   tags=_tags_tensor({"creases": crease}))
        per_face = 16
    verts = CUBE_V if scheme == "catmark" else OCTA_V
    # the positions are those of the mesh without the hole; only the faces go
    assert_close(module(verts), untagged(verts), rtol=0, atol=0)
    assert module.faces.shape[0] == untagged.faces.shape[0] - per_face
    kept = {tuple(f) for f in module.faces.tolist()}
    assert kept < {tuple(f) for f in untagged.faces.tolist()}


@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner", "none"])
@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_three_boundary_modes_match_reference(boundary, scheme):
    if scheme == "catmark":
        faces, V, cls = GRID_F, 9, CatmullClark
    else:
        faces = [[a, b, c] for a, b, c, d in GRID_F] + [[a, c, d] for a, b, c, d in GRID_F]
        V, cls = 9, LoopSubdivision
    tags = {"creases": {(0, 1): INF, (1, 2): INF}} if boundary == "none" else {}
    module = _check_against_reference(cls, V, faces, tags, boundary, "uniform", scheme, 2)
    if boundary == "none":
        # every face touches a vertex with an untagged boundary edge: all are holes
        assert module.faces.shape[0] == 0


def test_boundary_none_keeps_interior_faces():
    """A 4x4 grid: with boundary "none" only the centre face has no boundary vertex."""
    faces = [[r * 4 + c, r * 4 + c + 1, r * 4 + c + 5, r * 4 + c + 4]
             for r in range(3) for c in range(3)]
    module = _check_against_reference(CatmullClark, 16, faces, {}, "none", "uniform",
                                      "catmark", 2)
    assert module.faces.shape[0] == 16  # the centre face's 4 children, twice refined


def test_cube_with_hanging_triangle_keeps_the_non_manifold_vertex():
    """OpenSubdiv keeps a non-manifold vertex fixed ((1, 1, 1) for vertex 7)."""
    verts = torch.cat([CUBE_V, torch.tensor([[2.0, 1.5, 1.0], [2.0, 2.0, 2.0]],
                                            dtype=torch.float64)])
    faces = [f + [-1] if len(f) == 3 else f for f in CUBE_F] + [[7, 8, 9, -1]]
    faces_lists = CUBE_F + [[7, 8, 9]]
    _check_against_reference(CatmullClark, 10, faces_lists, {}, "edge_only", "uniform",
                             "catmark", 2)
    out, _ = catmull_clark(verts, torch.tensor(faces))
    assert_close(out[7], verts[7], rtol=0, atol=0)


def test_octahedron_with_hanging_triangle_loop():
    """Loop on an octahedron with a triangle hanging from (0, 0, 1) keeps it."""
    verts = torch.cat([OCTA_V, torch.tensor([[0.5, 0.5, 2.0], [-0.5, 0.5, 2.0]],
                                            dtype=torch.float64)])
    faces = OCTA_F + [[4, 6, 7]]
    _check_against_reference(LoopSubdivision, 8, faces, {}, "edge_only", "uniform", "loop", 2)
    out, _ = loop_subdivide(verts, faces)
    assert_close(out[4], verts[4], rtol=0, atol=0)


def test_inconsistently_wound_edge_is_sharp():
    """Two quads traversing their shared edge in the same direction: the edge is sharp."""
    faces = [[0, 1, 4, 3], [1, 4, 5, 2]]  # edge (1, 4) runs 1 -> 4 in both faces
    g = torch.Generator().manual_seed(0)
    verts = torch.rand(6, 3, generator=g, dtype=torch.float64)
    op = catmull_clark_operator(faces, 6, dtype=torch.float64)
    out = op.matrix.to_dense() @ verts
    edge_row = 6 + 2 + sorted({(0, 1), (1, 4), (3, 4), (0, 3), (2, 5), (1, 2), (4, 5)}).index(
        (1, 4))
    assert_close(out[edge_row], (verts[1] + verts[4]) / 2)
    _check_against_reference(CatmullClark, 6, faces, {}, "edge_only", "uniform", "catmark", 2)
    consistent = catmull_clark_operator([[0, 1, 4, 3], [1, 2, 5, 4]], 6, dtype=torch.float64)
    assert not torch.allclose((consistent.matrix.to_dense() @ verts)[edge_row], out[edge_row])


def test_interior_non_manifold_crease_is_a_crease_not_a_corner():
    """Three quads fanning from a chain of edges: the interior vertex of the chain keeps the
    crease rule (OpenSubdiv's exception), the chain's ends are corners."""
    # spine 0-1-2 shared by three fins of two quads each: at vertex 1 the spine edges are
    # non-manifold (3 faces), no edge is a boundary, and 6 faces > 5 edges
    faces = []
    V = 3
    for _ in range(3):
        a, b, c = V, V + 1, V + 2  # the fin's outer edge
        faces += [[0, 1, b, a], [1, 2, c, b]]
        V += 3
    _check_against_reference(CatmullClark, V, faces, {}, "edge_only", "uniform", "catmark", 1)
    s = catmull_clark_operator(faces, V, dtype=torch.float64).matrix.to_dense()
    expected = torch.zeros(V, dtype=torch.float64)
    expected[1], expected[0], expected[2] = 0.75, 0.125, 0.125
    assert_close(s[1], expected)  # the crease rule along the spine
    assert_close(s[0], torch.eye(V, dtype=torch.float64)[0])  # spine end: a corner


def test_hand_derived_cube_crease_values():
    """Cube vertex 0 = (0,0,0), neighbours 1 (z), 2 (y), 4 (x); edges sorted: (0,1) is 0."""
    two = _tags_tensor({"creases": {(0, 1): INF, (0, 2): INF}})
    out = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64, tags=two).matrix.to_dense()
    # crease vertex: 3/4 V + 1/8 (a + b); infinitely sharp edge point: the midpoint
    assert_close(out[0] @ CUBE_V, torch.tensor([0.0, 0.125, 0.125], dtype=torch.float64))
    assert_close(out[14] @ CUBE_V, torch.tensor([0.0, 0.0, 0.5], dtype=torch.float64))
    three = _tags_tensor({"creases": {(0, 1): INF, (0, 2): INF, (0, 4): INF}})
    out = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64, tags=three).matrix.to_dense()
    assert_close(out[0] @ CUBE_V, CUBE_V[0])  # three sharp edges: a corner
    half = _tags_tensor({"creases": {(0, 1): 0.5}})
    out = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64, tags=half).matrix.to_dense()
    # semi-sharp 0.5: half the midpoint (0, 0, 1/2), half the smooth point; the smooth edge
    # point is (v0 + v1 + f0 + f1) / 4 with face points (0, 1/2, 1/2) and (1/2, 0, 1/2)
    smooth = (torch.tensor([0.0, 0, 0]) + torch.tensor([0.0, 0, 1]) + torch.tensor([0, 0.5, 0.5])
              + torch.tensor([0.5, 0, 0.5])) / 4
    expected = 0.5 * torch.tensor([0.0, 0.0, 0.5]) + 0.5 * smooth
    assert_close(out[14] @ CUBE_V, expected.double())
    # vertex 0 with one semi-sharp edge is a dart: the smooth rule, 5/9 of the way to centre
    assert_close(out[0] @ CUBE_V, torch.full((3,), 2 / 9, dtype=torch.float64))


def test_sharpness_zero_equals_untagged_exactly():
    for builder, faces, V in ((catmull_clark_operator, CUBE_F, 8), (loop_operator, OCTA_F, 6)):
        zero = {"creases": {(0, 1) if V == 8 else (0, 2): 0.0}, "corners": {3: 0.0}}
        tagged = builder(faces, V, dtype=torch.float64, tags=_tags_tensor(zero))
        plain = builder(faces, V, dtype=torch.float64)
        assert torch.equal(tagged.matrix.to_dense(), plain.matrix.to_dense())
        empty = builder(faces, V, dtype=torch.float64, tags=SubdivisionTags.empty())
        assert torch.equal(empty.matrix.to_dense(), plain.matrix.to_dense())


def test_sharpness_s_plus_one_decays_to_s():
    """Uniform rule: after one level, sharpness s + 1 is sharpness s on the children, so two
    levels from s + 1 then the second operator equal one level from the child tags."""
    tags = _tags_tensor({"creases": {(0, 1): 2.5, (1, 3): 2.5}})
    cc = CatmullClark(CUBE_F, 8, levels=2, dtype=torch.float64, tags=tags)
    child = cc.operator(0).child_tags
    assert_close(child.crease_sharpness, torch.full((4,), 1.5, dtype=torch.float64))
    op1 = cc.operator(1)
    again = catmull_clark_operator(cc.operator(0).child_faces, cc.operator(0).num_vertices_out,
                                   dtype=torch.float64, tags=child)
    assert torch.equal(op1.matrix.to_dense(), again.matrix.to_dense())
    # a crease of sharpness >= 1 is a full crease for the edge points of the first level
    for s in (1.0, 1.7, 3.0):
        op = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64,
                                    tags=_tags_tensor({"creases": {(0, 1): s}}))
        row = op.matrix.to_dense()[8 + 6 + 0]  # edge (0, 1) is edge 0
        assert_close(row[:2], torch.tensor([0.5, 0.5], dtype=torch.float64))


def test_bad_tags_name_the_problem():
    with pytest.raises(ValueError, match=r"tags.creases\[0\] = \(0, 7\) is not an edge"):
        catmull_clark_operator(CUBE_F, 8, tags=_tags_tensor({"creases": {(0, 7): 1.0}}))
    with pytest.raises(ValueError, match="tags.holes: index 6 out of range"):
        catmull_clark_operator(CUBE_F, 8, tags=_tags_tensor({"holes": [6]}))
    with pytest.raises(ValueError, match="crease_sharpness"):
        loop_operator(OCTA_F, 6, tags=_tags_tensor({"creases": {(0, 2): -1.0}}))
    with pytest.raises(ValueError, match="crease_method"):
        CatmullClark(CUBE_F, 8, options=SchemeOptions(crease_method="linear"))


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_limit_positions_with_sharp_tags(scheme):
    """Infinitely sharp closed crease loops and corners: the limit is invariant under
    refinement (the crease/corner masks apply), and semi-sharp tags are refused until they
    decay. (Darts, one sharp edge, get OpenSubdiv's smooth limit mask, which is not exact,
    so they are left out here.)"""
    from torchgeo_cg.mesh import apply_operator, limit_positions

    if scheme == "catmark":
        loop = [(0, 1), (1, 3), (3, 2), (2, 0)]  # around face 0
        cls, faces, verts = CatmullClark, CUBE_F, CUBE_V
    else:
        loop = [(0, 2), (2, 1), (1, 3), (3, 0)]  # the equator
        cls, faces, verts = LoopSubdivision, OCTA_F, OCTA_V
    crease = dict.fromkeys(loop, INF)
    tags = _tags_tensor({"creases": crease, "corners": {5 if scheme == "loop" else 7: INF}})
    module = cls(faces, verts.shape[0], levels=2, dtype=torch.float64, tags=tags)
    op0, op1 = module.operator(0), module.operator(1)
    first = limit_positions(op0, verts)
    second = limit_positions(op1, apply_operator(op0, verts))
    assert_close(second[: op0.num_vertices_out], first, rtol=1e-12, atol=1e-12)
    corner = 5 if scheme == "loop" else 7
    assert_close(first[corner], verts[corner])
    a, b = loop[0]
    prev = loop[-1][0]  # the crease neighbours of a are b and prev: the B-spline limit
    assert_close(first[a], (verts[prev] + 4 * verts[a] + verts[b]) / 6)
    semi = cls(faces, verts.shape[0], levels=1, dtype=torch.float64,
               tags=_tags_tensor({"creases": {(a, b): 2.5}}))
    with pytest.raises(ValueError, match="semi-sharp"):
        limit_positions(semi.operator(0), verts)


@pytest.mark.parametrize("triangle_rule", ["catmark", "smooth"])
def test_triangle_rule_matches_reference(triangle_rule):
    """A pyramid (four triangles on a quad) plus a triangle pair: OpenSubdiv's
    ``TRI_SUB_SMOOTH`` reweights smooth edges next to triangles (0.47 per triangle)."""
    faces = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4], [0, 3, 2, 1]]
    tags = {"creases": {(0, 1): 1.5}}
    module = _check_against_reference(CatmullClark, 5, faces, tags, "edge_only", "uniform",
                                      "catmark", 2, triangle_rule=triangle_rule)
    s = module.operator(0).matrix.to_dense()
    # edge (1, 4) between two triangles: hand-derived weights of its edge point
    row = s[5 + 5 + sorted({(0, 1), (1, 4), (1, 2), (2, 4), (2, 3), (3, 4), (0, 3), (0, 4)})
            .index((1, 4))]
    fw = 0.47 if triangle_rule == "smooth" else 0.25
    end = 0.5 * (1 - 2 * fw) + 2 * fw / 3  # its own weight plus a third of each face point
    assert_close(row[1], torch.tensor(end, dtype=torch.float64))
    assert_close(row[0], torch.tensor(fw / 3, dtype=torch.float64))  # opposite corners
    with pytest.raises(ValueError, match="triangle_rule"):
        catmull_clark_operator(faces, 5, options=SchemeOptions(triangle_rule="loop"))


def test_bilinear_operator_stays_on_the_control_polygons():
    from torchgeo_cg.mesh import bilinear_operator, limit_positions

    faces = [[0, 1, 4], [1, 2, 5, 4], [2, 3, 5]]
    g = torch.Generator().manual_seed(0)
    verts = torch.rand(6, 3, generator=g, dtype=torch.float64)
    op = bilinear_operator(faces, 6, dtype=torch.float64)
    out = op.matrix.to_dense() @ verts
    assert op.scheme == "bilinear"
    assert_close(out[:6], verts)  # vertex points stay
    for f, face in enumerate(faces):  # face points: centroids, written by hand
        assert_close(out[6 + f], verts[face].mean(0))
    edges = sorted({(min(f[i], f[(i + 1) % len(f)]), max(f[i], f[(i + 1) % len(f)]))
                    for f in faces for i in range(len(f))})
    for e, (a, b) in enumerate(edges):  # edge points: midpoints
        assert_close(out[9 + e], (verts[a] + verts[b]) / 2)
    # same topology as Catmull-Clark, and holes drop their children
    cc = catmull_clark_operator(faces, 6)
    assert op.faces.tolist() == cc.faces.tolist()
    holed = bilinear_operator(faces, 6, tags=_tags_tensor({"holes": [1]}))
    assert holed.faces.shape[0] == cc.faces.shape[0] - 4
    assert holed.child_tags.holes.tolist() == [3, 4, 5, 6]
    with pytest.raises(ValueError, match="scheme 'bilinear'"):
        limit_positions(op, verts)


@settings(max_examples=25, deadline=None)
@given(
    sharp=st.lists(st.sampled_from([0.0, 0.3, 1.0, 1.7, 2.3, INF]), min_size=12, max_size=12),
    corners=st.lists(st.sampled_from([0.0, 0.5, 1.5, INF]), min_size=8, max_size=8),
    method=st.sampled_from(["uniform", "chaikin"]),
    scheme=st.sampled_from(["catmark", "loop"]),
)
def test_random_tags_match_reference_and_rows_sum_to_one(sharp, corners, method, scheme):
    """Any mix of crease/corner sharpness on the 12 edges of the cube (Catmark) or the
    octahedron (Loop) and on their vertices."""
    faces, cls = (CUBE_F, CatmullClark) if scheme == "catmark" else (OCTA_F, LoopSubdivision)
    k = len(faces[0])
    edges = sorted({(min(f[i], f[(i + 1) % k]), max(f[i], f[(i + 1) % k]))
                    for f in faces for i in range(k)})
    V = 8 if scheme == "catmark" else 6
    tags = {"creases": dict(zip(edges, sharp)), "corners": dict(enumerate(corners[:V]))}
    module = _check_against_reference(cls, V, faces, tags, "edge_only", method, scheme, 2)
    for level in range(2):
        s = module.operator(level).matrix.to_dense()
        assert_close(s.sum(1), torch.ones(s.shape[0], dtype=torch.float64))
        assert bool((s >= 0).all())


@pytest.mark.parametrize("field, value, error", [
    ("creases", torch.tensor([[0.0, 1.5]]), TypeError),  # was truncated to (0, 1)
    ("creases", torch.tensor([0, 1, 3]), ShapeError),  # was a raw reshape RuntimeError
    ("creases", torch.tensor([[0, 1, 3, 2]]), ShapeError),  # was read as two creases
    ("corners", torch.tensor([1.0]), TypeError),
    ("holes", torch.tensor([True]), TypeError),
])
def test_tag_fields_of_the_wrong_dtype_or_shape_are_named(field, value, error):
    """Float indices and odd shapes in a tag field are neither truncated nor reshaped:
    every builder raises an error naming the field."""
    sharp = {"creases": "crease_sharpness", "corners": "corner_sharpness"}.get(field)
    tags = SubdivisionTags.empty(torch.float64)._replace(**{field: value})
    if sharp:
        n = value.shape[0] if field == "corners" else max(value.numel() // 2, 1)
        tags = tags._replace(**{sharp: torch.ones(n, dtype=torch.float64)})
    quad = [[0, 1, 2, 3]]
    builders = [catmull_clark_operator, loop_operator] + (
        [bilinear_operator] if field == "holes" else [])
    for build in builders:
        faces = quad if build is not loop_operator else [[0, 1, 2], [0, 2, 3]]
        with pytest.raises(error, match=f"tags.{field}"):
            build(faces, 4, tags=tags)


@pytest.mark.parametrize("field", ["crease_sharpness", "corner_sharpness"])
def test_nan_sharpness_raises_value_error_naming_it(field):
    """NaN in parameters is never swallowed: a NaN sharpness is not a sharpness;
    every builder names the field instead of treating it as smooth (NaN > 0 is False)."""
    one = torch.tensor([float("nan")], dtype=torch.float64)
    tags = SubdivisionTags.empty(torch.float64)._replace(
        creases=torch.tensor([[0, 2]]), crease_sharpness=torch.ones(1, dtype=torch.float64),
        corners=torch.tensor([1]), corner_sharpness=torch.ones(1, dtype=torch.float64))
    tags = tags._replace(**{field: one})
    tris = [[0, 1, 2], [0, 2, 3]]
    for build in (catmull_clark_operator, loop_operator):
        with pytest.raises(ValueError, match=f"tags.{field}\\[0\\].*nan"):
            build(tris, 4, tags=tags)
