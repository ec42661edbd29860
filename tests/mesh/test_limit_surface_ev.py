"""The limit surface next to extraordinary vertices of high valence (Catmark and Loop):
positions and normals continuous across every edge out of the vertex at any distance from it,
and equal to an exact reference: the same points evaluated through more refinement levels
(where they reach regular patches, the closed-form B-spline and box-spline patches), and at
the vertex itself the limit masks of :func:`limit_frames` (tested against OpenSubdiv)."""

import math

import numpy as np
import pytest
import torch

from tests.mesh._osd import run_osd
from torchgeo_cg.mesh import (
    apply_stencils,
    catmull_clark_operator,
    limit_frames,
    limit_stencils,
    limit_surface,
    loop_operator,
)
from torchgeo_cg.mesh.data import rabbit
from torchgeo_cg.mesh.subdivision._ev_patches import ev_tables as _ev_tables

F64 = torch.float64
LEVEL = 8  # the default max_level: the points below lie within 2**-LEVEL of the vertex
EXACT = "donot_use_mm_for_euclid_dist"  # cdist without the cancellation of |x|^2 + |y|^2 - 2xy


def rabbit_triangles():
    """The shipped rabbit, each quad split along alternating diagonals: a real mesh with
    vertices of valence 3 to 9."""
    m = rabbit(dtype=F64)
    turn = (torch.arange(m.faces.shape[0]) % 2).bool()[:, None]
    f = torch.where(turn, torch.roll(m.faces, 1, 1), m.faces)
    return m.verts, torch.cat([f[:, [0, 1, 2]], f[:, [0, 2, 3]]])


def bipyramid(n):
    """Two apexes of valence ``n`` over a wavy ring (triangles, Loop)."""
    a = torch.arange(n, dtype=F64) * 2 * math.pi / n
    ring = torch.stack([torch.cos(a), torch.sin(a), 0.2 * torch.cos(3 * a)], 1)
    verts = torch.cat([ring, torch.tensor([[0.1, 0.0, 1.3], [0.0, -0.2, -0.8]], dtype=F64)])
    i = torch.arange(n)
    faces = torch.cat([torch.stack([i, (i + 1) % n, torch.full_like(i, n)], 1),
                       torch.stack([(i + 1) % n, i, torch.full_like(i, n + 1)], 1)])
    return verts, faces


def prism(n):
    """An ``n``-gonal prism (two ``n``-gon caps, ``n`` side quads; Catmark): the caps'
    face points have valence ``n``, the ring vertices valence 3."""
    a = torch.arange(n, dtype=F64) * 2 * math.pi / n
    ring = torch.stack([torch.cos(a), 0.8 * torch.sin(a), 0.1 * torch.sin(2 * a)], 1)
    verts = torch.cat([ring, ring + torch.tensor([0.1, 0.0, 1.0], dtype=F64)])
    i = torch.arange(n)
    sides = torch.stack([i, (i + 1) % n, (i + 1) % n + n, i + n], 1).tolist()
    caps = [list(range(n - 1, -1, -1)), list(range(n, 2 * n))]
    return verts, sides + caps


def corner_frames(scheme, verts, faces, valence):
    """Per ptex corner at an extraordinary vertex of ``valence``: ``(ptex id, uv of the
    corner, the two edge directions, the vertex's index at level 1)``."""
    rows = []
    if isinstance(faces, list):  # the prism: the caps' sub-faces, the vertex at (1, 1)
        first = len(faces) - 2  # the caps come last; each side quad is one ptex face
        for cap in range(2):
            for j in range(len(faces[first + cap])):
                ptex = first + cap * len(faces[first]) + j
                rows.append((ptex, (1.0, 1.0), ((0.0, -1.0), (-1.0, 0.0)),
                             len(verts) + first + cap))
        return rows if len(faces[first]) == valence else []
    val = torch.bincount(faces.flatten(), minlength=verts.shape[0])
    val[torch.nonzero(val == valence).flatten()[2:]] = 0  # two such vertices are enough
    corners = ((0.0, 0.0), ((1.0, 0.0), (0.0, 1.0))), ((1.0, 0.0), ((-1.0, 1.0), (-1.0, 0.0))), \
        ((0.0, 1.0), ((0.0, -1.0), (1.0, -1.0)))
    for f, face in enumerate(faces.tolist()):
        for j, v in enumerate(face):
            if val[v] != valence:
                continue
            if scheme == "catmark":  # a triangle's sub-face j has (0, 0) at corner j
                rows.append((3 * f + j, corners[0][0], corners[0][1], v))
            else:
                rows.append((f, corners[j][0], corners[j][1], v))
    return rows


