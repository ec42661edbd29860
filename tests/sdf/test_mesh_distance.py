"""mesh_sdf against a brute-force reference written here, winding numbers and trimesh."""

from __future__ import annotations

import importlib.util
import math
import sys
import warnings

import numpy as np
import pytest
import torch
import trimesh

import torchgeo_cg.sdf as S
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.engine import backend as engine_backend
from torchgeo_cg.sdf import mesh_distance as M


def _mesh(m: trimesh.Trimesh, dtype=torch.float64):
    return torch.tensor(m.vertices, dtype=dtype), torch.tensor(m.faces)


def _brute_force(vertices, faces, points):
    """Exact unsigned distance by checking every face with a dense barycentric scan."""
    tri = vertices[faces]  # (F, 3, 3)
    p = points[:, None, :]
    a, b, c = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
    # closest point on each triangle from the three edges and the clamped plane projection
    n = torch.cross(b - a, c - a, dim=-1)
    n = n / n.norm(dim=-1, keepdim=True)
    proj = p - ((p - a) * n).sum(-1, keepdim=True) * n

    def inside(q):
        s1 = (torch.cross(b - a, q - a, dim=-1) * n).sum(-1)
        s2 = (torch.cross(c - b, q - b, dim=-1) * n).sum(-1)
        s3 = (torch.cross(a - c, q - c, dim=-1) * n).sum(-1)
        return (s1 >= 0) & (s2 >= 0) & (s3 >= 0)

    def seg(u, v):
        t = (((p - u) * (v - u)).sum(-1) / ((v - u) ** 2).sum(-1)).clamp(0, 1)
        return (p - (u + t[..., None] * (v - u))).norm(dim=-1)

    d = torch.minimum(torch.minimum(seg(a, b), seg(b, c)), seg(c, a))
    d_plane = (p - proj).norm(dim=-1)
    d = torch.where(inside(proj), torch.minimum(d, d_plane), d)
    return d.min(1).values


