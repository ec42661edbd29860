"""limit_frames against OpenSubdiv's ``Far::PrimvarRefiner::Limit`` run live: positions,
both tangents ``(du, dv)`` and their normals at every refined vertex (vertex, face and
edge points), on closed and open meshes, with infinitely sharp tags, in both boundary
modes, for Catmark and Loop."""

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree

from tests.mesh._osd import run_osd
from tests.mesh.test_opensubdiv_live import CUBE_F, CUBE_V, grid
from torchgeo_cg.mesh import SubdivisionTags, catmull_clark_operator, loop_operator
from torchgeo_cg.mesh.data import rabbit
from torchgeo_cg.mesh.subdivision import SchemeOptions
from torchgeo_cg.mesh.subdivision.limit import limit_frames


def tags(creases=(), corners=(), holes=()):
    """Infinitely sharp creases and corners (sharpness 10), holes."""
    return SubdivisionTags(
        creases=torch.tensor(list(creases), dtype=torch.long).reshape(-1, 2),
        crease_sharpness=torch.full((len(creases),), 10.0, dtype=torch.float64),
        corners=torch.tensor(list(corners), dtype=torch.long),
        corner_sharpness=torch.full((len(corners),), 10.0, dtype=torch.float64),
        holes=torch.tensor(list(holes), dtype=torch.long),
    )


def triangulated(faces):
    return [[a, b, c] for a, b, c, d in faces] + [[a, c, d] for a, b, c, d in faces]


def shape(name):
    """(verts, faces, scheme, tags) of each test shape."""
    rv, rf = rabbit().verts.double().tolist(), rabbit().faces.tolist()
    gv, gf = grid(5)
    mixed_v = [[0, 0, 0], [1, 0, 0.2], [1, 1, 0], [0, 1, 0.1], [2, 0, 0], [2, 1, 0.3],
               [1.5, 2, 0], [0.5, 2.2, 0.4], [-0.6, 0.5, 0.2]]
    mixed_f = [[0, 1, 2, 3], [1, 4, 5, 2], [2, 5, 6], [3, 2, 6, 7], [0, 3, 8]]
    ico = trimesh.creation.icosphere(subdivisions=1)
    crease_loop = [(0, 1), (1, 3), (3, 2), (2, 0), (0, 4)]  # with a 3-crease corner at 0
    return {
        "cube": (CUBE_V, CUBE_F, "catmark", None),
        "creased_cube": (CUBE_V, CUBE_F, "catmark", tags(crease_loop)),
        "grid": (gv, gf, "catmark", None),
        "grid_tags": (gv, gf, "catmark", tags([(6, 7), (7, 8), (6, 11), (17, 18)],
                                              [12, 2], [5])),  # creases, a dart, corners, hole
        "mixed": (mixed_v, mixed_f, "catmark", None),
        "rabbit": (rv, rf, "catmark", None),
        "rabbit_crease": (rv, rf, "catmark", tags([rf[0][:2], rf[0][1:3]])),
        "loop_ico": (np.asarray(ico.vertices).tolist(), ico.faces.tolist(), "loop", None),
        "loop_grid": (gv, triangulated(gf), "loop",
                      tags([(6, 7), (7, 8), (6, 11), (17, 18)], [12])),
        "loop_rabbit": (rv, triangulated(rf), "loop", None),
    }[name]


@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
@pytest.mark.parametrize("name", ["cube", "creased_cube", "grid", "grid_tags", "mixed", "rabbit",
                                  "rabbit_crease", "loop_ico", "loop_grid", "loop_rabbit"])
def test_limit_frames_match_primvar_refiner_limit(name, boundary):
    verts, faces, scheme, shape_tags = shape(name)
    build = catmull_clark_operator if scheme == "catmark" else loop_operator
    op = build(faces, len(verts), dtype=torch.float64, tags=shape_tags,
               options=SchemeOptions(boundary=boundary))
    ours = limit_frames(op, torch.tensor(verts, dtype=torch.float64))
    theirs = run_osd(verts, faces, "limit 1", tags=shape_tags, boundary=boundary, scheme=scheme)
    # OpenSubdiv numbers its refined vertices in another order: pair them by position
    dist, twin = cKDTree(theirs[:, :3]).query(ours.positions.numpy())
    theirs = theirs[twin]
    assert np.unique(twin).size == twin.size and dist.max() <= 1e-12 * np.abs(verts).max()
    scale = np.abs(theirs[:, 3:]).max()
    np.testing.assert_allclose(ours.tangent_u.numpy(), theirs[:, 3:6], rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(ours.tangent_v.numpy(), theirs[:, 6:9], rtol=0, atol=1e-13 * scale)
    normal = np.cross(theirs[:, 3:6], theirs[:, 6:9])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    np.testing.assert_allclose(ours.normals.numpy(), normal, rtol=0, atol=1e-12)
