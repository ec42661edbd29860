"""Meshes of the kinds of OpenSubdiv's eight non-manifold regression shapes
(``tests/mesh/_nonmanifold_shapes.py``: 2-gons and ``[a, a, b]`` faces on an edge,
degenerate quads as poles, merged grids, back-to-back faces, fins, reversed faces)
against OpenSubdiv run live: refined vertices at levels 1-3 and PrimvarRefiner::Limit
positions at every level. OpenSubdiv derives non-manifold sharpness at the base level
and the refined levels inherit it; these kinds exercise that inheritance."""

import pytest
import torch

from tests.mesh._nonmanifold_shapes import KINDS
from tests.mesh._osd import run_osd
from tests.mesh.test_opensubdiv_live import same_points
from torchgeo_cg.mesh import (
    CatmullClark,
    LoopSubdivision,
    catmull_clark_operator,
    limit_positions,
)
from torchgeo_cg.mesh.subdivision import SchemeOptions
from torchgeo_cg.mesh.subdivision.operator import apply_operator

CASES = [pytest.param(name, boundary, marks=[pytest.mark.slow] if name.endswith("360") else [])
         for name in KINDS for boundary in ("edge_only", "edge_and_corner")
         if not (name.endswith("360") and boundary == "edge_and_corner")]  # the slow one once


@pytest.mark.parametrize(("name", "boundary"), CASES)
def test_kind_refines_and_limits_as_opensubdiv(name, boundary):
    verts, faces, scheme = KINDS[name]
    module = (CatmullClark if scheme == "catmark" else LoopSubdivision)(
        faces, len(verts), levels=3, dtype=torch.float64, options=SchemeOptions(boundary=boundary))
    x = torch.tensor(verts, dtype=torch.float64)
    for level in (1, 2, 3):
        op = module.operator(level - 1)
        limit = limit_positions(op, x)
        x = apply_operator(op, x)
        same_points(x, run_osd(verts, faces, f"refine {level}", scheme=scheme,
                               boundary=boundary))
        same_points(limit, run_osd(verts, faces, f"limit {level}", scheme=scheme,
                                   boundary=boundary)[:, :3])


def test_two_gon_children_stay_sharp():
    """A 2-gon on a boundary edge, wound against the quad: the quad and the 2-gon's first
    side share the edge consistently, so its children look manifold, yet OpenSubdiv keeps
    them non-manifold (infinitely sharp) and their edge point a crease vertex."""
    op = catmull_clark_operator([[0, 1, 2, 3], [1, 0]], 4, dtype=torch.float64)
    assert op.child_edge_tags is not None and bool((op.child_edge_tags < 0).any())
    assert op.child_tags is not None and {0, 1} <= set(op.child_tags.corners.tolist())
    child = catmull_clark_operator(op.child_faces, op.num_vertices_out, dtype=torch.float64,
                                   tags=op.child_tags, edge_tags=op.child_edge_tags)
    edge_point = 4 + 2  # the shared edge (0, 1) is the first edge
    row = child.matrix.to_dense()[edge_point]
    assert row[edge_point] == 0.75 and row[0] == 0.125 and row[1] == 0.125  # crease rule