def _points(m: trimesh.Trimesh, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    surf = m.sample(n, seed=seed) if "seed" in m.sample.__code__.co_varnames else m.sample(n)
    near = surf + rng.normal(scale=0.05, size=surf.shape)
    lo, hi = m.bounds
    uni = rng.uniform(lo - 0.3, hi + 0.3, size=(n // 4, 3))
    return torch.tensor(np.concatenate([near, uni]))


MESHES = {
    "icosphere": lambda: trimesh.creation.icosphere(subdivisions=2),
    "box": lambda: trimesh.creation.box(extents=(1.0, 0.6, 0.3)),
    "torus": lambda: trimesh.creation.torus(1.0, 0.3, major_sections=24, minor_sections=12),
}


@pytest.mark.parametrize("name", sorted(MESHES))
def test_against_brute_force_and_winding_signs(name):
    m = MESHES[name]()
    V, F = _mesh(m)
    p = _points(m, 300)
    r = M.mesh_sdf(V, F, p, return_closest=True)
    ref = _brute_force(V, F, p)
    assert_close(r.sdf.abs(), ref, atol=1e-12, rtol=0)
    # 0 sign errors against the (brute force) winding number on a watertight mesh
    w = M.winding_number(V, F, p)
    assert_close(w.round(), (w > 0.5).double(), atol=1e-6, rtol=0)  # closed: w is 0 or 1
    assert torch.equal(r.sdf < 0, w > 0.5)
    # closest points lie on the returned faces at the returned distance
    assert_close((p - r.closest_points).norm(dim=-1), r.sdf.abs())
    tri = V[F[r.face_ids]]
    q = S.closest_point_on_triangle(p, tri[:, 0], tri[:, 1], tri[:, 2]).points
    assert_close(q, r.closest_points)
    # both sign methods agree on a watertight mesh
    assert torch.equal(M.mesh_sdf(V, F, p, sign="winding").sdf, r.sdf)
    assert_close(M.mesh_sdf(V, F, p, sign="none").sdf, r.sdf.abs())


def test_against_trimesh():
    m = MESHES["torus"]()
    V, F = _mesh(m)
    p = _points(m, 150, seed=3)
    ours = M.mesh_sdf(V, F, p).sdf.numpy()
    theirs = trimesh.proximity.signed_distance(m, p.numpy())  # positive inside
    np.testing.assert_allclose(ours, -theirs, atol=1e-9)


def test_signs_next_to_sharp_edges_and_corners():
    """Points just off a cube's edges and corners, where face normals alone fail."""
    V, F = _mesh(trimesh.creation.box(extents=(2.0, 2.0, 2.0)))
    dirs = torch.tensor([[1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 1, 1], [-1, 1, 1], [1, -1, -1]],
                        dtype=torch.float64)
    base = dirs  # edge midpoints and corners of the cube [-1, 1]^3
    eps = torch.tensor([1e-3, -1e-3, 1e-6, -1e-6], dtype=torch.float64)
    p = (base[:, None] * (1 + eps[None, :, None])).reshape(-1, 3)
    sdf = M.mesh_sdf(V, F, p).sdf
    from torchgeo_cg.sdf.primitives import box

    ref = box(p)
    assert torch.equal(sdf < 0, ref < 0)
    assert_close(sdf, ref, atol=1e-12, rtol=0)


def test_closest_point_on_triangle_features():
    a = torch.tensor([0.0, 0.0, 0.0])
    b = torch.tensor([1.0, 0.0, 0.0])
    c = torch.tensor([0.0, 1.0, 0.0])
    p = torch.tensor([[0.2, 0.2, 1.0], [0.5, -1.0, 0.0], [1.0, 1.0, 0.0], [-0.5, 0.5, 2.0],
                      [-1.0, -1.0, 0.0], [2.0, -0.1, 0.0], [-0.1, 3.0, 0.0]])
    r = S.closest_point_on_triangle(p, a, b, c)
    assert r.feature.tolist() == [0, 1, 2, 3, 4, 5, 6]
    assert_close(r.points, torch.tensor([[0.2, 0.2, 0.0], [0.5, 0.0, 0.0], [0.5, 0.5, 0.0],
                                         [0.0, 0.5, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0],
                                         [0.0, 1.0, 0.0]]))


def test_degenerate_faces_are_harmless():
    m = MESHES["icosphere"]()
    V, F = _mesh(m)
    p = _points(m, 100)
    clean = M.mesh_sdf(V, F, p).sdf
    # a zero-area face (repeated vertex) and a collinear sliver along an existing edge
    e0, e1 = F[0, 0], F[0, 1]
    mid = (V[e0] + V[e1]) / 2
    V2 = torch.cat([V, mid[None]])
    F2 = torch.cat([F, torch.tensor([[e0, e0, e1], [e0, V.shape[0], e1]])])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = M.mesh_sdf(V2, F2, p, sign="pseudonormal")
    assert torch.isfinite(r.sdf).all()
    assert_close(r.sdf, clean)
    pts = p.clone().requires_grad_(True)
    M.mesh_sdf(V2, F2, pts, sign="pseudonormal").sdf.sum().backward()
    assert torch.isfinite(pts.grad).all()


def test_open_mesh_warns_and_uses_winding_numbers():
    m = MESHES["icosphere"]()
    V, F = _mesh(m)
    F_open = F[3:]  # three holes
    assert M.is_watertight(F) and not M.is_watertight(F_open)
    p = torch.tensor([[0.0, 0.0, 0.0], [0.1, 0.2, -0.1], [2.0, 0.0, 0.0], [0.0, -1.5, 0.3]],
                     dtype=torch.float64)
    with pytest.warns(RuntimeWarning, match="watertight"):
        r = M.mesh_sdf(V, F_open, p)
    assert (r.sdf[:2] < 0).all() and (r.sdf[2:] > 0).all()
    assert_close(r.sdf, M.mesh_sdf(V, F_open, p, sign="winding").sdf)
    w = M.winding_number(V, F_open, p)
    assert (w[:2] > 0.5).all() and (w[:2] < 1.0).all()  # fractional near holes


def test_batched_points_dtype_and_gradcheck():
    m = trimesh.creation.icosphere(subdivisions=1)
    V, F = _mesh(m)
    p = _points(m, 24).reshape(2, -1, 3)
    r = M.mesh_sdf(V, F, p, return_closest=True)
    assert r.sdf.shape == p.shape[:-1] and r.closest_points.shape == p.shape
    assert r.face_ids.shape == p.shape[:-1]
    assert_close(r.sdf[1], M.mesh_sdf(V, F, p[1]).sdf)
    r32 = M.mesh_sdf(V.float(), F, p.float())
    assert r32.sdf.dtype == torch.float32
    assert_close(r32.sdf, r.sdf.float())
    q = (torch.tensor([[0.3, 0.1, 0.2], [1.5, 0.2, -0.4]], dtype=torch.float64)
         .requires_grad_(True))
    V0, F0 = _mesh(trimesh.creation.icosphere(subdivisions=0))  # 12 vertices keep it quick
    Vg = V0.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda a, b: M.mesh_sdf(b, F0, a).sdf, (q, Vg))


def test_device_dtype(device, dtype):
    V, F = _mesh(trimesh.creation.icosphere(subdivisions=1), dtype)
    V, F = V.to(device), F.to(device)
    p = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0]], device=device, dtype=dtype)
    out = M.mesh_sdf(V, F, p).sdf
    assert out.device == p.device and out.dtype == dtype
    assert out[0] < -0.9 and abs(float(out[1]) - 1.0) < 1e-6


def test_bad_input():
    V, F = _mesh(trimesh.creation.icosphere(subdivisions=0))
    p = torch.zeros(2, 3, dtype=torch.float64)
    bad = V.clone()
    bad[0, 0] = math.nan
    with pytest.raises(ValueError, match="finite"):
        M.mesh_sdf(bad, F, p)
    with pytest.raises(ValueError, match="indices"):
        M.mesh_sdf(V, F + 100, p)
    with pytest.raises(ValueError, match="indices"):
        M.mesh_sdf(V, F - 1, p)
    with pytest.raises(ValueError, match="non-empty"):
        M.mesh_sdf(V, F[:0], p)
    with pytest.raises(ValueError, match="non-empty"):
        M.mesh_sdf(V[:0], F[:0], p)
    with pytest.raises(ShapeError, match="points"):
        M.mesh_sdf(V, F, torch.zeros(2, 2, dtype=torch.float64))
    with pytest.raises(ShapeError, match="faces"):
        M.mesh_sdf(V, F[:, :2], p)
    with pytest.raises(TypeError, match="integer"):
        M.mesh_sdf(V, F.double(), p)
    with pytest.raises(ValueError, match="sign"):
        M.mesh_sdf(V, F, p, sign="rays")


