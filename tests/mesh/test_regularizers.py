"""Mesh regularizers against formulas written here (explicit loops over a small mesh)."""

from __future__ import annotations

import math

import pytest
import torch
import trimesh

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.mesh import (
    edge_length_loss,
    laplacian_smoothing_loss,
    mesh_edges,
    mesh_laplacian,
    normal_consistency_loss,
)


def flat_grid(n: int, quads: bool):
    """(n x n) vertices on z = 0 (with a random in-plane jitter for cotangents)."""
    ij = torch.cartesian_prod(torch.arange(n), torch.arange(n))
    verts = torch.cat([ij.double(), torch.zeros(n * n, 1, dtype=torch.float64)], 1)
    cells = [(i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1)
             for i in range(n - 1) for j in range(n - 1)]
    if quads:
        return verts, torch.tensor(cells)
    tris = [t for a, b, c, d in cells for t in ((a, b, c), (a, c, d))]
    return verts, torch.tensor(tris)


def polygon_edges(faces):
    edges = set()
    for f in faces:
        f = [int(v) for v in f if v >= 0]
        for k in range(len(f)):
            a, b = f[k], f[(k + 1) % len(f)]
            edges.add((min(a, b), max(a, b)))
    return sorted(edges)


def reference_uniform(verts, faces):
    out = torch.zeros_like(verts)
    nbrs = {}
    for a, b in polygon_edges(faces):
        nbrs.setdefault(a, []).append(b)
        nbrs.setdefault(b, []).append(a)
    for i, js in nbrs.items():
        out[i] = verts[js].mean(0) - verts[i]
    return out


def reference_cotangent(verts, faces):
    w = {}
    for f in faces.tolist():
        f = [v for v in f if v >= 0]
        for t in range(1, len(f) - 1):  # fan triangulation
            tri = (f[0], f[t], f[t + 1])
            for k in range(3):
                o, i, j = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
                u, v = verts[i] - verts[o], verts[j] - verts[o]
                angle = math.acos(float((u @ v) / (u.norm() * v.norm())))
                for a, b in ((i, j), (j, i)):
                    w[(a, b)] = w.get((a, b), 0.0) + 1 / math.tan(angle)
    out = torch.zeros_like(verts)
    total = torch.zeros(verts.shape[0], dtype=verts.dtype)
    for (i, j), wij in w.items():
        out[i] += wij * (verts[j] - verts[i])
        total[i] += wij
    return out / total[:, None]


def bumpy_mesh():
    m = trimesh.creation.icosphere(subdivisions=1)
    gen = torch.Generator().manual_seed(0)
    verts = torch.from_numpy(m.vertices).double()
    verts = verts * (1 + 0.1 * torch.rand(verts.shape[0], 1, generator=gen, dtype=torch.float64))
    return verts, torch.from_numpy(m.faces).long()


def mixed_polygons():
    verts = torch.tensor([[0.0, 0, 0], [1, 0, 0.1], [2, 0, 0], [0, 1, 0.2], [1, 1, 0.3],
                          [2, 1, -0.1], [1, 2, 0.4]], dtype=torch.float64)
    faces = torch.tensor([[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 6, -1], [4, 5, 6, -1]])
    return verts, faces


@pytest.mark.parametrize("mesh", [bumpy_mesh, mixed_polygons])
def test_laplacians_match_formulas(mesh):
    verts, faces = mesh()
    torch.testing.assert_close(mesh_laplacian(verts, faces), reference_uniform(verts, faces))
    torch.testing.assert_close(mesh_laplacian(verts, faces, "cotangent"),
                               reference_cotangent(verts, faces))
    expected = reference_uniform(verts, faces).norm(dim=-1).mean()
    torch.testing.assert_close(laplacian_smoothing_loss(verts, faces), expected)


def test_normal_consistency_and_edge_length_match_formulas():
    verts, faces = mixed_polygons()
    normals = []
    for f in faces.tolist():
        f = [v for v in f if v >= 0]
        n = sum(torch.linalg.cross(verts[f[k]], verts[f[(k + 1) % len(f)]]) for k in range(len(f)))
        normals.append(n / n.norm())
    adjacent = [(f, g) for f in range(len(faces)) for g in range(f + 1, len(faces))
                if len(set(faces[f].tolist()) & set(faces[g].tolist()) - {-1}) == 2]
    expected = sum(1 - float(normals[f] @ normals[g]) for f, g in adjacent) / len(adjacent)
    torch.testing.assert_close(float(normal_consistency_loss(verts, faces)), expected)
    lengths = [float((verts[a] - verts[b]).norm()) for a, b in polygon_edges(faces)]
    expected = sum((x - 0.7) ** 2 for x in lengths) / len(lengths)
    torch.testing.assert_close(float(edge_length_loss(verts, faces, 0.7)), expected)


