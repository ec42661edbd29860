"""The Loop limit surface (limit_surface / limit_stencils / sample_limit_surface on Loop
operators) against OpenSubdiv's Far::PatchTable run live, the planar lattice by hand,
uniform Loop subdivision and limit_positions."""

import itertools

import numpy as np
import pytest
import torch
import trimesh

from tests.mesh._osd import run_osd
from tests.mesh.test_limit_surface import grid
from torchgeo_cg.mesh import (
    LoopSubdivision,
    SubdivisionTags,
    apply_stencils,
    limit_positions,
    limit_stencils,
    limit_surface,
    loop_operator,
    sample_limit_surface,
)
from torchgeo_cg.mesh.data import rabbit
from torchgeo_cg.mesh.subdivision import SchemeOptions

F64 = torch.float64
OCTA_V = [[0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, -1]]
OCTA_F = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [5, 2, 1], [5, 3, 2], [5, 4, 3],
          [5, 1, 4]]


def triangulated(faces):
    return [[a, b, c] for a, b, c, d in faces] + [[a, c, d] for a, b, c, d in faces]


def tags(creases=(), sharpness=10.0, corners=(), holes=()):
    return SubdivisionTags(
        creases=torch.tensor(list(creases), dtype=torch.long).reshape(-1, 2),
        crease_sharpness=torch.full((len(creases),), sharpness, dtype=F64),
        corners=torch.tensor(list(corners), dtype=torch.long),
        corner_sharpness=torch.full((len(corners),), 10.0, dtype=F64),
        holes=torch.tensor(list(holes), dtype=torch.long),
    )


def ico():
    mesh = trimesh.creation.icosphere(subdivisions=1)
    return np.asarray(mesh.vertices).tolist(), mesh.faces.tolist()


def rabbit_tri():
    return rabbit().verts.double().tolist(), triangulated(rabbit().faces.tolist())


def triangle_points(num_faces, n, seed, margin=2.0 ** -5, allowed=None):
    """Uniform points of the ptex triangles, ``margin`` away from their corners."""
    g = torch.Generator().manual_seed(seed)
    ids = torch.tensor(allowed if allowed is not None else range(num_faces))
    fid = ids[torch.randint(0, len(ids), (n,), generator=g)]
    uv = torch.rand(n, 2, generator=g, dtype=F64)
    uv = torch.where(uv.sum(-1, keepdim=True) > 1, 1 - uv, uv)
    return fid, margin + (1 - 3 * margin) * uv


CASES = {
    "octahedron": (lambda: (OCTA_V, OCTA_F), "edge_only", None),
    "ico": (ico, "edge_only", None),
    "grid_edge_only": (lambda: (grid(6)[0], triangulated(grid(6)[1])), "edge_only", None),
    "grid_edge_and_corner": (lambda: (grid(6)[0], triangulated(grid(6)[1])),
                             "edge_and_corner", None),
    "grid_creases": (lambda: (grid(6)[0], triangulated(grid(6)[1])), "edge_only",
                     tags([(7, 8), (8, 9), (9, 10), (14, 20)], corners=[21])),
    "grid_semi_sharp": (lambda: (grid(6)[0], triangulated(grid(6)[1])), "edge_only",
                        tags([(7, 8), (8, 9), (9, 15)], sharpness=2.5)),
    "rabbit": (rabbit_tri, "edge_only", None),
}