# --- batched meshes and polygon faces -------------------------------------------------------


def test_batched_vertices_match_a_loop():
    V, F = _mesh(trimesh.creation.icosphere(subdivisions=2))
    gen = torch.Generator().manual_seed(1)
    verts = V * (1.0 + 0.3 * torch.rand(3, 1, 1, generator=gen, dtype=V.dtype))  # 3 shapes
    verts = verts + 0.05 * torch.randn(verts.shape, generator=gen, dtype=V.dtype)
    p = 1.5 * (torch.rand(3, 70, 3, generator=gen, dtype=V.dtype) * 2 - 1)
    r = M.mesh_sdf(verts, F, p, return_closest=True, sign="winding")
    for b in range(3):
        one = M.mesh_sdf(verts[b], F, p[b], return_closest=True, sign="winding")
        assert_close(r.sdf[b], one.sdf, atol=1e-14, rtol=0)
        assert_close(r.closest_points[b], one.closest_points, atol=1e-14, rtol=0)
        assert torch.equal(r.face_ids[b], one.face_ids)
        assert_close(M.winding_number(verts, F, p)[b], M.winding_number(verts[b], F, p[b]))
    # one point set against every shape (batch dims broadcast), and batch dims (2, 3)
    shared = M.mesh_sdf(verts, F, p[0]).sdf
    assert shared.shape == (3, 70)
    assert_close(shared[2], M.mesh_sdf(verts[2], F, p[0]).sdf, atol=1e-14, rtol=0)
    two = M.mesh_sdf(verts.expand(2, 3, -1, -1), F, p).sdf
    assert two.shape == (2, 3, 70)
    assert_close(two[1], r.sdf, atol=1e-14, rtol=0)


def test_polygon_faces_are_triangulated():
    from torchgeo_cg.mesh.faces import triangulate_faces

    # a unit cube of 6 quads, wound outward; mixed with a padded triangle row
    V = torch.tensor([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1],
                      [1, 1, 1], [0, 1, 1]], dtype=torch.float64)
    quads = torch.tensor([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [2, 3, 7, 6],
                          [1, 2, 6, 5], [0, 4, 7, 3]])
    p = torch.tensor([[0.5, 0.5, 0.5], [0.2, 0.9, 0.5], [2.0, 0.5, 0.5], [1.5, 1.5, 1.5]],
                     dtype=torch.float64)
    r = M.mesh_sdf(V, quads, p, return_closest=True)
    from torchgeo_cg.sdf.primitives import box

    assert_close(r.sdf, box(p - 0.5, torch.tensor([0.5, 0.5, 0.5], dtype=torch.float64)),
                 atol=1e-12, rtol=0)
    tris = triangulate_faces(quads)
    assert torch.equal(r.face_ids, M.mesh_sdf(V, tris, p, return_closest=True).face_ids)
    assert_close(M.winding_number(V, quads, p), torch.tensor([1.0, 1, 0, 0],
                                                              dtype=torch.float64))
    with pytest.raises(ValueError, match="indices"):
        M.mesh_sdf(V, torch.tensor([[0, 1, 2, 9]]), p)


# --- numerics at every scale, empty inputs --------------------------------------------------

TET_V = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=torch.float64)
TET_F = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
TET_P = torch.tensor([[0.1, 0.2, 0.3], [0.2, 0.2, -2.0], [0.05, 0.05, 0.05], [1.0, 1.0, 1.0]],
                     dtype=torch.float64)
# hand-derived: distances to the planes x = 0, z = 0, and to the slanted face x + y + z = 1
TET_SDF = torch.tensor([-0.1, 2.0, -0.05, 2.0 / math.sqrt(3.0)], dtype=torch.float64)


@pytest.mark.parametrize("s", [1e-15, 1e-6, 1.0, 1e6, 1e77, 1e155, 1e-150, 1e-300, 1e300])
@pytest.mark.parametrize("sign", ["pseudonormal", "winding"])
def test_scale_equivariance_float64(s, sign):
    r = M.mesh_sdf(TET_V * s, TET_F, TET_P * s, sign=sign, return_closest=True)
    assert torch.isfinite(r.sdf).all()
    assert_close(r.sdf / s, TET_SDF, atol=1e-12, rtol=1e-12)
    plain = M.mesh_sdf(TET_V * s, TET_F, TET_P * s, sign=sign).sdf  # an engine's own path
    assert_close(plain / s, TET_SDF, atol=1e-12, rtol=1e-12)
    assert torch.equal(r.face_ids, M.mesh_sdf(TET_V, TET_F, TET_P, sign=sign,
                                              return_closest=True).face_ids)
    w = M.winding_number(TET_V * s, TET_F, TET_P * s)
    assert_close(w.abs(), torch.tensor([1.0, 0, 1, 0], dtype=torch.float64), atol=1e-12, rtol=0)


def test_scale_float32():
    for s in (1e-6, 1e-3, 1e3, 1e6):
        r = M.mesh_sdf((TET_V * s).float(), TET_F, (TET_P * s).float()).sdf
        assert_close(r / s, TET_SDF.float(), atol=1e-5, rtol=1e-5)