@pytest.mark.parametrize("quads", [False, True])
def test_zero_on_a_flat_grid(quads):
    verts, faces = flat_grid(5, quads)
    interior = ((verts[:, 0] > 0) & (verts[:, 0] < 4) & (verts[:, 1] > 0) & (verts[:, 1] < 4))
    assert mesh_laplacian(verts, faces)[interior].abs().max() == 0
    # cotangent weights reproduce linear functions: zero inside even after in-plane jitter
    gen = torch.Generator().manual_seed(1)
    jitter = verts.clone()
    jitter[:, :2] += 0.2 * torch.rand(25, 2, generator=gen, dtype=torch.float64)
    lap = mesh_laplacian(jitter, faces, "cotangent")
    assert lap[interior].abs().max() < 1e-12
    assert lap[~interior].norm(dim=-1).min() > 0.01  # boundaries are pulled inwards
    assert normal_consistency_loss(jitter, faces) < 1e-15
    n_diag = 0 if quads else 16  # triangulated cells add one diagonal of length sqrt(2)
    n_edges = 40 + n_diag
    expected = n_diag * (math.sqrt(2) - 1) ** 2 / n_edges
    torch.testing.assert_close(float(edge_length_loss(verts, faces, target=1.0)), expected)
    tilted = verts.clone()
    tilted[:, 2] = 0.3 * verts[:, 0] - 0.2 * verts[:, 1]  # still a plane
    assert normal_consistency_loss(tilted, faces) < 1e-15


def test_batched_equals_loop_and_scaling():
    verts, faces = bumpy_mesh()
    batch = torch.stack([verts, 2 * verts, verts.flip(-1)])
    for fn in (laplacian_smoothing_loss, normal_consistency_loss, edge_length_loss):
        out = fn(batch, faces)
        assert out.shape == (3,)
        torch.testing.assert_close(out, torch.stack([fn(v, faces) for v in batch]))
    for s in (1e-6, 1e6):
        for method in ("uniform", "cotangent"):
            torch.testing.assert_close(laplacian_smoothing_loss(s * verts, faces, method),
                                       s * laplacian_smoothing_loss(verts, faces, method))
        torch.testing.assert_close(normal_consistency_loss(s * verts, faces),
                                   normal_consistency_loss(verts, faces))
        torch.testing.assert_close(edge_length_loss(s * verts, faces, s * 0.3),
                                   s**2 * edge_length_loss(verts, faces, 0.3))


@pytest.mark.grad
@pytest.mark.parametrize("name", ["uniform", "cotangent", "normal", "edge"])
def test_gradcheck(name):
    verts, faces = mixed_polygons()
    verts.requires_grad_(True)
    fn = {"uniform": lambda v: laplacian_smoothing_loss(v, faces),
          "cotangent": lambda v: laplacian_smoothing_loss(v, faces, "cotangent"),
          "normal": lambda v: normal_consistency_loss(v, faces),
          "edge": lambda v: edge_length_loss(v, faces, 0.5)}[name]
    assert torch.autograd.gradcheck(fn, (verts,))


def test_flat_grid_gradient_is_finite_and_nan_propagates():
    verts, faces = flat_grid(4, False)
    verts.requires_grad_(True)
    (laplacian_smoothing_loss(verts, faces) + normal_consistency_loss(verts, faces)
     + edge_length_loss(verts, faces, 1.0)).backward()
    assert torch.isfinite(verts.grad).all()
    bad = verts.detach().clone()
    bad[0, 0] = float("nan")
    assert torch.isnan(laplacian_smoothing_loss(bad, faces))
    assert torch.isnan(edge_length_loss(bad, faces))
    with pytest.raises(ValueError, match="method"):
        laplacian_smoothing_loss(bad, faces, "robust")
    with pytest.raises(ValueError, match="faces"):
        edge_length_loss(bad, torch.tensor([[0, 1, 99]]))


# ----------------------------------------------------------------------------- contract ------
def test_nan_vertex_propagates_to_normal_consistency_and_cotangents():
    # unguarded: a NaN normal failed the "> 0" guard and counted as a zero-area face (term 0)
    verts, faces = mixed_polygons()
    bad = verts.clone()
    bad[6, 2] = float("nan")
    assert torch.isnan(normal_consistency_loss(bad, faces))
    lap = mesh_laplacian(bad, faces, "cotangent")
    reference = reference_cotangent(verts, faces)
    touched = torch.tensor([3, 4, 5, 6])  # the neighbours of vertex 6, and itself
    assert torch.isnan(lap[touched]).any(-1).all()
    untouched = torch.tensor([0, 1, 2])
    torch.testing.assert_close(lap[untouched], reference[untouched])