@pytest.mark.parametrize("name", list(CASES))
def test_matches_opensubdiv_patch_table(name):
    make, boundary, shape_tags = CASES[name]
    verts, faces = make()
    op = loop_operator(faces, len(verts), dtype=F64, tags=shape_tags,
                       options=SchemeOptions(boundary=boundary))
    fid, uv = triangle_points(len(faces), 300, 1)
    ours = limit_surface(op, torch.tensor(verts, dtype=F64), fid, uv)
    ref = run_osd(verts, faces, "patch 8", tags=shape_tags, boundary=boundary, scheme="loop",
                  samples=np.c_[fid.numpy(), uv.numpy()])
    scale = np.abs(np.asarray(verts)).max()
    np.testing.assert_allclose(ours.positions.numpy(), ref[:, :3], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(ours.du.numpy(), ref[:, 3:6], rtol=0, atol=1e-11 * scale)
    np.testing.assert_allclose(ours.dv.numpy(), ref[:, 6:9], rtol=0, atol=1e-11 * scale)


def lattice(n=8):
    """The regular triangulated lattice ``(i, j)``, ``0 <= i, j < n`` (edge directions
    (1, 0), (0, 1), (-1, 1)), as ``(verts (V, 3) with z = 0, faces, index)``."""
    index = {p: k for k, p in enumerate(itertools.product(range(n), range(n)))}
    faces = []
    for i, j in index:
        if i + 1 < n and j + 1 < n:
            faces += [[index[i, j], index[i + 1, j], index[i, j + 1]],
                      [index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]]]
    verts = torch.tensor([[i, j, 0.0] for i, j in index], dtype=F64)
    return verts, faces, index


def test_planar_lattice_is_reproduced_by_hand():
    """On a regular planar lattice, the box spline reproduces linear functions: the point
    at ``(u, v)`` of triangle ``(i, j), (i+1, j), (i, j+1)`` is ``(i + u, j + v)``, with
    ``du = (1, 0)`` and ``dv = (0, 1)``, the normal ``+z``."""
    verts, faces, index = lattice()
    f = faces.index([index[3, 3], index[4, 3], index[3, 4]])
    op = loop_operator(faces, len(verts), dtype=F64)
    _, uv = triangle_points(1, 50, 2, margin=0.0)
    out = limit_surface(op, verts, torch.full((50,), f), uv)
    torch.testing.assert_close(out.positions[:, :2], uv + 3, atol=1e-14, rtol=0)
    torch.testing.assert_close(out.du, torch.tensor([1.0, 0, 0], dtype=F64).expand(50, 3))
    torch.testing.assert_close(out.dv, torch.tensor([0, 1.0, 0], dtype=F64).expand(50, 3))
    torch.testing.assert_close(out.normals, torch.tensor([0, 0, 1.0], dtype=F64).expand(50, 3))
    st = limit_stencils(op, torch.full((50,), f), uv)  # a regular patch: 12 control points
    assert (st.positions.crow[1:] - st.positions.crow[:-1]).max() <= 12


@pytest.mark.parametrize("boundary", ["edge_only", "edge_and_corner"])
@pytest.mark.parametrize("name", ["octahedron", "ico", "grid", "grid_creases"])
def test_corners_equal_limit_positions(name, boundary):
    if name in ("octahedron", "ico"):
        verts, faces = (OCTA_V, OCTA_F) if name == "octahedron" else ico()
        shape_tags = None
    else:
        verts, faces = grid(6)[0], triangulated(grid(6)[1])
        shape_tags = tags([(7, 8), (8, 9), (9, 10), (10, 16), (16, 15), (15, 14), (14, 8)],
                          corners=[21]) if name == "grid_creases" else None
    v = torch.tensor(verts, dtype=F64)
    op = loop_operator(faces, len(verts), dtype=F64, tags=shape_tags,
                       options=SchemeOptions(boundary=boundary))
    fid = torch.arange(len(faces)).repeat_interleave(3)
    uv = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], dtype=F64).repeat(len(faces), 1)
    out = limit_surface(op, v, fid, uv)
    want = limit_positions(op, v)[torch.tensor(faces).flatten()]
    torch.testing.assert_close(out.positions, want, atol=1e-12, rtol=0)