def test_empty_inputs_give_empty_outputs():
    V, F = _mesh(trimesh.creation.icosphere(subdivisions=1))
    empty = torch.zeros(0, 3, dtype=torch.float64)
    assert M.winding_number(V, F, empty).shape == (0,)
    for sign in ("auto", "pseudonormal", "winding", "none"):
        r = M.mesh_sdf(V, F, empty, sign=sign, return_closest=True)
        assert r.sdf.shape == (0,) and r.closest_points.shape == (0, 3)
        assert r.face_ids.shape == (0,)
    with pytest.warns(RuntimeWarning, match="watertight"):
        assert M.mesh_sdf(V, F[3:], empty).sdf.shape == (0,)
    assert M.mesh_sdf(V, F, torch.zeros(4, 0, 3, dtype=torch.float64)).sdf.shape == (4, 0)
    assert M.mesh_sdf(V.expand(0, -1, -1), F, empty).sdf.shape == (0, 0)
    assert M.winding_number(V, F, torch.zeros(2, 0, 3, dtype=torch.float64)).shape == (2, 0)


def test_nan_points_give_nan():
    V, F = _mesh(trimesh.creation.icosphere(subdivisions=1))
    p = torch.tensor([[0.0, 0.0, 0.0], [math.nan, 0.0, 0.0], [0.0, 0.0, 2.0]],
                     dtype=torch.float64)
    r = M.mesh_sdf(V, F, p).sdf
    assert torch.isnan(r[1]) and torch.isfinite(r[[0, 2]]).all()
    assert_close(r[[0, 2]], M.mesh_sdf(V, F, p[[0, 2]]).sdf)


# --- progress, vmap, jacrev -----------------------------------------------------------------


def test_progress_bar(capsys):
    V, F = _mesh(trimesh.creation.icosphere(subdivisions=1))
    p = _points(trimesh.creation.icosphere(subdivisions=1), 50)
    quiet = M.mesh_sdf(V, F, p, backend="torch").sdf
    assert capsys.readouterr().err == ""
    loud = M.mesh_sdf(V, F, p, backend="torch", progress=True).sdf
    assert "mesh_sdf" in capsys.readouterr().err
    assert torch.equal(quiet, loud)


def test_vmap_and_jacrev():
    V, F = _mesh(trimesh.creation.icosphere(subdivisions=1))
    gen = torch.Generator().manual_seed(2)
    p = 1.5 * (torch.rand(4, 9, 3, generator=gen, dtype=V.dtype) * 2 - 1)
    verts = V * (1 + 0.2 * torch.rand(4, 1, 1, generator=gen, dtype=V.dtype))
    direct = M.mesh_sdf(V, F, p).sdf
    assert_close(torch.func.vmap(lambda q: M.mesh_sdf(V, F, q).sdf)(p), direct)
    batched = torch.func.vmap(lambda v, q: M.mesh_sdf(v, F, q).sdf)(verts, p)
    assert_close(batched, M.mesh_sdf(verts, F, p).sdf)
    # jacrev w.r.t. the points: the gradient of a distance is the unit vector (p - q)/|p - q|
    jac = torch.func.jacrev(lambda q: M.mesh_sdf(V, F, q).sdf)(p[0])  # (9, 9, 3)
    r = M.mesh_sdf(V, F, p[0], return_closest=True)
    unit = (p[0] - r.closest_points) / r.sdf[:, None]
    assert_close(jac.diagonal(dim1=0, dim2=1).t(), unit, atol=1e-10, rtol=0)
    assert_close(jac.sum((1, 2)) - jac.diagonal(dim1=0, dim2=1).sum(0),
                 torch.zeros(9, dtype=V.dtype))
    jv = torch.func.jacrev(lambda v: M.mesh_sdf(v, F, p[0]).sdf)(V)
    vv = V.clone().requires_grad_(True)
    M.mesh_sdf(vv, F, p[0]).sdf[3].backward()
    assert_close(jv[3], vv.grad)


# --- backends -------------------------------------------------------------------------------

from torchgeo_cg.sdf import _closest_faces as CF  # noqa: E402
from torchgeo_cg.sdf import engines as E  # noqa: E402

BACKENDS = ["torch", *E.ENGINES]


def _backend(name):
    if name != "torch":
        pytest.importorskip(E.ENGINES[name])
    return name


def _all_face_d2(vertices, faces, points):
    """(N, F) squared distance of every point to every face, written here (Ericson's
    region tests, 'Real-Time Collision Detection' 5.1.5), float64."""
    tri = vertices[faces]
    p = points[:, None]
    a, b, c = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]

    def d2_seg(u, v):
        t = (((p - u) * (v - u)).sum(-1) / ((v - u) ** 2).sum(-1)).clamp(0, 1)
        return ((p - u - t[..., None] * (v - u)) ** 2).sum(-1)

    n = torch.cross(b - a, c - a, dim=-1)
    h = ((p - a) * n).sum(-1) / (n * n).sum(-1)
    q = p - h[..., None] * n
    s1 = (torch.cross(b - a, q - a, dim=-1) * n).sum(-1)
    s2 = (torch.cross(c - b, q - b, dim=-1) * n).sum(-1)
    s3 = (torch.cross(a - c, q - c, dim=-1) * n).sum(-1)
    edges = torch.minimum(torch.minimum(d2_seg(a, b), d2_seg(b, c)), d2_seg(c, a))
    plane = ((p - q) ** 2).sum(-1)
    return torch.where((s1 >= 0) & (s2 >= 0) & (s3 >= 0), torch.minimum(plane, edges), edges)


