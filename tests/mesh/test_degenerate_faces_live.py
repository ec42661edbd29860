"""Faces with a repeated vertex (degenerate quads as poles, a quad with a vertex twice)
and repeated faces (back-to-back, duplicated) refine as OpenSubdiv refines them, run live:
refined vertices at levels 1-3 and PrimvarRefiner::Limit at level 1, Catmark and Loop."""

import math

import pytest
import torch

from tests.mesh._osd import run_osd
from tests.mesh.test_opensubdiv_live import CUBE_F, CUBE_V, same_points
from torchgeo_cg.mesh import (
    catmull_clark,
    catmull_clark_operator,
    limit_positions,
    loop_operator,
    loop_subdivide,
)
from torchgeo_cg.mesh.subdivision import SchemeOptions
from torchgeo_cg.mesh.subdivision.limit import limit_frames

SQUARE = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
OCTA_V = [[0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, -1]]
OCTA_F = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [5, 2, 1], [5, 3, 2], [5, 4, 3],
          [5, 1, 4]]


def quad_pole_cylinder(n):
    """A cylinder of ``n`` quads closed at both ends by ``n`` degenerate quads
    ``(r_k+1, r_k, P, P)`` around a pole ``P`` (OpenSubdiv's ``catmark_nonman_quadpole``)."""
    ring = [[math.cos(2 * math.pi * k / n), math.sin(2 * math.pi * k / n), z]
            for z in (0.0, 1.0) for k in range(n)]
    verts = ring + [[0, 0, -0.5], [0, 0, 1.5]]
    bottom, top = 2 * n, 2 * n + 1
    faces = [[k, (k + 1) % n, n + (k + 1) % n, n + k] for k in range(n)]
    faces += [[(k + 1) % n, k, bottom, bottom] for k in range(n)]
    faces += [[n + k, n + (k + 1) % n, top, top] for k in range(n)]
    return verts, faces


FIN_V = SQUARE + [[0, 0, 1], [1, 0, 1], [0, -1, 0], [1, -1, 0]]
SHAPES = {
    "quadpole8": (*quad_pole_cylinder(8), "catmark"),
    "quadpole64": (*quad_pole_cylinder(64), "catmark"),
    "back_to_back_quads": (SQUARE, [[0, 1, 2, 3], [3, 2, 1, 0]], "catmark"),
    "cube_duplicate_face": (CUBE_V, CUBE_F + [[0, 1, 3, 2]], "catmark"),
    "cube_back_to_back_face": (CUBE_V, CUBE_F + [[2, 3, 1, 0]], "catmark"),
    "cube_degenerate_face": (CUBE_V, [[0, 1, 3, 3], *CUBE_F[1:]], "catmark"),
    "quad_as_triangle": (SQUARE + [[2, 0.5, 0]], [[0, 1, 2, 3], [1, 4, 2, 2]], "catmark"),
    "pentagon_vertex_thrice": (SQUARE + [[2, 0.5, 0]], [[0, 1, 2, 3], [1, 4, 4, 4, 2]],
                               "catmark"),
    "all_equal_face": (SQUARE + [[3, 3, 3]], [[0, 1, 2, 3], [4, 4, 4, 4]], "catmark"),
    "fin_edge": (FIN_V, [[0, 1, 2, 3], [1, 0, 4, 5], [0, 1, 7, 6]], "catmark"),
    "loop_back_to_back": (SQUARE, [[0, 1, 2], [2, 1, 0]], "loop"),
    "loop_back_to_back_pair": (SQUARE + [[0.5, 0.5, 1.0]],
                               [[0, 1, 2], [2, 1, 0], [2, 3, 0], [0, 3, 2]], "loop"),
    "loop_octahedron_duplicate": (OCTA_V, OCTA_F + [[0, 1, 2]], "loop"),
    "loop_fin_edge": (FIN_V, [[0, 1, 2], [1, 0, 4], [0, 1, 6]], "loop"),
}


@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
@pytest.mark.parametrize("name", list(SHAPES))
def test_refines_as_opensubdiv(name, boundary):
    verts, faces, scheme = SHAPES[name]
    v = torch.tensor(verts, dtype=torch.float64)
    refine = catmull_clark if scheme == "catmark" else loop_subdivide
    for level in (1, 2, 3):
        ours, _ = refine(v, faces, levels=level, options=SchemeOptions(boundary=boundary))
        same_points(ours, run_osd(verts, faces, f"refine {level}", scheme=scheme,
                                  boundary=boundary))
    build = catmull_clark_operator if scheme == "catmark" else loop_operator
    op = build(faces, len(verts), dtype=torch.float64, options=SchemeOptions(boundary=boundary))
    theirs = run_osd(verts, faces, "limit 1", scheme=scheme, boundary=boundary)
    same_points(limit_positions(op, v), theirs[:, :3])
    frames = limit_frames(op, v)  # finite everywhere
    assert torch.isfinite(frames.tangent_u).all() and torch.isfinite(frames.normals).all()


def test_strictly_invalid_faces_still_raise():
    with pytest.raises(ValueError, match="out of range"):
        catmull_clark_operator([[0, 1, 2, 5]], 4)
    with pytest.raises(ValueError, match="index -3"):
        catmull_clark_operator([[0, 1, 2, -3]], 4)
    with pytest.raises(Exception, match="triangles"):
        loop_operator([[0, 1, 2, 3]], 4)