def test_uniform_subdivision_converges_to_it():
    """At the vertices of uniform level k inside a face, the limit surface is the limit
    position of that vertex (exactly), and the refined vertices approach it as k grows."""
    verts, faces = ico()
    v = torch.tensor(verts, dtype=F64)
    op = loop_operator(faces, len(verts), dtype=F64)
    errors = []
    for k in (1, 2, 3):
        m = 2 ** k
        uv = torch.tensor([(i / m, j / m) for i in range(m + 1) for j in range(m + 1 - i)],
                          dtype=F64)
        fid = torch.arange(6).repeat_interleave(len(uv))
        on = limit_surface(op, v, fid, uv.repeat(6, 1)).positions
        fine = LoopSubdivision(faces, len(verts), levels=k, dtype=F64)
        coarse = LoopSubdivision(faces, len(verts), levels=k - 1, dtype=F64)
        lim = limit_positions(fine.operator(k - 1), coarse(v))
        nearest = torch.cdist(on, lim).argmin(1)
        torch.testing.assert_close(on, lim[nearest], atol=1e-12, rtol=0)
        errors.append(float((fine(v)[nearest] - on).norm(dim=-1).max()))
    assert errors[0] > 2 * errors[1] > 4 * errors[2] > 0, errors


def test_positions_and_normals_are_continuous_across_edges():
    verts, faces = ico()  # valence-5 vertices at the corners of every face
    v = torch.tensor(verts, dtype=F64)
    op = loop_operator(faces, len(verts), dtype=F64)
    where = {(f[i], f[(i + 1) % 3]): (k, i) for k, f in enumerate(faces) for i in range(3)}
    w = torch.tensor([0.0, 2.0 ** -20, 0.13, 0.5, 0.77, 1 - 2.0 ** -20, 1.0], dtype=F64)
    along = [lambda w: (w, 0 * w), lambda w: (1 - w, w), lambda w: (0 * w, 1 - w)]
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
    # the normals too, at the valence-5 vertices and within 2**-20 of them
    torch.testing.assert_close(one.normals, two.normals, atol=1e-9, rtol=0)


@pytest.mark.grad
def test_gradcheck_through_limit_stencils():
    grid_v, grid_f = grid(4)
    faces = triangulated(grid_f)
    op = loop_operator(faces, len(grid_v), dtype=F64, tags=tags([(5, 6)]))
    fid, uv = triangle_points(len(faces), 12, 4, margin=0.0)
    st = limit_stencils(op, fid, uv)
    v = torch.tensor(grid_v, dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x: tuple(apply_stencils(m, x) for m in st), (v,))
    assert torch.autograd.gradcheck(lambda x: limit_surface(op, x, fid, uv).normals, (v,))


def test_samples_are_uniform_by_area():
    op = loop_operator(OCTA_F, 6, dtype=F64)
    v = torch.tensor(OCTA_V, dtype=F64)
    n = 4000
    out = sample_limit_surface(op, v, n, generator=torch.Generator().manual_seed(0))
    assert out.positions.shape == (n, 3) and bool((out.uv.sum(-1) <= 1).all())
    counts = torch.bincount(out.face_ids, minlength=8).double()
    assert (counts - n / 8).abs().max() < 4 * (n / 8 * 7 / 8) ** 0.5  # equal areas
    torch.testing.assert_close(out.positions, limit_surface(op, v, out.face_ids, out.uv).positions)


def test_bad_input_raises():
    op = loop_operator(OCTA_F, 6, dtype=F64)
    v = torch.tensor(OCTA_V, dtype=F64)
    with pytest.raises(ValueError, match=r"u \+ v <= 1"):
        limit_surface(op, v, torch.tensor([0]), torch.tensor([[0.6, 0.6]], dtype=F64))
    with pytest.raises(ValueError, match=r"ptex face ids in \[0, 8\)"):
        limit_surface(op, v, torch.tensor([8]), torch.tensor([[0.2, 0.2]], dtype=F64))
    holed = loop_operator(OCTA_F, 6, dtype=F64, tags=tags(holes=[3]))
    with pytest.raises(ValueError, match="on a hole"):
        limit_surface(holed, v, torch.tensor([3]), torch.tensor([[0.2, 0.2]], dtype=F64))