def _winding_reference(vertices, faces, points):
    """Solid-angle sum (Van Oosterom & Strackee), written here in numpy."""
    tri = vertices[faces].numpy()[None]
    x = tri - points.numpy()[:, None, None]
    a, b, c = x[:, :, 0], x[:, :, 1], x[:, :, 2]
    la, lb, lc = (np.linalg.norm(y, axis=-1) for y in (a, b, c))
    det = np.einsum("nfk,nfk->nf", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("nfk,nfk->nf", a, b) * lc
           + np.einsum("nfk,nfk->nf", a, c) * lb + np.einsum("nfk,nfk->nf", b, c) * la)
    return torch.from_numpy(2 * np.arctan2(det, den).sum(1) / (4 * np.pi))


def _bumpy_sphere():
    m = trimesh.creation.icosphere(subdivisions=3)
    v = m.vertices
    r = 1 + 0.15 * np.sin(5 * v[:, 0]) * np.sin(4 * v[:, 1]) * np.cos(3 * v[:, 2])
    return trimesh.Trimesh(v * r[:, None], m.faces, process=False)


REFERENCE_MESHES = {
    "torus": lambda: trimesh.creation.torus(1.0, 0.3, major_sections=32, minor_sections=16),
    "bumpy_sphere": _bumpy_sphere,
    "open_sphere": lambda: trimesh.Trimesh(*(lambda m: (m.vertices, m.faces[12:]))(
        trimesh.creation.icosphere(subdivisions=2)), process=False),
}


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
@pytest.mark.parametrize("mesh", sorted(REFERENCE_MESHES))
@pytest.mark.parametrize("backend", BACKENDS)
def test_backend_against_all_faces(backend, mesh, scale):
    m = REFERENCE_MESHES[mesh]()
    V, F = _mesh(m)
    p = _points(m, 400, seed=5)
    V, p = V * scale, p * scale
    sign = "winding" if mesh == "open_sphere" else "pseudonormal"
    r = M.mesh_sdf(V, F, p, sign=sign, return_closest=True, backend=_backend(backend))
    d2 = _all_face_d2(V, F, p)
    best = d2.min(1).values
    # same face, or an equidistant one; distance within 1e-12 of the mesh size
    chosen = d2.gather(1, r.face_ids[:, None]).squeeze(1)
    size = float((V.amax(0) - V.amin(0)).max())
    assert ((chosen.sqrt() - best.sqrt()).abs() <= 1e-12 * size).all()
    assert_close(r.sdf.abs(), best.sqrt(), atol=1e-12 * size, rtol=0)
    assert torch.equal(r.sdf < 0, _winding_reference(V, F, p) > 0.5)
    # without closest points or gradients an engine answers alone (its kernel evaluates)
    plain = M.mesh_sdf(V, F, p, sign=sign, backend=backend).sdf
    assert_close(plain.abs(), best.sqrt(), atol=1e-12 * size, rtol=0)
    assert torch.equal(plain < 0, r.sdf < 0)
    unsigned = M.mesh_sdf(V, F, p, sign="none", backend=backend).sdf
    assert_close(unsigned, best.sqrt(), atol=1e-12 * size, rtol=0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_backends_agree_and_gradients_identical(backend):
    m = _bumpy_sphere()
    V, F = _mesh(m)
    p = _points(m, 300, seed=7)
    ref = M.mesh_sdf(V, F, p, return_closest=True, backend="torch")
    r = M.mesh_sdf(V, F, p, return_closest=True, backend=_backend(backend))
    assert_close(r.sdf, ref.sdf, atol=1e-12, rtol=0)
    assert_close(r.closest_points, ref.closest_points, atol=1e-12, rtol=0)
    grads = []
    for name in ("torch", backend):
        vv, pp = V.clone().requires_grad_(True), p.clone().requires_grad_(True)
        M.mesh_sdf(vv, F, pp, backend=name).sdf.square().sum().backward()
        grads.append((vv.grad, pp.grad))
    assert_close(grads[1][0], grads[0][0], atol=1e-12, rtol=0)
    assert_close(grads[1][1], grads[0][1], atol=1e-12, rtol=0)


@pytest.mark.grad
@pytest.mark.parametrize("backend", BACKENDS)
def test_gradcheck_with_each_backend(backend):
    V0, F0 = _mesh(trimesh.creation.icosphere(subdivisions=0))
    q = torch.tensor([[0.3, 0.1, 0.2], [1.5, 0.2, -0.4], [0.0, -1.2, 0.1]], dtype=torch.float64)
    fn = lambda a, b: M.mesh_sdf(b, F0, a, backend=_backend(backend)).sdf  # noqa: E731
    assert torch.autograd.gradcheck(fn, (q.requires_grad_(True), V0.clone().requires_grad_(True)))


def test_backend_names_and_missing_engine(monkeypatch):
    V, F = TET_V, TET_F
    with pytest.raises(ValueError, match="backend"):
        M.mesh_sdf(V, F, TET_P, backend="embree9")
    monkeypatch.setitem(E.ENGINES, "ghost", "no_such_module_for_torchgeo_cg")
    with pytest.raises(ImportError, match="fast"):
        M.mesh_sdf(V, F, TET_P, backend="ghost")
    assert "ghost" not in E.available_engines()
    expected = E.available_engines()[0] if E.available_engines() else "torch"
    assert CF.resolve_backend("auto") == expected
    with pytest.raises(ImportError, match="fast"):
        M.MeshSDF(V, F, backend="ghost")


class _BrokenWarp:
    """A meta path finder under which ``warp`` is found (installed) but importing it raises
    what a missing CUDA driver library raises."""

    def find_spec(self, name, path=None, target=None):
        if name != "warp":
            return None
        return importlib.util.spec_from_loader(name, self)

    def create_module(self, spec):
        return None

    def exec_module(self, module):
        raise OSError("libcuda.so: cannot open shared object file")


@pytest.fixture
def broken_warp(monkeypatch):
    """Warp installed but failing to import: the engine module is imported afresh under
    :class:`_BrokenWarp`; the real modules come back after the test."""
    for name in ("warp", "torchgeo_cg.sdf._engine_warp"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    if hasattr(S, "_engine_warp"):  # the fresh import rebinds it; restored at teardown
        monkeypatch.setattr(S, "_engine_warp", S._engine_warp)
    monkeypatch.setattr(sys, "meta_path", [_BrokenWarp(), *sys.meta_path])
    _forget_warp(monkeypatch)


def _forget_warp(monkeypatch):
    """The engine layer loads Warp once per process: forget that load (and its warning)
    for one test; the real state comes back after it."""
    monkeypatch.setattr(engine_backend, "_STATE", {})
    monkeypatch.setattr(engine_backend, "_WARNED", set())
    monkeypatch.delenv(engine_backend.DISABLE_ENV, raising=False)


def test_engine_that_fails_to_import(broken_warp):
    """An installed engine whose import raises (not ImportError): ``auto`` warns once and
    gives the torch results; an explicit ``warp`` raises an ImportError chained from it."""
    m = trimesh.creation.icosphere(subdivisions=1)
    V, F = _mesh(m)
    p = _points(m, 50, seed=3)
    with pytest.warns(UserWarning, match="failed to import.*OSError: libcuda.so") as record:
        assert CF.resolve_backend("auto") == "torch"
        got = M.mesh_sdf(V, F, p, return_closest=True)  # backend="auto"
        M.MeshSDF(V, F)
    assert len([w for w in record if "failed to import" in str(w.message)]) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no second warning
        M.mesh_sdf(V, F, p)
    want = M.mesh_sdf(V, F, p, return_closest=True, backend="torch")
    assert torch.equal(got.sdf, want.sdf) and torch.equal(got.closest_points,
                                                          want.closest_points)
    assert E.available_engines() == []
    with pytest.raises(ImportError, match="installed but failed to import.*libcuda") as info:
        M.mesh_sdf(V, F, p, backend="warp")
    assert isinstance(info.value.__cause__, OSError)
    assert "fast" not in str(info.value)  # not the message of a missing extra
    with pytest.raises(ImportError, match="failed to import"):
        M.MeshSDF(V, F, backend="warp")
    from torchgeo_cg.sdf import _engine_warp as broken

    with pytest.raises(ImportError, match="failed to import") as info:
        broken.build_warp_search(V[None], F)
    assert isinstance(info.value.__cause__, OSError)


def test_missing_engine_message_differs_from_failed_import(monkeypatch):
    """Not installed at all: the message names the extra and no warning is given."""
    monkeypatch.setitem(sys.modules, "warp", None)  # find_spec finds nothing
    _forget_warp(monkeypatch)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert CF.resolve_backend("auto") == "torch"
    with pytest.raises(ImportError, match="optional extra 'fast'") as info:
        CF.resolve_backend("warp")
    assert "failed to import" not in str(info.value)


@pytest.mark.parametrize("backend", BACKENDS)
def test_mesh_sdf_module_caches_its_structure(backend, monkeypatch):
    import copy

    backend = _backend(backend)
    m = trimesh.creation.icosphere(subdivisions=2)
    V, F = _mesh(m)
    p = _points(m, 100, seed=9)
    module = M.MeshSDF(V, F, backend=backend)
    ref = M.mesh_sdf(V, F, p, return_closest=True, backend=backend)
    ref2 = M.mesh_sdf(2 * V, F, p, backend=backend)
    builds = []
    real = CF._build_search
    monkeypatch.setattr(CF, "_build_search", lambda *a: builds.append(1) or real(*a))
    first = module(p, return_closest=True)
    second = module(p.flip(0))
    assert len(builds) == 1  # the second query reused the structure
    assert torch.equal(first.sdf, ref.sdf)
    assert_close(second.sdf, ref.sdf.flip(0), atol=1e-14, rtol=0)  # an engine's own float64
    module.verts.mul_(2.0)  # an in-place edit rebuilds
    assert_close(module(p).sdf, ref2.sdf, atol=1e-12, rtol=0)
    assert len(builds) == 2
    twin = copy.deepcopy(module)
    assert_close(twin(p).sdf, module(p).sdf, atol=0, rtol=0)
    fresh = M.MeshSDF(V, F, backend=backend)
    fresh.load_state_dict(module.state_dict())
    assert_close(fresh(p).sdf, module(p).sdf, atol=0, rtol=0)
    assert module.to(torch.float32)(p.float()).sdf.dtype == torch.float32


def test_without_the_extra_auto_falls_back_to_torch():
    """A fresh process where the engine cannot be imported, as on an install without
    ``fast``: ``auto`` is torch, an explicit engine raises ImportError naming the extra,
    and the engine module still imports (its doctests pass)."""
    import subprocess
    import sys

    script = """
import sys, doctest, warnings
sys.modules["warp"] = None  # import warp now fails, find_spec finds nothing
import torch
from torchgeo_cg.sdf import _closest_faces, _engine_warp as engine_warp, engines, mesh_sdf
assert engines.available_engines() == [] and _closest_faces.resolve_backend("auto") == "torch"
v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=torch.float64)
f = torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
p = torch.tensor([[0.1, 0.2, 0.3]], dtype=torch.float64)
assert abs(float(mesh_sdf(v, f, p).sdf[0]) + 0.1) < 1e-12
try:
    mesh_sdf(v, f, p, backend="warp")
    raise SystemExit("no ImportError")
except ImportError as e:
    assert "fast" in str(e), e
failed, tried = doctest.testmod(engine_warp, optionflags=doctest.ELLIPSIS)
assert failed == 0 and tried > 0, (failed, tried)
print("ok")
"""
    import os

    env = {k: v for k, v in os.environ.items() if k != engine_backend.DISABLE_ENV}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=300, env=env)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]


