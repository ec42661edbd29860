"""The mesh validator of the queries: checks, messages and fan triangulation."""

from __future__ import annotations

import math

import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.mesh.faces import check_mesh, triangulate_faces

VERTS = torch.tensor([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]])


def test_check_mesh_triangulates_polygons_and_keeps_triangles():
    quads = torch.tensor([[0, 1, 2, 3], [0, 1, 4, -1]])
    assert torch.equal(check_mesh(VERTS, quads), triangulate_faces(quads))
    tris = torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32)
    out = check_mesh(VERTS, tris)
    assert out.dtype == torch.long and torch.equal(out, tris.long())
    assert torch.equal(check_mesh(VERTS, [[0, 1, 2, 3]]), torch.tensor([[0, 1, 2], [0, 2, 3]]))


@pytest.mark.parametrize("faces, error, match", [
    (torch.tensor([[0, 1, 5]]), ValueError, r"indices in \[0, 4\], got range \[0, 5\]"),
    (torch.tensor([[-1, 1, 2]]), ValueError, "indices"),
    (torch.tensor([[0, 1, 2, -1, 3]]), ValueError, "padding"),
    (torch.tensor([[0, 1, 2, -3]]), ValueError, "out of range"),
    (torch.zeros(0, 3, dtype=torch.long), ValueError, "non-empty"),
    (torch.tensor([[0, 1]]), ShapeError, "K >= 3"),
    (torch.tensor([[0.0, 1, 2]]), TypeError, "integer"),
])
def test_check_mesh_rejects_bad_faces_naming_them(faces, error, match):
    with pytest.raises(error, match=match):
        check_mesh(VERTS, faces)


def test_check_mesh_checks_the_vertices():
    with pytest.raises(TypeError, match="verts"):
        check_mesh(VERTS.long(), [[0, 1, 2]])
    with pytest.raises(ShapeError, match="verts"):
        check_mesh(VERTS[:, :2], [[0, 1, 2]])
    bad = VERTS.clone()
    bad[1, 0] = math.nan
    assert check_mesh(bad, [[0, 1, 2]]).shape == (1, 3)  # finiteness only when asked
    with pytest.raises(ValueError, match="finite"):
        check_mesh(bad, [[0, 1, 2]], finite=True)
    batched = VERTS.expand(2, 3, -1, -1)
    assert check_mesh(batched, [[0, 1, 2]]).shape == (1, 3)