def edge_points(rows, d):
    """Points at distance ``d`` (ptex units) along both edges out of each corner, and one
    inside: ``(face_ids, uv, owner vertex, on an edge)``."""
    fid, uv, owner, on_edge = [], [], [], []
    for ptex, o, (a, b), v in rows:
        for step, edge in ((a, True), (b, True), ((0.5 * a[0] + 0.3 * b[0],
                                                   0.5 * a[1] + 0.3 * b[1]), False)):
            fid.append(ptex)
            uv.append((o[0] + d * step[0], o[1] + d * step[1]))
            owner.append(v)
            on_edge.append(edge)
    return (torch.tensor(fid), torch.tensor(uv, dtype=F64).clamp(0, 1), torch.tensor(owner),
            torch.tensor(on_edge))


def mesh_case(name):
    if name.startswith("rabbit"):
        verts, faces = rabbit_triangles()
        return verts, faces, int(name.split("_")[-1])
    n = int(name.split("_")[-1])
    return (*(prism(n) if name.startswith("prism") else bipyramid(n)), n)


def operator(scheme, verts, faces):
    build = catmull_clark_operator if scheme == "catmark" else loop_operator
    return build(faces, verts.shape[0], dtype=F64)


CASES = [("catmark", "rabbit_8"), ("catmark", "rabbit_9"), ("catmark", "prism_12"),
         ("catmark", "prism_16"), ("loop", "rabbit_8"), ("loop", "rabbit_9"),
         ("loop", "bipyramid_12"), ("loop", "bipyramid_16")]


@pytest.mark.parametrize(("scheme", "name"), CASES)
def test_normals_continuous_across_edges_near_the_vertex(scheme, name):
    """Every point on an edge out of the vertex is evaluated in both faces of the edge:
    one position and one normal, at distances inside the last level's faces."""
    verts, faces, valence = mesh_case(name)
    op = operator(scheme, verts, faces)
    rows = corner_frames(scheme, verts, faces, valence)
    assert rows
    scale = verts.abs().max()
    for d in (2.0 ** -10, 2.0 ** -20, 2.0 ** -40):
        fid, uv, owner, on_edge = edge_points(rows, d)
        out = limit_surface(op, verts, fid, uv)
        p, n = out.positions[on_edge], out.normals[on_edge]
        near = (torch.cdist(p, p, compute_mode=EXACT) <= 1e-13 * scale) & (owner[on_edge, None] ==
                                                       owner[None, on_edge])
        near.fill_diagonal_(False)
        assert (near.sum(1) == 1).all(), d  # each edge point has exactly one twin
        i, k = torch.nonzero(near, as_tuple=True)
        torch.testing.assert_close(n[i], n[k], atol=1e-11, rtol=0)
        assert torch.isfinite(out.du).all() and (out.normals.norm(dim=-1) - 1).abs().max() < 1e-12


def refined_frames(scheme, verts, faces, levels):
    """Limit positions and normals of the vertices of ``levels`` uniform refinements (the
    limit masks of :func:`limit_frames`, which OpenSubdiv's live tests check)."""
    build = catmull_clark_operator if scheme == "catmark" else loop_operator
    op = build(faces, verts.shape[0], dtype=F64)
    for _ in range(levels - 1):  # a loop over levels
        verts = apply_stencils(op.stencils, verts)
        op = build(op.faces, op.num_vertices_out, dtype=F64)
    return limit_frames(op, verts)


SMALL = [("catmark", "prism_8"), ("catmark", "prism_12"), ("catmark", "prism_16"),
         ("catmark", "prism_3"), ("loop", "bipyramid_8"), ("loop", "bipyramid_12"),
         ("loop", "bipyramid_16"), ("loop", "bipyramid_3")]