@pytest.mark.slow
def test_mesh_sdf_module_under_compile_vmap_jacrev():
    V, F = _mesh(trimesh.creation.icosphere(subdivisions=1))
    p = torch.rand(2, 30, 3, generator=torch.Generator().manual_seed(4), dtype=V.dtype) * 2 - 1
    module = M.MeshSDF(V, F)
    eager = module(p).sdf
    assert_close(torch.compile(module)(p).sdf, eager, atol=1e-14, rtol=0)
    assert_close(torch.func.vmap(lambda q: module(q).sdf)(p), eager, atol=1e-14, rtol=0)
    jac = torch.func.jacrev(lambda q: module(q).sdf)(p[0])
    r = module(p[0], return_closest=True)
    unit = (p[0] - r.closest_points) / r.sdf[:, None]
    assert_close(jac.diagonal(dim1=0, dim2=1).t(), unit, atol=1e-10, rtol=0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_points_beyond_float32_range(backend):
    """An engine searches in float32: points beyond its range are moved along their own
    direction before the search; the float64 answer still matches the torch backend."""
    p = torch.tensor([[1e200, 3e199, -2e199], [0.2, -1e300, 0.1], [0.1, 0.2, 0.3]],
                     dtype=torch.float64)
    got = M.mesh_sdf(TET_V, TET_F, p, backend=_backend(backend)).sdf
    want = M.mesh_sdf(TET_V, TET_F, p, backend="torch").sdf
    assert torch.isfinite(got).all()
    assert_close(got, want, rtol=1e-12, atol=0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_repeated_calls_reuse_only_an_identical_mesh(backend, monkeypatch):
    """Plain ``mesh_sdf`` calls keep an engine's structure for exactly the last mesh: a
    second call on the same mesh does not rebuild, an in-place edit (same storage) does."""
    backend = _backend(backend)
    m = trimesh.creation.icosphere(subdivisions=2)
    V, F = _mesh(m)
    p = _points(m, 50, seed=3)
    want2 = M.mesh_sdf(2 * V, F, p, backend="torch").sdf
    builds = []
    real = CF._build_search
    monkeypatch.setattr(CF, "_build_search", lambda *a: builds.append(1) or real(*a))
    first = M.mesh_sdf(V, F, p, backend=backend).sdf
    again = M.mesh_sdf(V, F, p, backend=backend).sdf
    assert torch.equal(first, again)
    reused = len(builds)
    V.mul_(2.0)
    assert_close(M.mesh_sdf(V, F, p, backend=backend).sdf, want2, atol=1e-12, rtol=0)
    assert reused == (1 if backend != "torch" else 2) and len(builds) == reused + 1


# --- scale, dtype policy ---------------------------------------------------------------------

UNIT_TRI = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=torch.float64)


@pytest.mark.parametrize("dtype, s", [(torch.float64, 1e-170), (torch.float64, 1e-100),
                                      (torch.float64, 1e100), (torch.float64, 1e160),
                                      (torch.float32, 1e-12), (torch.float32, 1e12),
                                      (torch.float32, 1e20)])
def test_closest_point_on_triangle_at_any_scale(dtype, s):
    # hand-derived: the point (0.2, 0.3, 0.5) projects into the triangle z = 0; before the
    # fix the 4th powers of the lengths under/overflowed: an edge point at 1e-100 and 1e100,
    # a vertex at 1e-170, NaN at 1e160 (float32: an edge at 1e+-12, NaN at 1e20)
    p = torch.tensor([[0.2, 0.3, 0.5], [2.0, -0.5, 0.0]], dtype=torch.float64)
    r = S.closest_point_on_triangle((p * s).to(dtype), *(UNIT_TRI * s).to(dtype))
    assert r.feature.tolist() == [0, 5]
    want = torch.tensor([[0.2, 0.3, 0.0], [1.0, 0.0, 0.0]], dtype=torch.float64)
    assert_close((r.points.double() / s), want, atol=1e-6 if dtype == torch.float32 else 1e-14,
                 rtol=0)


def test_mixed_dtypes_follow_the_points_or_raise_naming_both():
    # the mesh follows the points (winding numbers as well as distances)
    V, F, p32 = TET_V, TET_F, TET_P.float()
    ref = M.mesh_sdf(V.float(), F, p32).sdf
    assert torch.equal(M.mesh_sdf(V, F, p32).sdf, ref)
    assert torch.equal(M.MeshSDF(V, F, backend="torch")(p32).sdf, ref)
    w = M.winding_number(V, F, p32)
    assert w.dtype == torch.float32 and torch.equal(w, M.winding_number(V.float(), F, p32))
    with pytest.raises(TypeError, match="v1 is torch.float32 on cpu but points"):
        S.closest_point_on_triangle(TET_P, V[0], V[1].float(), V[2])  # not promoted


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16])
def test_low_precision_is_computed_in_float32(low):
    V, F, P = TET_V.to(low), TET_F, TET_P.to(low)
    ref = M.mesh_sdf(V.float(), F, P.float(), return_closest=True)
    r = M.mesh_sdf(V, F, P, return_closest=True)
    assert r.sdf.dtype == low and r.closest_points.dtype == low
    assert torch.equal(r.sdf, ref.sdf.to(low))
    assert torch.equal(r.closest_points, ref.closest_points.to(low))
    assert torch.equal(r.face_ids, ref.face_ids)
    assert torch.equal(M.MeshSDF(V, F, backend="torch")(P).sdf, ref.sdf.to(low))
    w = M.winding_number(V, F, P)
    assert w.dtype == low and torch.equal(w, M.winding_number(V.float(), F, P.float()).to(low))
    c = S.closest_point_on_triangle(P, V[0], V[1], V[2])
    c32 = S.closest_point_on_triangle(P.float(), V[0].float(), V[1].float(), V[2].float())
    assert c.points.dtype == low and torch.equal(c.points, c32.points.to(low))
    assert torch.equal(c.feature, c32.feature)


