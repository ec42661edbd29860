"""limit_frames against OpenSubdiv's ``Far::PrimvarRefiner::Limit`` run live on the kinds of
OpenSubdiv's non-manifold regression shapes (``tests/mesh/_nonmanifold_shapes.py``: 2-gons
and ``[a, a, b]`` faces on an edge, degenerate quads as poles, merged grids, back-to-back
faces, fins, reversed faces), Catmark and Loop, both boundary modes: both tangents
``(du, dv)`` and their normals at every refined vertex.

Refined vertices are paired by index, not by position (these shapes have coincident
refined vertices: the edge points of a 2-gon's two edges, the vertex and edge points of a
degenerate quad): OpenSubdiv numbers the vertex points and face points as we do and the
edge points in the order each edge's first side appears (faces in order, sides in face
order); the positions are checked to agree under that pairing.

OpenSubdiv's ``Limit`` sizes its mask buffers by the level's maximum valence,
``max(M0, 4, 2 + max edge faces)`` after a Catmark step; the edge point of an edge with
``m`` faces has ``2 m`` faces, and where ``2 m`` exceeds that size its first tangent reads
the second tangent's leading weights (vertex ``-4/6``, edges ``-1/6, 4/6, -1/6``) as the
weights of its last faces. limit_frames does not copy that; the test adds those terms
(derived by hand below) to our first tangent where OpenSubdiv's buffer overflows.
"""

import numpy as np
import pytest
import torch

from tests.mesh._nonmanifold_shapes import KINDS
from tests.mesh._osd import run_osd
from torchgeo_cg.mesh import catmull_clark_operator, loop_operator
from torchgeo_cg.mesh.subdivision import SchemeOptions
from torchgeo_cg.mesh.subdivision._topology import mesh_topology
from torchgeo_cg.mesh.subdivision.limit import limit_frames

CASES = [pytest.param(name, boundary, marks=[pytest.mark.slow] if name.endswith("360") else [])
         for name in KINDS for boundary in ("edge_only", "edge_and_corner")
         if not (name.endswith("360") and boundary == "edge_and_corner")]  # the slow one once


def _base_sides(faces, num_vertices):
    """``(sides, edge_c)``: every side ``(face, position, size)`` in face-major order, and
    its edge as the operators number them."""
    width = max(map(len, faces))
    padded = torch.tensor([list(f) + [-1] * (width - len(f)) for f in faces])
    topo = mesh_topology(padded, num_vertices)
    sides = [(f, p, len(face)) for f, face in enumerate(faces) for p in range(len(face))]
    return sides, topo.edge_c.tolist(), topo


def osd_index(faces, num_vertices, scheme):
    """OpenSubdiv's index of each of our refined vertices."""
    sides, edge_c, topo = _base_sides(faces, num_vertices)
    row_edge = num_vertices + (len(faces) if scheme == "catmark" else 0)
    first = {}
    for c, e in enumerate(edge_c):
        first.setdefault(e, c)
    by_first = sorted(first, key=first.get)
    edge_rank = {e: r for r, e in enumerate(by_first)}
    return np.array(list(range(row_edge)) + [row_edge + edge_rank[e]
                                             for e in range(len(by_first))])


def overflow_terms(faces, num_vertices, refined):
    """``{our refined index: the terms OpenSubdiv's first tangent adds}`` for Catmark edge
    points whose ``2 m`` faces exceed OpenSubdiv's level-1 maximum valence. Their child
    faces come two per side of the edge (face-major): at the side's head, whose vertex
    opposite the edge point is the edge point of the next side of the face, then at its
    tail (the edge point of the previous side)."""
    sides, edge_c, topo = _base_sides(faces, num_vertices)
    row_edge = num_vertices + len(faces)
    count = np.bincount(edge_c)
    m0 = max(max(map(len, faces)), int(topo.num_faces_v.max()), int(topo.valence_v.max()))
    size = max(m0, 4, 2 + int(count.max()))
    start = np.cumsum([0] + [len(f) for f in faces])
    diag = {}
    for c, (f, p, n) in enumerate(sides):
        nxt, prv = start[f] + (p + 1) % n, start[f] + (p - 1) % n
        diag.setdefault(edge_c[c], []).extend([row_edge + edge_c[nxt], row_edge + edge_c[prv]])
    cross = [-4 / 6, -1 / 6, 4 / 6, -1 / 6] + [0.0] * size  # the regular crease's second tangent
    return {row_edge + e: sum(cross[i - size] * refined[d[i]] for i in range(size, len(d)))
            for e, d in diag.items() if len(d) > size}


@pytest.mark.parametrize(("name", "boundary"), CASES)
def test_nonmanifold_kind_frames_match_primvar_refiner_limit(name, boundary):
    verts, faces, scheme = KINDS[name]
    build = catmull_clark_operator if scheme == "catmark" else loop_operator
    op = build(faces, len(verts), dtype=torch.float64, options=SchemeOptions(boundary=boundary))
    ours = limit_frames(op, torch.tensor(verts, dtype=torch.float64))
    index = osd_index(faces, len(verts), scheme)
    theirs = run_osd(verts, faces, "limit 1", boundary=boundary, scheme=scheme)[index]
    np.testing.assert_allclose(ours.positions.numpy(), theirs[:, :3], rtol=0,
                               atol=1e-13 * np.abs(verts).max())
    du = theirs[:, 3:6].copy()
    if scheme == "catmark":
        refined = run_osd(verts, faces, "refine 1", boundary=boundary, scheme=scheme)[index]
        for v, terms in overflow_terms(faces, len(verts), refined).items():
            du[v] -= terms
    scale = np.abs(theirs[:, 3:]).max()
    np.testing.assert_allclose(ours.tangent_u.numpy(), du, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(ours.tangent_v.numpy(), theirs[:, 6:9], rtol=0, atol=1e-13 * scale)
    # normals where the tangents span a plane: the points of 2-gons and back-to-back faces
    # have a tangent that is zero up to rounding (|du x dv| ~ 1e-17 scale^2, the others
    # 1e-3 scale^2 and more), where the normal's direction is rounding noise
    normal = np.cross(du, theirs[:, 6:9])
    length = np.linalg.norm(normal, axis=1)
    spans = length > 1e-8 * scale**2
    assert spans.mean() > 0.5, spans.mean()
    expected = normal[spans] / length[spans, None]
    np.testing.assert_allclose(ours.normals.numpy()[spans], expected, rtol=0, atol=1e-12)

def test_overflow_is_where_the_shapes_need_it():
    """The buffer-overflow terms are needed (and given) only on the back-to-back quads with
    hanging faces, where an edge has four faces and the base valence is four."""
    needing = set()
    for name, (verts, faces, scheme) in KINDS.items():
        if scheme == "catmark" and not name.endswith("360"):
            refined = np.zeros((len(verts) + len(faces) + sum(map(len, faces)), 3))
            if overflow_terms(faces, len(verts), refined):
                needing.add(name)
    assert needing == {"catmark_val2_nonman"}