@pytest.mark.parametrize("s", [1e-30, 1e-12, 1e12, 1e30])
def test_float32_at_extreme_scales_matches_float64(s):
    # unguarded: |n_f|^2 |n_g|^2 (s^8) and |a x b|^2 (s^4) under/overflowed float32: the normal
    # consistency became 0 or NaN, the cotangent weights 0, the smoothing loss 0 or inf
    verts, faces = bumpy_mesh()
    want_nc = normal_consistency_loss(verts, faces)
    want_lap = mesh_laplacian(verts, faces, "cotangent")
    small = (verts * s).float()
    torch.testing.assert_close(normal_consistency_loss(small, faces).double(), want_nc,
                               rtol=1e-4, atol=1e-6)
    torch.testing.assert_close(mesh_laplacian(small, faces, "cotangent").double() / s, want_lap,
                               rtol=1e-3, atol=1e-5)
    want = laplacian_smoothing_loss(verts, faces)
    torch.testing.assert_close(laplacian_smoothing_loss(small, faces).double() / s, want,
                               rtol=1e-4, atol=0.0)


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_half_inputs_are_computed_in_float32(dtype):
    verts, faces = bumpy_mesh()
    half = verts.to(dtype)
    ref = half.float()
    for fn in (lambda v: mesh_laplacian(v, faces, "cotangent"),
               lambda v: laplacian_smoothing_loss(v, faces),
               lambda v: normal_consistency_loss(v, faces),
               lambda v: edge_length_loss(v, faces, 0.3)):
        got = fn(half)
        assert got.dtype == dtype
        assert torch.equal(got, fn(ref).to(dtype))


def test_edge_length_target_tensor():
    verts, faces = mixed_polygons()
    target = torch.tensor([0.5, 0.9], dtype=torch.float64, requires_grad=True)
    batch = torch.stack([verts, 2 * verts])
    loss = edge_length_loss(batch, faces, target)
    want = torch.stack([edge_length_loss(verts, faces, 0.5),
                        edge_length_loss(2 * verts, faces, 0.9)])
    torch.testing.assert_close(loss, want)
    loss.sum().backward()
    lengths = torch.tensor([float((verts[a] - verts[b]).norm()) for a, b in polygon_edges(faces)],
                           dtype=torch.float64)
    grad = torch.stack([-2 * (lengths - 0.5).mean(), -2 * (2 * lengths - 0.9).mean()])
    torch.testing.assert_close(target.grad, grad)
    with pytest.raises(TypeError, match="target.*float32.*verts.*float64"):
        edge_length_loss(verts, faces, target.detach().float())
    with pytest.raises(ValueError, match="target"):
        edge_length_loss(verts, faces, torch.tensor([0.5, -1.0], dtype=torch.float64))
    with pytest.raises(ValueError, match="target"):
        edge_length_loss(verts, faces, float("nan"))
    with pytest.raises(ShapeError, match="target"):  # not a raw broadcasting RuntimeError
        edge_length_loss(batch, faces, torch.ones(3, dtype=torch.float64))


def test_mesh_edges_validates_and_accepts_lists():
    # unguarded: raw torch errors (unpack of a 1-D shape) and no check of face sizes
    want = mesh_edges(torch.tensor([[0, 1, 2, 3], [1, 4, 2, -1]]))
    got = mesh_edges([[0, 1, 2, 3], [1, 4, 2]])
    assert torch.equal(got.edges, want.edges) and torch.equal(got.face_pairs, want.face_pairs)
    assert torch.equal(got.edges, torch.tensor(polygon_edges([[0, 1, 2, 3], [1, 4, 2]])))
    empty = mesh_edges(torch.zeros(0, 3, dtype=torch.long))
    assert empty.edges.shape == (0, 2) and empty.face_pairs.shape == (0, 2)
    with pytest.raises(ShapeError, match="faces"):
        mesh_edges(torch.tensor([0, 1, 2]))
    with pytest.raises(TypeError, match="faces"):
        mesh_edges(torch.zeros(2, 3))
    with pytest.raises(ValueError, match="faces"):
        mesh_edges(torch.tensor([[0, 1, -1]]))


@pytest.mark.parametrize("n_verts", [0, 4])
def test_no_faces_gives_zero_losses(n_verts):
    verts = torch.randn(2, n_verts, 3, dtype=torch.float64)
    faces = torch.zeros(0, 3, dtype=torch.long)
    for method in ("uniform", "cotangent"):
        assert torch.equal(mesh_laplacian(verts, faces, method), torch.zeros_like(verts))
        assert torch.equal(laplacian_smoothing_loss(verts, faces, method), verts.new_zeros(2))
    assert torch.equal(normal_consistency_loss(verts, faces), verts.new_zeros(2))
    assert torch.equal(edge_length_loss(verts, faces, 0.5), verts.new_zeros(2))