@pytest.mark.parametrize("dtype, s", [(torch.float64, 1.5e308), (torch.float32, 2.5e38)])
@pytest.mark.parametrize("sign", ["pseudonormal", "winding"])
def test_top_of_the_float_range(dtype, s, sign):
    # the power-of-two scale was 2^1024 = inf there (2^128 in float32): NaN distances
    rows = [0, 2, 3]  # inputs and distances below the largest finite value
    V, P = (TET_V * s).to(dtype), (TET_P[rows] * s).to(dtype)
    r = M.mesh_sdf(V, TET_F, P, sign=sign, backend="torch").sdf
    assert_close(r.double() / s, TET_SDF[rows], atol=1e-6, rtol=0)


@pytest.mark.parametrize("dtype, far", [(torch.float32, 1e6), (torch.float64, 1e15)])
def test_closest_point_of_a_far_point_above_a_face(dtype, far):
    """Hand-derived: below the face z = 0 of the tetrahedron, at (0.1, 0.2, -far), the
    closest point is (0.1, 0.2, 0) and the distance is far (within 1/eps mesh sizes)."""
    p = torch.tensor([[0.1, 0.2, -far]], dtype=dtype)
    r = M.mesh_sdf(TET_V.to(dtype), TET_F, p, return_closest=True)
    want = torch.tensor([[0.1, 0.2, 0.0]], dtype=dtype)
    eps = torch.finfo(dtype).eps
    assert_close(r.closest_points, want, atol=16 * eps, rtol=0)  # to the mesh size
    assert_close(r.sdf, torch.tensor([far], dtype=dtype), rtol=4 * eps, atol=0)