@pytest.mark.parametrize(("scheme", "name"), SMALL)
def test_equal_to_the_limit_at_refined_vertices(scheme, name):
    """Dyadic points next to the vertex are vertices of a uniform refinement: positions
    and normals there against the limit masks (exact), at the vertex itself too, and
    points so deep that everything but the vertex's limit underflows."""
    verts, faces, valence = mesh_case(name)
    op = operator(scheme, verts, faces)
    rows = corner_frames(scheme, verts, faces, valence)
    levels = 5
    rows = rows[:4]
    frames = refined_frames(scheme, verts, faces, levels)
    scale = verts.abs().max()
    for j in range(1, levels):  # ptex distance 2**-j: a vertex of level j + 1 (Catmark's
        # sub-faces) or j (Loop's triangles), both refined here
        fid, uv, _, _ = edge_points(rows, 2.0 ** -j)
        out = limit_surface(op, verts, fid, uv)
        dist, at = torch.cdist(out.positions, frames.positions, compute_mode=EXACT).min(1)
        inner = torch.arange(fid.numel()) % 3 == 2  # not a vertex of the refinement
        assert dist[~inner].max() < 1e-13 * scale, j
        torch.testing.assert_close(out.normals[~inner], frames.normals[at[~inner]],
                                   atol=1e-12, rtol=0)
    base = limit_frames(op, verts)
    for d in (0.0, 1e-300):
        fid, uv, owner, _ = edge_points(rows, d)
        out = limit_surface(op, verts, fid, uv)
        torch.testing.assert_close(out.positions, base.positions[owner], atol=1e-13 * scale,
                                   rtol=0)
        torch.testing.assert_close(out.normals, base.normals[owner], atol=1e-11, rtol=0)
        assert torch.isfinite(out.du).all() and torch.isfinite(out.dv).all()


@pytest.mark.parametrize(("scheme", "name"), [("catmark", "rabbit_9"), ("loop", "rabbit_9"),
                                              ("catmark", "prism_3")])
def test_derivatives_near_the_vertex_are_those_of_the_ptex_parametrisation(scheme, name):
    """Central differences at points 2**-12 from the vertex (valence 9, and 3 where the
    derivatives vanish at the vertex); at the vertex, ``du`` and ``dv`` are tangent to the
    two edges (the derivatives' limits there, rescaled)."""
    verts, faces, valence = mesh_case(name)
    op = operator(scheme, verts, faces)
    rows = corner_frames(scheme, verts, faces, valence)
    d = 2.0 ** -12
    fid, uv, _, _ = edge_points(rows, d)
    fid, uv = fid[2::3].contiguous(), uv[2::3].contiguous()  # the inner points
    out = limit_surface(op, verts, fid, uv)
    h = d * 1e-4
    for k, deriv in ((0, out.du), (1, out.dv)):
        step = torch.zeros(2, dtype=F64)
        step[k] = h
        fd = (limit_surface(op, verts, fid, uv + step).positions
              - limit_surface(op, verts, fid, uv - step).positions) / (2 * h)
        torch.testing.assert_close(deriv, fd, rtol=1e-6, atol=1e-6 * deriv.norm(dim=-1).max())
    fid, uv, _, _ = edge_points(rows, 0.0)
    at = limit_surface(op, verts, fid[::3], uv[::3])
    fid, uv, _, _ = edge_points(rows, 2.0 ** -200)  # deep: the direction has converged
    near = limit_surface(op, verts, fid, uv)
    for e in (0, 1):  # the derivative along each edge, at the vertex and next to it
        a = torch.tensor([r[2][e] for r in rows], dtype=F64)
        along = near.du[e::3] * a[:, :1] + near.dv[e::3] * a[:, 1:]
        at_vertex = at.du * a[:, :1] + at.dv * a[:, 1:]
        cos = torch.nn.functional.cosine_similarity(along, at_vertex, dim=-1)
        torch.testing.assert_close(cos, torch.ones_like(cos), atol=1e-12, rtol=0)


def test_float32_and_scale():
    """float32 operators: the normals across the edges agree to float32's accuracy; the
    normals do not change with the mesh's scale."""
    verts, faces = rabbit_triangles()
    rows = corner_frames("catmark", verts, faces, 9)
    op = catmull_clark_operator(faces, verts.shape[0], dtype=torch.float32)
    fid, uv, owner, on_edge = edge_points(rows, 2.0 ** -14)
    st = limit_stencils(op, fid, uv.float())
    v32 = verts.float()
    du, dv = apply_stencils(st.du, v32), apply_stencils(st.dv, v32)
    n = torch.nn.functional.normalize(torch.linalg.cross(du, dv), dim=-1)
    ref = limit_surface(operator("catmark", verts, faces), verts, fid, uv).normals
    assert (n.double() - ref).norm(dim=-1).max() < 2e-5  # float32: about 16 eps
    for k in (1e-6, 1e6):
        torch.testing.assert_close(limit_surface(op, v32 * k, fid, uv.float()).normals, n,
                                   atol=1e-5, rtol=0)


