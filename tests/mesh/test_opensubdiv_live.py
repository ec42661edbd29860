"""The subdivision operators against OpenSubdiv run live (``tests/mesh/_osd.py``)."""

from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

import torchgeo_cg.mesh as mesh_pkg
from tests.mesh._osd import run_osd
from torchgeo_cg.mesh import (
    SubdivisionTags,
    catmull_clark,
    catmull_clark_operator,
    limit_positions,
    load_mesh,
    loop_operator,
    loop_subdivide,
)
from torchgeo_cg.mesh.subdivision import SchemeOptions

RABBIT = Path(mesh_pkg.__file__).parent / "data" / "rabbit.obj"
CUBE_V = [[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)]
CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]


def grid(n=4):
    v = [[c, r, 0.1 * ((r * 7 + c * 3) % 5)] for r in range(n) for c in range(n)]
    f = [[r * n + c, r * n + c + 1, (r + 1) * n + c + 1, (r + 1) * n + c]
         for r in range(n - 1) for c in range(n - 1)]
    return v, f


def same_points(ours, theirs, tol=1e-9):
    """Every point of one set has its twin in the other (OpenSubdiv numbers its new
    vertices in another order); the distance scales with the shape."""
    ours, theirs = np.asarray(ours, dtype=np.float64), np.asarray(theirs, dtype=np.float64)
    assert ours.shape == theirs.shape
    scale = np.abs(theirs).max()
    d1, _ = cKDTree(theirs).query(ours)
    d2, _ = cKDTree(ours).query(theirs)
    assert max(d1.max(), d2.max()) <= tol * scale


def tagged_cube():
    return SubdivisionTags(
        creases=torch.tensor([[0, 1], [1, 3]]), crease_sharpness=torch.tensor([10.0, 1.5]),
        corners=torch.tensor([7]), corner_sharpness=torch.tensor([2.0]),
        holes=torch.zeros(0, dtype=torch.long),
    )


@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
@pytest.mark.parametrize("shape", ["cube", "tagged_cube", "grid", "rabbit"])
def test_catmark_refinement_and_limit_match_opensubdiv(shape, boundary):
    tags = None
    if shape in ("cube", "tagged_cube"):
        verts, faces = CUBE_V, CUBE_F
        tags = tagged_cube() if shape == "tagged_cube" else None
    elif shape == "grid":
        verts, faces = grid()
    else:
        m = load_mesh(RABBIT)
        verts, faces = m.verts.double().tolist(), m.faces.tolist()
    v = torch.tensor(verts, dtype=torch.float64)
    ours, _ = catmull_clark(v, faces, levels=2, options=SchemeOptions(boundary=boundary), tags=tags)
    theirs = run_osd(verts, faces, "refine 2", tags=tags, boundary=boundary)
    same_points(ours, theirs)
    if shape == "tagged_cube":
        return  # semi-sharp tags remain at level 2: no limit masks there
    op = catmull_clark_operator(faces, len(verts), dtype=torch.float64, tags=tags,
                                options=SchemeOptions(boundary=boundary))
    limit_ours = limit_positions(op, v)
    limit_theirs = run_osd(verts, faces, "limit 1", tags=tags, boundary=boundary)[:, :3]
    same_points(limit_ours, limit_theirs)


def test_loop_refinement_matches_opensubdiv():
    verts = [[0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, -1]]
    faces = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [5, 2, 1], [5, 3, 2], [5, 4, 3],
             [5, 1, 4]]
    v = torch.tensor(verts, dtype=torch.float64)
    ours, _ = loop_subdivide(v, faces, levels=2)
    same_points(ours, run_osd(verts, faces, "refine 2", scheme="loop"))
    op = loop_operator(faces, 6, dtype=torch.float64)
    same_points(limit_positions(op, v), run_osd(verts, faces, "limit 1", scheme="loop")[:, :3])


def test_ptex_indices_of_mixed_faces():
    verts = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0], [1.5, 2, 0]]
    faces = [[0, 1, 2, 3], [1, 4, 5, 2], [2, 5, 6]]
    first = run_osd(verts, faces, "ptex")[:, 0]
    assert first.tolist() == [0, 1, 2]  # quads are one ptex face, the triangle three