@pytest.mark.parametrize("s", [1.0, 1e3, 1e-3, 2.0**40])
@pytest.mark.parametrize("offset", [1e-4, 2e-4, 1e-3])
def test_closest_point_near_a_corner_is_on_the_edge_in_float32(offset, s):
    """The foot on edge v2v0 lies ``offset`` from v0; the corner (the clamped candidate of
    edge v0v1) is farther by only ``offset^2``, below float32's rounding of the squared
    distances. The clamp tests decide, not the distances: the edge point comes back."""
    from torchgeo_cg.sdf import closest_point_on_triangle

    v0, v1, v2 = (torch.tensor(v, dtype=torch.float32) * s
                  for v in ([0.0, 0, 0], [1.0, 0, 0], [0.0, 1, 0]))
    p = torch.tensor([-1.0, offset, 0.3], dtype=torch.float32) * s
    out = closest_point_on_triangle(p, v0, v1, v2)
    assert int(out.feature) == 3  # the edge v2v0, not the corner v0 (4)
    want = torch.tensor([0.0, offset, 0.0]) * s
    assert float((out.points - want).abs().max()) <= 2e-7 * s
    # the projection inside the face wins over an edge that rounding ties with it
    inside = closest_point_on_triangle(torch.tensor([offset, 0.5, 1.0]) * s, v0, v1, v2)
    assert int(inside.feature) == 0
    assert float((inside.points - torch.tensor([offset, 0.5, 0.0]) * s).abs().max()) <= 2e-7 * s