@pytest.mark.grad
def test_gradcheck_near_the_vertex():
    verts, faces = prism(8)
    op = catmull_clark_operator(faces, verts.shape[0], dtype=F64)
    rows = corner_frames("catmark", verts, faces, 8)[:3]
    fid, uv, _, _ = edge_points(rows, 2.0 ** -11)
    st = limit_stencils(op, fid, uv)

    def normals(x):
        du, dv = apply_stencils(st.du, x), apply_stencils(st.dv, x)
        return torch.nn.functional.normalize(torch.linalg.cross(du, dv), dim=-1)

    v = verts.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(normals, (v,))
    torch.testing.assert_close(normals(verts), limit_surface(op, verts, fid, uv).normals)


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
@pytest.mark.parametrize("valence", [3, 5, 8, 12, 30])
def test_ring_tables_against_the_closed_forms(scheme, valence):
    """The subdominant eigenvalue of the ring's subdivision matrix against its closed form
    (Stam 1998; Loop: ``3/8 + 1/4 cos(2 pi / N)``), the limit mask a
    left eigenvector (``l^T Q = 0``), ``Q 1 = 0``, the children's patch rows affine, and
    ``Q^inf`` a rank-2 projector that ``Q`` fixes."""
    P, l_row, lam, powers, Pi = _ev_tables(valence, scheme, F64, "cpu")
    c = math.cos(2 * math.pi / valence)
    if scheme == "catmark":
        want = (5 + c + math.cos(math.pi / valence) * math.sqrt(2 * (9 + c))) / 16
    else:
        want = 3 / 8 + c / 4
    assert abs(lam - want) < 1e-13
    Q = powers[0]
    torch.testing.assert_close(l_row @ Q, torch.zeros_like(l_row), atol=1e-13, rtol=0)
    torch.testing.assert_close(Q.sum(1), torch.zeros_like(l_row), atol=1e-13, rtol=0)
    torch.testing.assert_close(l_row.sum(), torch.tensor(1.0, dtype=F64))
    torch.testing.assert_close(P.sum(-1), torch.ones(P.shape[:2], dtype=F64))
    torch.testing.assert_close(Pi @ Pi, Pi, atol=1e-12, rtol=0)
    torch.testing.assert_close(Q @ Pi, Pi, atol=1e-12, rtol=0)
    assert torch.linalg.matrix_rank(Pi).item() == 2


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_matches_opensubdiv_next_to_high_valence_vertices(scheme):
    """OpenSubdiv's ``Far::PatchTable`` run live (regular patches after 10 levels of
    isolation: exact there), at points of the faces around the valence-8 and -9 vertices
    of the triangulated rabbit, 2**-5 to 1/2 of a ptex face from the vertex."""
    verts, faces = rabbit_triangles()
    rows = corner_frames(scheme, verts, faces, 8) + corner_frames(scheme, verts, faces, 9)
    g = torch.Generator().manual_seed(3)
    pick = torch.randint(0, len(rows), (200,), generator=g)
    w = 2.0 ** -5 + (0.5 - 2.0 ** -5) * torch.rand(200, 2, generator=g, dtype=F64)
    o = torch.tensor([rows[i][1] for i in pick.tolist()], dtype=F64)
    a = torch.tensor([rows[i][2][0] for i in pick.tolist()], dtype=F64)
    b = torch.tensor([rows[i][2][1] for i in pick.tolist()], dtype=F64)
    fid = torch.tensor([rows[i][0] for i in pick.tolist()])
    uv = (o + w[:, :1] * a + w[:, 1:] * b).clamp(0, 1)
    ours = limit_surface(operator(scheme, verts, faces), verts, fid, uv)
    ref = run_osd(verts.tolist(), faces.tolist(), "patch 10", scheme=scheme,
                  samples=np.c_[fid.numpy(), uv.numpy()])
    # OpenSubdiv's derivatives on Catmark's sub-faces of non-quads are twice ours (see
    # test_limit_surface's live test); positions and normals compare directly
    scale = float(verts.abs().max())
    np.testing.assert_allclose(ours.positions.numpy(), ref[:, :3], atol=1e-12 * scale, rtol=0)
    half = 0.5 if scheme == "catmark" else 1.0
    np.testing.assert_allclose(ours.du.numpy(), half * ref[:, 3:6], atol=1e-11 * scale, rtol=0)
    np.testing.assert_allclose(ours.dv.numpy(), half * ref[:, 6:9], atol=1e-11 * scale, rtol=0)
