"""Tests for torchgeo_cg.mesh.marching_cubes against scikit-image, brute force and by hand."""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

import torchgeo_cg.mesh as mesh_pkg
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.grid import Volume
from torchgeo_cg.mesh import MarchingCubes, MarchingCubesResult, marching_cubes
from torchgeo_cg.mesh.marching_cubes._tables import (
    AMBIGUOUS,
    CORNER_OFFSETS,
    CUBE_FACES,
    EDGE_CORNERS,
    TRIANGLES,
    face_segments,
)

skimage_measure = pytest.importorskip("skimage.measure")
trimesh = pytest.importorskip("trimesh")


# ----------------------------------------------------------------------------- fields
def grid(n: int, lo: float = -1.2, hi: float = 1.2, dtype=torch.float64, device="cpu"):
    """``(X, Y, Z)`` coordinates (indexing="ij"), their spacing and origin."""
    x = torch.linspace(lo, hi, n, dtype=dtype, device=device)
    X, Y, Z = torch.meshgrid(x, x, x, indexing="ij")
    return X, Y, Z, float(x[1] - x[0]), lo


def sphere(X, Y, Z, r=0.8):
    return (X**2 + Y**2 + Z**2).sqrt() - r


def torus(X, Y, Z, R=0.7, r=0.3):
    return ((X**2 + Y**2).sqrt() - R).hypot(Z) - r


def double_torus(X, Y, Z):
    return torch.minimum(torus(X + 0.55, Y, Z, 0.6, 0.2), torus(X - 0.55, Y, Z, 0.6, 0.2))


def gyroid_ball(X, Y, Z):
    g = (torch.sin(4 * X) * torch.cos(4 * Y) + torch.sin(4 * Y) * torch.cos(4 * Z)
         + torch.sin(4 * Z) * torch.cos(4 * X)) / 4
    return torch.maximum(g, sphere(X, Y, Z, 1.0))


def noise_ball(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    noise = gaussian_filter(rng.standard_normal((n, n, n)), sigma=n / 16)
    noise = torch.from_numpy(noise / noise.std() * 0.3)
    X, Y, Z, h, lo = grid(n)
    return torch.maximum(noise, sphere(X, Y, Z, 1.0)), h, lo


def pad_outside(vol: torch.Tensor, value: float = 1.0) -> torch.Tensor:
    """Surround the last three axes with one layer of outside samples (closes the surface)."""
    return torch.nn.functional.pad(vol, (1, 1, 1, 1, 1, 1), value=value)


# ---------------------------------------------------------------------------- helpers
def to_trimesh(result):
    return trimesh.Trimesh(
        result.verts.detach().cpu().double().numpy(), result.faces.cpu().numpy(), process=False
    )


def closed_and_oriented(verts: np.ndarray, faces: np.ndarray) -> tuple[bool, str]:
    """Merge vertices by exact position; every directed edge once, its reverse once."""
    if faces.shape[0] == 0:
        return True, "empty"
    _, inverse = np.unique(verts, axis=0, return_inverse=True)
    f = inverse.reshape(-1)[faces]
    if (f[:, 0] == f[:, 1]).any() or (f[:, 1] == f[:, 2]).any() or (f[:, 0] == f[:, 2]).any():
        return False, "a face collapsed after merging vertices by position"
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]).astype(np.int64)
    n = int(f.max()) + 1
    codes = directed[:, 0] * n + directed[:, 1]
    uniq, counts = np.unique(codes, return_counts=True)
    if (counts != 1).any():
        return False, "a directed edge is used twice (non-manifold or flipped face)"
    missing = int((~np.isin(directed[:, 1] * n + directed[:, 0], uniq)).sum())
    if missing:
        return False, f"{missing} edges have one face only (hole)"
    return True, "ok"


def triangle_areas(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    tri = verts[faces]
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def signed_volume(verts: np.ndarray, faces: np.ndarray) -> float:
    tri = verts[faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6)


def cell_cases(vol: np.ndarray, iso: float = 0.0) -> np.ndarray:
    """Brute-force case index of every cell, bit c = corner (dx, dy, dz) inside."""
    inside = vol < iso
    X, Y, Z = vol.shape
    case = np.zeros((X - 1, Y - 1, Z - 1), dtype=np.int64)
    for c, (dx, dy, dz) in enumerate(CORNER_OFFSETS):
        case |= inside[dx:X - 1 + dx, dy:Y - 1 + dy, dz:Z - 1 + dz].astype(np.int64) << c
    return case


def face_cells(verts_index: np.ndarray, faces: np.ndarray, shape) -> np.ndarray:
    """Flat index of the cell holding each face (its centroid, in index coordinates)."""
    cell = np.floor(verts_index[faces].mean(1)).astype(np.int64)
    return np.ravel_multi_index(cell.T, tuple(s - 1 for s in shape))


# ----------------------------------------------------------------------------- tables
def test_tables_boundary_of_every_case_is_its_face_segments():
    for case in range(256):
        directed = set()
        for a, b, c in TRIANGLES[case]:
            directed |= {(a, b), (b, c), (c, a)}
        boundary = {e for e in directed if (e[1], e[0]) not in directed}
        segments = {s for face in range(6) for s in face_segments(case, face)}
        assert boundary == segments, case
        assert len(directed) == 3 * len(TRIANGLES[case]), case  # no edge used twice


def test_tables_shared_faces_close_for_every_pair_of_neighbouring_cases():
    # Cell A's face (axis, side 1) is cell B's face (axis, side 0): whatever A and B
    # are, the segments A draws there must be B's segments reversed.
    def edge_position(e, shift):
        a, b = EDGE_CORNERS[e]
        return tuple(
            (pa + pb) / 2 + s for pa, pb, s in zip(CORNER_OFFSETS[a], CORNER_OFFSETS[b], shift)
        )

    checked = 0
    for axis in range(3):
        high = next(f for f, (ax, side, _) in enumerate(CUBE_FACES) if ax == axis and side == 1)
        low = next(f for f, (ax, side, _) in enumerate(CUBE_FACES) if ax == axis and side == 0)
        shift = tuple(1 if k == axis else 0 for k in range(3))
        for case_a in range(256):
            shared = [c for c in range(8) if CORNER_OFFSETS[c][axis] == 1]
            for case_b in range(256):
                if any(((case_a >> c) & 1) != ((case_b >> (c ^ (4 >> axis))) & 1)
                       for c in shared):
                    continue
                seg_a = {(edge_position(p, (0, 0, 0)), edge_position(q, (0, 0, 0)))
                         for p, q in face_segments(case_a, high)}
                seg_b = {(edge_position(q, shift), edge_position(p, shift))
                         for p, q in face_segments(case_b, low)}
                assert seg_a == seg_b, (axis, case_a, case_b)
                checked += 1
    assert checked == 3 * 256 * 16


def test_tables_ambiguity_flags_by_hand():
    assert not AMBIGUOUS[0] and not AMBIGUOUS[255]
    assert not AMBIGUOUS[0b00000001]  # one corner
    assert not AMBIGUOUS[0b00000011]  # an edge (corners 0, 1)
    assert AMBIGUOUS[0b00001001]  # corners 0 and 3: face diagonal
    assert AMBIGUOUS[0b10000001]  # corners 0 and 7: body diagonal
    assert not AMBIGUOUS[0b00001111]  # the face x = 0
    assert sum(AMBIGUOUS) == 128


def test_every_case_alone_in_a_padded_volume_is_closed_and_outward():
    # all 256 cases in one batched call: corners random in [-1, -0.1] or [0.1, 1]
    gen = torch.Generator().manual_seed(0)
    cases = torch.arange(256)
    bits = (cases[:, None] >> torch.arange(8)) & 1  # (256, 8)
    mag = 0.1 + 0.9 * torch.rand(256, 8, generator=gen, dtype=torch.float64)
    values = torch.where(bits == 1, -mag, mag)
    vol = torch.zeros(256, 2, 2, 2, dtype=torch.float64)
    for c, (dx, dy, dz) in enumerate(CORNER_OFFSETS):
        vol[:, dx, dy, dz] = values[:, c]
    result = marching_cubes(pad_outside(vol))
    for case, m in enumerate(result.split()):
        ok, why = closed_and_oriented(m.verts.numpy(), m.faces.numpy())
        assert ok, (case, why)
        if m.faces.shape[0]:
            assert signed_volume(m.verts.numpy(), m.faces.numpy()) > 0, case


def test_all_4096_two_cell_configurations_are_closed():
    configs = torch.arange(4096)
    bits = ((configs[:, None] >> torch.arange(12)) & 1).reshape(4096, 3, 2, 2)
    gen = torch.Generator().manual_seed(1)
    mag = 0.1 + 0.9 * torch.rand(4096, 3, 2, 2, generator=gen, dtype=torch.float64)
    result = marching_cubes(pad_outside(torch.where(bits == 1, -mag, mag)))
    # packed check: all meshes at once (vertex ids are unique across the batch)
    offsets = torch.repeat_interleave(
        torch.arange(4096) * 1000, result.verts_per_mesh
    )[:, None].double()  # move meshes apart so merging by position stays per mesh
    ok, why = closed_and_oriented((result.verts + offsets).numpy(), result.faces.numpy())
    assert ok, why


# ------------------------------------------------------------------ against skimage
@pytest.mark.parametrize("method", ["lorensen", "lewiner"])
@pytest.mark.parametrize("shape,n", [("sphere", 64), ("torus", 128)])
def test_matches_skimage_on_unambiguous_fields(shape, n, method):
    X, Y, Z, h, lo = grid(n)
    field = {"sphere": sphere, "torus": torus}[shape](X, Y, Z)
    assert not np.asarray(AMBIGUOUS)[cell_cases(field.numpy())].any()  # no ambiguous cell
    ours = marching_cubes(field, origin=(lo, lo, lo), spacing=(h, h, h))
    sk_v, sk_f, _, _ = skimage_measure.marching_cubes(
        field.numpy(), 0.0, spacing=(h, h, h), method=method
    )
    sk_v = sk_v.astype(np.float64) + lo
    v = ours.verts.numpy()
    assert v.shape == sk_v.shape and ours.faces.shape == sk_f.shape
    d_ours, _ = cKDTree(sk_v).query(v)
    d_sk, _ = cKDTree(v).query(sk_v)
    assert d_ours.max() < 1e-5 and d_sk.max() < 1e-5  # same vertex sets (skimage is f32)
    area, sk_area = triangle_areas(v, ours.faces.numpy()).sum(), triangle_areas(sk_v, sk_f).sum()
    vol, sk_vol = signed_volume(v, ours.faces.numpy()), abs(signed_volume(sk_v, sk_f))
    # The same vertices and the same loops per cell; only the diagonal that splits a
    # non-planar quad or hexagon differs (ours: best triangle quality), an O(h^2)
    # effect, hence n = 128 for the thinner torus.
    assert abs(area / sk_area - 1) < 1e-4
    assert abs(vol / sk_vol - 1) < 1e-4


@pytest.mark.parametrize("field_name", ["gyroid", "noise"])
def test_close_to_skimage_on_ambiguous_fields_and_differences_are_in_ambiguous_cells(
    field_name,
):
    n = 64
    if field_name == "gyroid":
        X, Y, Z, h, lo = grid(n)
        field = gyroid_ball(X, Y, Z)
    else:
        field, h, lo = noise_ball(n)
    cases = cell_cases(field.numpy())
    ambiguous_cells = np.asarray(AMBIGUOUS)[cases].reshape(-1)
    assert ambiguous_cells.sum() > 0  # the field does exercise ambiguous cells
    ours = marching_cubes(field, ambiguity="separate")  # index coordinates: cells of faces
    sk_v, sk_f, _, _ = skimage_measure.marching_cubes(field.numpy(), 0.0)
    sk_v = sk_v.astype(np.float64)
    v, f = ours.verts.numpy(), ours.faces.numpy()
    area, sk_area = triangle_areas(v, f), triangle_areas(sk_v, sk_f)
    cell, sk_cell = face_cells(v, f, field.shape), face_cells(sk_v, sk_f, field.shape)
    amb, sk_amb = ambiguous_cells[cell], ambiguous_cells[sk_cell]
    # Totals within 1e-3 (area, and volume of these closed surfaces).
    assert abs(area.sum() / sk_area.sum() - 1) < 1e-3
    vol, sk_vol = signed_volume(v, f), abs(signed_volume(sk_v, sk_f))
    assert abs(vol / sk_vol - 1) < 1e-3
    # Outside the ambiguous cells both tools make the same triangles per cell up to
    # the diagonal splitting a non-planar quad/hexagon: the same number of faces and
    # the same vertices in every cell.
    n_cells = ambiguous_cells.shape[0]
    per_cell = np.bincount(cell[~amb], minlength=n_cells)
    sk_per_cell = np.bincount(sk_cell[~sk_amb], minlength=n_cells)
    np.testing.assert_array_equal(per_cell, sk_per_cell)

    def vertex_sum_per_cell(verts, faces, cells, keep):
        pairs = np.unique(np.stack([np.repeat(cells[keep], 3), faces[keep].reshape(-1)]), axis=1)
        out = np.zeros((n_cells, 3))
        np.add.at(out, pairs[0], verts[pairs[1]])
        return out

    np.testing.assert_allclose(
        vertex_sum_per_cell(v, f, cell, ~amb), vertex_sum_per_cell(sk_v, sk_f, sk_cell, ~sk_amb),
        atol=1e-4,
    )
    # The diagonals change the area by O(h^2) only; the remaining difference sits in
    # the ambiguous cells, where the topology is a choice: ours separates the inside
    # corners, Lewiner's asymptotic decider may join them.
    assert abs(area[~amb].sum() / sk_area[~sk_amb].sum() - 1) < 1e-3
    print(f"{field_name}: {int(ambiguous_cells.sum())} ambiguous cells, area in them "
          f"{area[amb].sum():.3f} (ours) vs {sk_area[sk_amb].sum():.3f} (skimage)")


# ------------------------------------------------------------ watertight, topology
@pytest.mark.parametrize("name,expected", [("sphere", 2), ("torus", 0), ("double", -2)])
def test_euler_characteristic_and_watertight(name, expected):
    X, Y, Z, h, lo = grid(48, -1.5, 1.5)  # the double torus spans x in [-1.35, 1.35]
    field = {"sphere": sphere, "torus": torus, "double": double_torus}[name](X, Y, Z)
    result = marching_cubes(field, origin=(lo, lo, lo), spacing=(h, h, h))
    m = to_trimesh(result)
    assert m.is_watertight and m.is_winding_consistent
    assert m.euler_number == expected
    ok, why = closed_and_oriented(result.verts.numpy(), result.faces.numpy())
    assert ok, why


@pytest.mark.parametrize("field_name", ["gyroid", "noise"])
def test_smooth_ambiguous_fields_are_closed(field_name):
    if field_name == "gyroid":
        X, Y, Z, h, lo = grid(40)
        field = gyroid_ball(X, Y, Z)
    else:
        field, h, lo = noise_ball(40, seed=3)
    result = marching_cubes(field, spacing=(h, h, h))
    ok, why = closed_and_oriented(result.verts.numpy(), result.faces.numpy())
    assert ok, why


@pytest.mark.parametrize("seed", range(4))
def test_random_fields_with_frequent_ambiguity_are_closed(seed):
    gen = torch.Generator().manual_seed(seed)
    vol = pad_outside(torch.randn(12, 10, 11, generator=gen, dtype=torch.float64))
    cases = cell_cases(vol.numpy())
    assert np.asarray(AMBIGUOUS)[cases].mean() > 0.1
    result = marching_cubes(vol)
    ok, why = closed_and_oriented(result.verts.numpy(), result.faces.numpy())
    assert ok, why
    assert signed_volume(result.verts.numpy(), result.faces.numpy()) > 0


@pytest.mark.parametrize("dtype_", [torch.float32, torch.float64])
@pytest.mark.parametrize("seed", range(20))
def test_integer_fields_at_integer_iso_are_closed_without_degenerate_faces(seed, dtype_):
    gen = torch.Generator().manual_seed(100 + seed)
    vol = torch.randint(-2, 3, (10, 10, 10), generator=gen).to(dtype_)
    vol = pad_outside(vol, 3.0)
    iso = float(seed % 3 - 1)  # -1, 0, 1: exact-iso samples everywhere
    result = marching_cubes(vol, iso=iso)
    v, f = result.verts.double().numpy(), result.faces.numpy()
    assert (vol == iso).any()
    assert np.unique(v, axis=0).shape[0] == v.shape[0]  # no duplicate positions
    assert triangle_areas(v, f).min() > 0  # no zero-area face
    ok, why = closed_and_oriented(v, f)
    assert ok, why


@settings(max_examples=25)
@given(st.integers(0, 2**31 - 1), st.floats(-0.5, 0.5))
def test_property_closed_oriented_and_inside_the_bounding_box(seed, iso):
    gen = torch.Generator().manual_seed(seed)
    vol = pad_outside(torch.randn(5, 6, 4, generator=gen, dtype=torch.float64), 2.0)
    result = marching_cubes(vol, iso=iso, origin=(1.0, -2.0, 0.5), spacing=(0.5, 1.0, 2.0))
    ok, why = closed_and_oriented(result.verts.numpy(), result.faces.numpy())
    assert ok, why
    if result.faces.shape[0]:
        assert signed_volume(result.verts.numpy(), result.faces.numpy()) > 0
        lo = torch.tensor([1.0, -2.0, 0.5], dtype=torch.float64)
        last_index = torch.tensor(vol.shape, dtype=torch.float64) - 1
        hi = lo + torch.tensor([0.5, 1.0, 2.0], dtype=torch.float64) * last_index
        assert (result.verts >= lo).all() and (result.verts <= hi).all()


# ---------------------------------------------------------------- orientation, normals
def test_orientation_and_normals_agree_with_faces(device, dtype):
    X, Y, Z, h, lo = grid(32, dtype=dtype, device=device)
    result = marching_cubes(torus(X, Y, Z), origin=(lo, lo, lo), spacing=(h, h, 2 * h))
    assert result.verts.dtype == dtype and result.verts.device.type == device.type
    assert result.faces.dtype == torch.long and result.normals.dtype == dtype
    v, f = result.verts.cpu().double().numpy(), result.faces.cpu().numpy()
    assert signed_volume(v, f) > 0
    tri = v[f]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vert_n = result.normals.cpu().double().numpy()[f].mean(1)
    assert (np.einsum("ij,ij->i", face_n, vert_n) > 0).all()
    np.testing.assert_allclose(np.linalg.norm(result.normals.cpu().numpy(), axis=1), 1, atol=1e-5)


def test_normals_of_a_sphere_are_radial():
    X, Y, Z, h, lo = grid(40)
    result = marching_cubes(sphere(X, Y, Z), origin=(lo, lo, lo), spacing=(h, h, h))
    radial = result.verts / result.verts.norm(dim=1, keepdim=True)
    assert (result.normals * radial).sum(1).min() > 0.999


def test_vertices_interpolate_by_hand():
    # one edge from f = -1 at x = 0 to f = 3 at x = 1: t = (0 - -1) / (3 - -1) = 0.25
    vol = torch.full((2, 2, 2), 3.0, dtype=torch.float64)
    vol[0, 0, 0] = -1.0
    result = marching_cubes(vol, origin=(10.0, 20.0, 30.0), spacing=(2.0, 4.0, 8.0))
    expected = torch.tensor(
        [[10.5, 20.0, 30.0], [10.0, 21.0, 30.0], [10.0, 20.0, 32.0]], dtype=torch.float64
    )
    torch.testing.assert_close(result.verts, expected)
    torch.testing.assert_close(result.faces, torch.tensor([[0, 1, 2]]))
    # face normal (1/2)(v1 - v0) x (v2 - v0) points away from the inside corner
    v = result.verts
    assert (torch.linalg.cross(v[1] - v[0], v[2] - v[0]) > 0).all()


def test_exact_iso_sample_is_outside_and_clamped():
    vol = torch.ones(2, 2, 2, dtype=torch.float64)
    vol[0, 0, 0] = -1.0
    vol[1, 0, 0] = 0.0  # equal to iso: outside, vertex clamped next to it
    result = marching_cubes(vol)
    delta = torch.finfo(torch.float64).eps ** 0.5
    assert result.faces.shape == (1, 3)
    torch.testing.assert_close(result.verts[0], torch.tensor([1 - delta, 0.0, 0.0],
                                                             dtype=torch.float64))


# ----------------------------------------------------------------- batching, empties
def test_batch_equals_separate_calls_and_split():
    X, Y, Z, h, lo = grid(20)
    vols = torch.stack([sphere(X, Y, Z), torus(X, Y, Z), torch.ones_like(X), sphere(X, Y, Z, 0.5)])
    iso = torch.tensor([0.0, 0.05, 0.0, -0.1], dtype=torch.float64)
    batched = marching_cubes(vols, iso=iso, temperature=0.2)
    parts = batched.split()
    assert len(parts) == 4
    assert batched.verts_per_mesh.tolist() == [p.verts.shape[0] for p in parts]
    for b, part in enumerate(parts):
        single = marching_cubes(vols[b], iso=float(iso[b]), temperature=0.2)
        for got, want in zip(part, single):
            torch.testing.assert_close(got, want)
    assert parts[2].faces.shape == (0, 3)


def test_no_surface_gives_empty_tensors(device, dtype):
    vol = torch.ones(4, 5, 6, dtype=dtype, device=device)
    result = marching_cubes(vol, temperature=0.5)
    assert isinstance(result, MarchingCubesResult)
    assert result.verts.shape == (0, 3) and result.verts.dtype == dtype
    assert result.faces.shape == (0, 3) and result.faces.dtype == torch.long
    assert result.normals.shape == (0, 3) and result.face_weights.shape == (0,)
    assert result.verts_per_mesh.tolist() == [0] and result.faces_per_mesh.tolist() == [0]
    assert result.verts.device.type == device.type
    assert len(result.split()) == 1


def test_open_surface_reaching_the_volume_border():
    X, Y, Z, h, lo = grid(9)
    plane = X + 0.3 * Y - 0.2 * Z + 0.05
    result = marching_cubes(plane, origin=(lo, lo, lo), spacing=(h, h, h))
    v = result.verts
    torch.testing.assert_close(v[:, 0] + 0.3 * v[:, 1] - 0.2 * v[:, 2] + 0.05,
                               torch.zeros_like(v[:, 0]))
    ok, why = closed_and_oriented(
        np.concatenate([v.numpy()]), result.faces.numpy()
    )
    assert not ok and "hole" in why  # open at the border, but no other defect
    assert abs(triangle_areas(v.numpy(), result.faces.numpy()).sum()
               - 2.4**2 * np.sqrt(1 + 0.3**2 + 0.2**2)) < 0.1


# ------------------------------------------------------------------------- gradients
def _small_field(seed=0, n=4):
    gen = torch.Generator().manual_seed(seed)
    vol = torch.randn(n, n, n, generator=gen, dtype=torch.float64)
    vol = torch.where(vol.abs() < 0.05, vol.sign() * 0.05 + vol, vol)  # away from iso
    return vol


@pytest.mark.slow
@pytest.mark.grad
def test_gradcheck_verts_normals_weights():
    vol = _small_field().requires_grad_()
    iso = torch.tensor(0.01, dtype=torch.float64, requires_grad=True)
    tau = torch.tensor(0.3, dtype=torch.float64, requires_grad=True)

    def fn(v, i, t):
        r = marching_cubes(v, iso=i, temperature=t)
        return r.verts, r.normals, r.face_weights

    assert marching_cubes(vol.detach()).faces.shape[0] > 10
    assert torch.autograd.gradcheck(fn, (vol, iso, tau), eps=1e-6, atol=1e-6)


@pytest.mark.slow
@pytest.mark.grad
def test_gradcheck_origin_spacing_batched():
    vol = torch.stack([_small_field(1, 3), _small_field(2, 3)]).requires_grad_()
    origin = torch.tensor([0.5, -1.0, 2.0], dtype=torch.float64, requires_grad=True)
    spacing = torch.tensor([[1.0, 0.5, 2.0], [0.3, 0.4, 0.5]], dtype=torch.float64,
                           requires_grad=True)

    def fn(v, o, s):
        r = marching_cubes(v, origin=o, spacing=s)
        return r.verts, r.normals

    assert (marching_cubes(vol.detach()).faces_per_mesh > 0).all()

    assert torch.autograd.gradcheck(fn, (vol, origin, spacing), eps=1e-6, atol=1e-6)


def test_gradients_stay_finite_on_degenerate_data(dtype):
    gen = torch.Generator().manual_seed(7)
    vol = pad_outside(torch.randint(-1, 2, (6, 6, 6), generator=gen).to(dtype), 1.0)
    vol.requires_grad_()
    iso = torch.zeros((), dtype=dtype, requires_grad=True)
    r = marching_cubes(vol, iso=iso, temperature=0.01)
    loss = r.verts.sum() + r.normals.sum() + (r.face_weights * r.verts[r.faces].sum((1, 2))).sum()
    loss.backward()
    assert torch.isfinite(vol.grad).all() and torch.isfinite(iso.grad)
    assert vol.grad.abs().sum() > 0


def test_soft_weights_equal_brute_force_product():
    vol = _small_field(3)
    iso, tau = 0.1, 0.25
    r = marching_cubes(vol, iso=iso, temperature=tau)
    cell = np.floor(r.verts[r.faces].mean(1).numpy()).astype(int)  # spacing 1, origin 0
    for (i, j, k), w in zip(cell.tolist(), r.face_weights.tolist()):
        expected = 1.0
        for dx, dy, dz in CORNER_OFFSETS:
            f = float(vol[i + dx, j + dy, k + dz])
            p = 1 / (1 + np.exp(-(iso - f) / tau))  # P(inside)
            expected *= p if f < iso else 1 - p
        assert w == pytest.approx(expected, rel=1e-12)
    hard = marching_cubes(vol, iso=iso)
    torch.testing.assert_close(hard.face_weights, torch.ones_like(hard.face_weights))
    torch.testing.assert_close(hard.verts, r.verts)


def test_soft_weights_give_gradients_where_topology_is_fixed():
    X, Y, Z, h, lo = grid(12)
    vol = sphere(X, Y, Z).requires_grad_()
    r = marching_cubes(vol, temperature=0.05)
    r.face_weights.sum().backward()
    # samples far from the surface get no gradient through verts, but some through weights
    assert vol.grad.abs().sum() > 0
    assert (r.face_weights > 0).all() and (r.face_weights <= 1).all()


# ---------------------------------------------------------------- module, API, errors
def test_module_equals_function_and_defaults_match():
    fn_defaults = {
        k: p.default for k, p in inspect.signature(marching_cubes).parameters.items()
        if p.default is not inspect.Parameter.empty
    }
    mod_defaults = {
        k: p.default for k, p in inspect.signature(MarchingCubes.__init__).parameters.items()
        if p.default is not inspect.Parameter.empty
    }
    assert fn_defaults == mod_defaults
    X, Y, Z, h, lo = grid(10)
    vol = torus(X, Y, Z)
    for got, want in zip(MarchingCubes()(vol), marching_cubes(vol)):
        torch.testing.assert_close(got, want)
    module = MarchingCubes(iso=torch.tensor(0.1), spacing=torch.tensor([0.5, 0.5, 1.0]),
                           temperature=0.3).to(torch.float64)
    assert module.iso.dtype == torch.float64 and "iso" in dict(module.named_buffers())
    for got, want in zip(module(vol), marching_cubes(vol, 0.1, spacing=(0.5, 0.5, 1.0),
                                                      temperature=0.3)):
        torch.testing.assert_close(got, want)


def test_public_api():
    assert {"marching_cubes", "MarchingCubes", "MarchingCubesResult"} <= set(mesh_pkg.__all__)
    assert MarchingCubesResult._fields == (
        "verts", "faces", "normals", "face_weights", "verts_per_mesh", "faces_per_mesh"
    )


@pytest.mark.parametrize(
    "kwargs,error,match",
    [
        ({"volume": [[[0.0]]]}, TypeError, "volume"),
        ({"volume": torch.zeros(3, 3, 3, dtype=torch.long)}, TypeError, "volume"),
        ({"volume": torch.zeros(3, 3)}, ShapeError, "volume"),
        ({"volume": torch.zeros(2, 2, 3, 3, 3)}, ShapeError, "volume"),
        ({"volume": torch.zeros(3, 1, 3)}, ShapeError, ">= 2"),
        ({"iso": "0"}, TypeError, "iso"),
        ({"iso": torch.zeros(2, 2)}, ShapeError, "iso"),
        ({"iso": torch.zeros(3)}, ShapeError, "iso"),
        ({"iso": torch.zeros((), dtype=torch.long)}, TypeError, "iso"),
        ({"origin": (0.0, 0.0)}, ShapeError, "origin"),
        ({"origin": "abc"}, TypeError, "origin"),
        ({"spacing": (1, 2)}, ShapeError, "spacing"),
        ({"spacing": torch.ones(2)}, ShapeError, "spacing"),
        ({"spacing": (1.0, float("nan"), 1.0)}, ValueError, "spacing"),
        ({"spacing": (1.0, float("inf"), 1.0)}, ValueError, "spacing"),
        ({"spacing": (1.0, -1.0, 1.0)}, ValueError, "spacing"),
        ({"mask": torch.ones(3, 3, 3)}, TypeError, "mask"),
        ({"mask": torch.ones(3, 3, 2, dtype=torch.bool)}, ShapeError, "mask"),
        ({"ambiguity": "lewiner"}, ValueError, "ambiguity"),
        ({"volume": Volume(torch.zeros(3, 3, 3), torch.zeros(3), torch.ones(3)),
          "origin": (0.0, 0.0, 0.0)}, TypeError, "origin"),
        ({"origin": torch.zeros(4)}, ShapeError, "origin"),
        ({"spacing": (1.0, 0.0, 1.0)}, ValueError, "spacing"),
        ({"spacing": torch.ones(3, 3)}, ShapeError, "spacing"),
        ({"temperature": 0.0}, ValueError, "temperature"),
        ({"temperature": torch.tensor(-1.0)}, ValueError, "temperature"),
    ],
)
def test_bad_input_raises(kwargs, error, match):
    args = {"volume": torch.zeros(3, 3, 3)} | kwargs
    with pytest.raises(error, match=match):
        marching_cubes(**args)


def test_slab_seams_do_not_change_the_result(monkeypatch):
    # the volume is processed in slabs along x; one-layer slabs must give the same mesh
    impl = importlib.import_module("torchgeo_cg.mesh.marching_cubes._steps")
    X, Y, Z, h, lo = grid(14)
    vols = torch.stack([torus(X, Y, Z), sphere(X, Y, Z), X + 0.1 * Y])
    want = marching_cubes(vols, temperature=0.3)
    monkeypatch.setattr(impl, "SLAB_CELLS", 1)
    monkeypatch.setattr(impl, "MAP_CELLS", 1)
    got = marching_cubes(vols, temperature=0.3)
    for a, b in zip(got, want):
        torch.testing.assert_close(a, b)


def test_to_trimesh_gives_a_watertight_sphere_and_round_trips():
    from torchgeo_cg.mesh import from_trimesh
    from torchgeo_cg.mesh import to_trimesh as export

    X, Y, Z, h, lo = grid(24)
    result = marching_cubes(sphere(X, Y, Z), origin=(lo, lo, lo), spacing=(h, h, h))
    tm = export(result)
    assert tm.is_watertight and tm.is_winding_consistent and tm.volume > 0
    assert tm.euler_number == 2
    back = from_trimesh(tm, dtype=torch.float64)
    torch.testing.assert_close(back.verts, result.verts)
    torch.testing.assert_close(back.faces, result.faces)


# ---------------------------------------------------- arguments, Volume, mask, scale, half
def test_volume_input_uses_its_origin_and_spacing():
    from torchgeo_cg.sdf.grid import sample_grid

    vol = sample_grid(lambda p: p.norm(dim=-1) - 0.7, (12, 10, 9),
                      ((-1.0, -0.9, -1.1), (1.0, 1.1, 0.9)), dtype=torch.float64)
    got = marching_cubes(vol)
    want = marching_cubes(vol.values, origin=vol.origin, spacing=vol.spacing)
    for a, b in zip(got, want):
        torch.testing.assert_close(a, b)
    want_tuple = marching_cubes(vol.values, origin=tuple(vol.origin.tolist()),
                                spacing=tuple(vol.spacing.tolist()))
    torch.testing.assert_close(got.verts, want_tuple.verts)
    radius = got.verts.norm(dim=1)
    assert (radius - 0.7).abs().max() < 0.02  # world units: the frame was applied


def test_numbers_numpy_and_tensors_are_accepted_alike():
    X, Y, Z, h, lo = grid(9)
    vol = sphere(X, Y, Z)
    want = marching_cubes(vol, iso=0.1, origin=(lo, lo, lo), spacing=(h, h, h))
    variants = [
        dict(iso=np.float64(0.1), origin=np.array([lo] * 3), spacing=np.array([h] * 3)),
        dict(iso=np.array(0.1), origin=[lo, lo, lo], spacing=(h, h, np.float32(h).item())),
        dict(iso=torch.tensor(0.1, dtype=torch.float64), origin=torch.full((3,), lo),
             spacing=torch.full((1, 3), h)),
    ]
    for kwargs in variants:
        got = marching_cubes(vol, **kwargs)
        torch.testing.assert_close(got.verts, want.verts)
        assert torch.equal(got.faces, want.faces)


def test_mask_matches_skimage_far_corner_rule():
    rng = np.random.default_rng(3)
    vol = gaussian_filter(rng.standard_normal((12, 11, 10)), 1.5)
    mask = rng.random(vol.shape) < 0.6
    ours = marching_cubes(torch.from_numpy(vol), mask=torch.from_numpy(mask), ambiguity="separate")
    sk_v, sk_f, _, _ = skimage_measure.marching_cubes(vol, 0.0, mask=mask, method="lewiner")
    v = ours.verts.numpy()
    # every vertex is used, and the set of vertices equals scikit-image's
    assert np.unique(ours.faces.numpy()).shape[0] == v.shape[0]
    dist, _ = cKDTree(sk_v).query(v)
    back, _ = cKDTree(v).query(sk_v)
    assert dist.max() < 1e-5 and back.max() < 1e-5
    # cells whose far corner is masked out make no face
    cell = np.floor(v[ours.faces.numpy()].mean(1)).astype(int)
    assert mask[cell[:, 0] + 1, cell[:, 1] + 1, cell[:, 2] + 1].all()
    # batch with a shared mask equals single calls
    both = marching_cubes(torch.from_numpy(np.stack([vol, -vol])), mask=torch.from_numpy(mask),
                          ambiguity="separate")
    assert both.faces_per_mesh[0] == ours.faces.shape[0]
    assert np.array_equal(both.split()[0].faces.numpy(), ours.faces.numpy())


@pytest.mark.parametrize(
    "dtype,scales",
    [(torch.float64, [1e-12, 1e-6, 1e6, 1e12]), (torch.float32, [1e-6, 1e-3, 1e3, 1e6])],
)
def test_scale_invariance_of_vertices_and_faces(dtype, scales):
    # random (tie-free) and smooth fields: any scale; integer fields with exact ties in the
    # face decider (products equal): scales that are powers of two (exact in floating point)
    gen = torch.Generator().manual_seed(5)
    noise = pad_outside(torch.randn(8, 8, 8, generator=gen, dtype=dtype), 1.0)
    integer = pad_outside(torch.randint(-2, 3, (7, 7, 7), generator=gen).to(dtype) + 0.25, 1.0)
    X, Y, Z, h, lo = grid(12, dtype=dtype)
    smooth = torus(X, Y, Z)
    tol = dict(rtol=0, atol=4 * torch.finfo(dtype).eps * 12)
    cases = [(noise, 0.0, scales), (smooth, 0.0, scales), (integer, 0.5, [2.0**-30, 2.0**20])]
    for vol, iso, factors in cases:
        ref = marching_cubes(vol, iso=iso)
        assert ref.faces.shape[0] > 50
        for s in factors:
            got = marching_cubes(vol * s, iso=iso * s)
            assert torch.equal(got.faces, ref.faces)
            torch.testing.assert_close(got.verts, ref.verts, **tol)
            torch.testing.assert_close(got.normals, ref.normals, rtol=0, atol=1e-4)
            assert torch.allclose(got.normals.norm(dim=1), got.normals.new_ones(()))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_gradients_finite_for_tiny_fields_with_spacing_grad(dtype):
    X, Y, Z, h, lo = grid(8, dtype=dtype)
    vol = (sphere(X, Y, Z) * 1e-20).requires_grad_()
    spacing = torch.full((3,), h, dtype=dtype, requires_grad=True)
    r = marching_cubes(vol, spacing=spacing)
    (r.verts.sum() + r.normals.sum()).backward()
    assert torch.isfinite(vol.grad).all() and torch.isfinite(spacing.grad).all()
    assert vol.grad.abs().max() > 0
    assert torch.allclose(r.normals.norm(dim=1), r.normals.new_ones(()))


@pytest.mark.parametrize("half", [torch.float16, torch.bfloat16])
def test_half_precision_classified_as_is_and_interpolated_in_float32(half):
    X, Y, Z, h, lo = grid(40, dtype=torch.float32)
    vol = sphere(X, Y, Z).to(half)
    got = marching_cubes(vol, origin=(lo, lo, lo), spacing=(h, h, h))
    want = marching_cubes(vol.float(), origin=(lo, lo, lo), spacing=(h, h, h))
    assert got.verts.dtype == half and got.normals.dtype == half
    assert torch.equal(got.faces, want.faces)  # same topology as the float32 samples
    torch.testing.assert_close(got.verts.float(), want.verts,
                               rtol=2 * torch.finfo(half).eps, atol=0)
    # the float32 positions keep the guarantees (no duplicates, no zero-area faces)
    v = want.verts.numpy()
    assert np.unique(v, axis=0).shape[0] == v.shape[0]
    assert triangle_areas(v.astype(np.float64), want.faces.numpy()).min() > 0



# ---------------------------------------------------------- ambiguity="asymptotic"
def cell_outlines(verts: np.ndarray, faces: np.ndarray) -> set:
    """The closed polygons each cell cuts from its faces, as a set of (cell, edge, edge).

    Vertices on grid edges are keyed by their grid edge; a face belongs to the cell
    holding all its vertices (a cell-centre vertex names its cell). The outline of a
    cell is the set of its faces' edges used once within the cell.
    """
    r = np.round(verts)
    on = verts == r
    ok = on.sum(1) == 2
    axis = np.argmin(on, axis=1)
    low = np.where(on, r, np.floor(verts)).astype(np.int64)
    key = np.where(ok, ((low[:, 0] * 1000 + low[:, 1]) * 1000 + low[:, 2]) * 3 + axis, -1)
    cand = np.empty((verts.shape[0], 4), dtype=np.int64)
    for dv in range(4):
        c = low.copy()
        for s, shift in enumerate((1, 2)):
            c[np.arange(len(c)), (axis + shift) % 3] -= (dv >> s) & 1
        cand[:, dv] = (c[:, 0] * 1000 + c[:, 1]) * 1000 + c[:, 2]
    centre = np.floor(verts).astype(np.int64) @ np.array([1000000, 1000, 1])
    cand[~ok] = centre[~ok, None]
    fc = cand[faces]  # (F, 3, 4)
    hit = (fc[:, 0, :, None, None] == fc[:, 1, None, :, None]) & (
        fc[:, 0, :, None, None] == fc[:, 2, None, None, :])
    good = hit.any((2, 3))  # (F, 4): candidates of vertex 0 shared by the other two
    unique = good.sum(1) == 1  # faces lying in one face plane (two cells) are skipped
    cell = fc[:, 0][np.arange(len(faces)), good.argmax(1)]
    with_centre = (~ok[faces]).any(1)
    first_centre = faces[np.arange(len(faces)), (~ok[faces]).argmax(1)]
    cell = np.where(with_centre, centre[first_centre], cell)
    unique |= with_centre
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    k = np.sort(key[edges], axis=1)
    rows = np.concatenate([np.stack([np.tile(cell, 3)], 1), k], axis=1)[np.tile(unique, 3)]
    u, c = np.unique(rows, axis=0, return_counts=True)
    once = u[(c == 1) & (u[:, 1] >= 0)]
    return set(map(tuple, once.tolist()))


def test_configuration_tables_boundary_is_the_face_segments_for_every_decision():
    from torchgeo_cg.mesh.marching_cubes._tables import (
        CENTRE,
        ambiguous_faces,
        configuration_triangles,
        tube_candidates,
    )

    n_configs = n_tubes = n_centres = 0
    for case in range(256):
        amb = ambiguous_faces(case)
        for bits in range(64):
            if bits & ~amb:
                continue
            for tube in range(len(tube_candidates(case, bits)) + 1):
                tris, centre_mask = configuration_triangles(case, bits, tube)
                directed = {e for a, b, c in tris for e in ((a, b), (b, c), (c, a))}
                assert len(directed) == 3 * len(tris), (case, bits, tube)  # no edge twice
                boundary = {e for e in directed if (e[1], e[0]) not in directed}
                segments = {sg for face in range(6)
                            for sg in face_segments(case, face, bool((bits >> face) & 1))}
                assert boundary == segments, (case, bits, tube)
                used = {e for t in tris for e in t}
                assert (CENTRE in used) == (centre_mask != 0)
                n_configs += 1
                n_tubes += tube > 0
                n_centres += centre_mask != 0
    assert (n_configs, n_tubes) == (1080, 424)
    assert n_centres > 0


def test_tables_shared_faces_close_for_every_face_decision():
    # a face decision is taken once per grid face: both cells draw the same segments
    checked = 0
    for axis in range(3):
        high = next(f for f, (ax, side, _) in enumerate(CUBE_FACES) if ax == axis and side == 1)
        low = next(f for f, (ax, side, _) in enumerate(CUBE_FACES) if ax == axis and side == 0)
        shift = 4 >> axis
        for case_a in range(256):
            shared = [c for c in range(8) if CORNER_OFFSETS[c][axis] == 1]
            # case_b: the shared corners (at its side 0), anything else at its side 1
            base = sum(((case_a >> c) & 1) << (c ^ shift) for c in shared)
            ring = CUBE_FACES[high][2]
            bits = [(case_a >> c) & 1 for c in ring]
            if not bits[0] == bits[2] != bits[1] == bits[3]:
                continue
            for join in (False, True):
                seg_a = {frozenset((p, q)) for p, q in face_segments(case_a, high, join)}
                seg_b = face_segments(base, low, join)
                moved = {frozenset((_shift_edge(p, axis), _shift_edge(q, axis)))
                         for p, q in seg_b}
                assert seg_a == moved, (axis, case_a, join)
                checked += 1
    assert checked == 3 * 2 * 2 * 16  # 2 ambiguous patterns x 16 far sides x 2 decisions


def _shift_edge(e: int, axis: int) -> int:
    """The edge of the cell below (along ``axis``) that is edge ``e`` of its neighbour above."""
    a, b = EDGE_CORNERS[e]
    bit = 4 >> axis
    return next(k for k, pair in enumerate(EDGE_CORNERS) if set(pair) == {a | bit, b | bit})


def _padded(field: np.ndarray) -> np.ndarray:
    return np.pad(field, 1, constant_values=1.0)


@pytest.mark.parametrize("kind", ["smooth", "random", "integer"])
def test_asymptotic_outlines_equal_skimage_lewiner(kind):
    rng = np.random.default_rng(11)
    field = {
        "smooth": lambda: gaussian_filter(rng.standard_normal((30, 30, 30)), 1.5),
        "random": lambda: rng.standard_normal((16, 16, 16)),
        "integer": lambda: rng.integers(-3, 4, (16, 16, 16)) + 0.5,  # no exact-level sample
    }[kind]()
    field = _padded(field)
    ours = marching_cubes(torch.from_numpy(field))
    sk_v, sk_f, _, _ = skimage_measure.marching_cubes(field, 0.0, method="lewiner")
    a = cell_outlines(ours.verts.numpy(), ours.faces.numpy())
    b = cell_outlines(sk_v.astype(np.float64), sk_f)
    cells = {e[0] for e in a | b}
    differ = {e[0] for e in a ^ b}
    # the old rule differs in many ambiguous cells; the decider matches Lewiner's
    old = cell_outlines(*(t.numpy() for t in marching_cubes(
        torch.from_numpy(field), ambiguity="separate")[:2]))
    old_differ = {e[0] for e in old ^ b}
    assert len(differ) <= 1e-3 * len(cells), (len(differ), len(cells))
    if kind != "smooth":
        assert len(old_differ) > 20 * max(len(differ), 1)
    ok, why = closed_and_oriented(ours.verts.numpy(), ours.faces.numpy())
    assert ok, why


@pytest.mark.parametrize("field_name", ["gyroid", "noise"])
def test_asymptotic_area_and_volume_match_skimage_lewiner(field_name):
    n = 64
    if field_name == "gyroid":
        X, Y, Z, h, lo = grid(n)
        field = gyroid_ball(X, Y, Z)
    else:
        field, h, lo = noise_ball(n)
    ours = marching_cubes(field)
    sk_v, sk_f, _, _ = skimage_measure.marching_cubes(field.numpy(), 0.0, method="lewiner")
    sk_v = sk_v.astype(np.float64)
    v, f = ours.verts.numpy(), ours.faces.numpy()
    area, sk_area = triangle_areas(v, f).sum(), triangle_areas(sk_v, sk_f).sum()
    assert abs(area / sk_area - 1) < 1e-3
    vol, sk_vol = signed_volume(v, f), abs(signed_volume(sk_v, sk_f))
    assert abs(vol / sk_vol - 1) < 1e-3


def _components(faces: np.ndarray) -> int:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    n = int(faces.max()) + 1
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[0]


@pytest.mark.parametrize("others,tube", [(0.1, True), (1.0, False)])
def test_interior_test_joins_body_diagonal_corners_by_a_tube(others, tube):
    # MC33 case 4: corners 0 and 7 inside, all faces unambiguous; the trilinear
    # interpolant joins them through the cell iff its value at the centre is inside
    cell = np.full((2, 2, 2), others)
    cell[0, 0, 0] = cell[1, 1, 1] = -1.0
    field = np.pad(cell, 1, constant_values=others)
    ours = marching_cubes(torch.from_numpy(field))
    sk_v, sk_f, _, _ = skimage_measure.marching_cubes(field, 0.0, method="lewiner")
    assert _components(ours.faces.numpy()) == (1 if tube else 2)
    assert _components(sk_f) == _components(ours.faces.numpy())
    # no tube: two octahedra around the two inside samples
    assert ours.faces.shape[0] == (len(sk_f) if tube else 16)
    ok, why = closed_and_oriented(ours.verts.numpy(), ours.faces.numpy())
    assert ok, why


def test_face_decider_by_hand():
    # one ambiguous face x = 0 (corners 0 and 3 inside), the rest outside: the saddle
    # value (f00 f11 - f01 f10) / (f00 + f11 - f01 - f10) decides
    def cell(inside_product):
        c = np.full((2, 2, 2), 1.0)
        c[0, 0, 0], c[0, 1, 1] = -inside_product, -1.0
        return torch.from_numpy(np.pad(c, 1, constant_values=1.0))

    joined = marching_cubes(cell(2.0))  # saddle (2 - 1) / (-3 - 2) < 0: inside, joined
    split = marching_cubes(cell(0.5))  # saddle (0.5 - 1) / (-1.5 - 2) > 0: separated
    assert _components(joined.faces.numpy()) == 1 and _components(split.faces.numpy()) == 2
    tie = marching_cubes(cell(1.0))  # saddle exactly at iso: outside, like a sample
    assert _components(tie.faces.numpy()) == 2
    assert _components(marching_cubes(cell(2.0), ambiguity="separate").faces.numpy()) == 2


@pytest.mark.slow
@pytest.mark.grad
def test_gradcheck_asymptotic_with_soft_weights_on_ambiguous_cells():
    gen = torch.Generator().manual_seed(4)
    vol = pad_outside(torch.randn(3, 3, 3, generator=gen, dtype=torch.float64), 1.0)
    cases = cell_cases(vol.numpy())
    assert np.asarray(AMBIGUOUS)[cases].any()
    vol.requires_grad_()
    iso = torch.tensor(0.05, dtype=torch.float64, requires_grad=True)

    def fn(v, i):
        r = marching_cubes(v, iso=i, temperature=0.3)
        return r.verts, r.normals, r.face_weights

    assert torch.autograd.gradcheck(fn, (vol, iso), eps=1e-6, atol=1e-6)


def test_interior_test_agrees_with_a_brute_force_flood_fill_of_the_trilinear_interpolant():
    # For random cells with a possible tube: sample the trilinear interpolant on a fine
    # grid, flood-fill the region of the tube's sign, and check whether the two patches
    # the tube would join touch the same component. (scikit-image's Lewiner test reports
    # more tunnels than this reference on random fields: its Euler characteristics are
    # lower; ours follow the interpolant.)
    from scipy.ndimage import label

    from torchgeo_cg.mesh.marching_cubes._decider import face_decisions, interior_decisions
    from torchgeo_cg.mesh.marching_cubes._tables import (
        configuration_tensors,
        corner_patches,
        tube_candidates,
    )

    tables = configuration_tensors()
    rng = np.random.default_rng(1)
    n = 25
    s = np.linspace(0, 1, n)
    X, Y, Z = np.meshgrid(s, s, s, indexing="ij")
    basis = np.stack([np.where(dx, X, 1 - X) * np.where(dy, Y, 1 - Y) * np.where(dz, Z, 1 - Z)
                      for dx, dy, dz in CORNER_OFFSETS])  # (8, n, n, n)
    corner_index = [tuple(np.array(off) * (n - 1)) for off in CORNER_OFFSETS]
    g = torch.from_numpy(rng.standard_normal((15000, 8)))
    cases = ((g < 0).long() << torch.arange(8)).sum(1)
    config = cases * 64 + face_decisions(g, cases, tables)
    ask = tables.needs_interior[config].nonzero().squeeze(1)[:1500]
    ours = interior_decisions(g[ask], config[ask], tables)
    tunnels = disagree = 0
    for k, cell in enumerate(ask.tolist()):
        case, bits = int(cases[cell]), int(config[cell]) % 64
        f = np.tensordot(g[cell].numpy(), basis, 1)
        patches = corner_patches(case, bits)
        truth = 0
        for t, (_, _, sign, pa, pc) in enumerate(tube_candidates(case, bits)):
            lab, _ = label(f < 0 if sign else f >= 0)
            la = {lab[corner_index[c]] for c in range(8) if patches[c] == pa}
            lc = {lab[corner_index[c]] for c in range(8) if patches[c] == pc}
            if (la & lc) - {0}:
                truth = t + 1
        tunnels += truth > 0
        disagree += truth != int(ours[k])
    assert len(ask) == 1500 and tunnels >= 10
    assert disagree <= 5  # thin tunnels below the flood fill's resolution


# ----------------------------------------------------------------------------- contract ------
@pytest.mark.parametrize("where", [(0, 0, 0), (2, 3, 1)])
@pytest.mark.parametrize("mask", [None, torch.zeros(4, 4, 4, dtype=torch.bool)])
def test_nan_sample_raises_naming_volume(where, mask):
    # a NaN sample is neither inside nor outside: it was silently outside (swallowed)
    X, Y, Z, h, lo = grid(4)
    vol = sphere(X, Y, Z, 0.9)
    vol[where] = float("nan")
    with pytest.raises(ValueError, match="volume: expected no NaN samples.*got 1 of 64"):
        marching_cubes(vol, mask=mask)
    with pytest.raises(ValueError, match="volume"):
        marching_cubes(torch.stack([sphere(X, Y, Z), vol]).float())


def test_nan_iso_raises_and_opposite_infinities_are_samples():
    X, Y, Z, h, lo = grid(5)
    vol = sphere(X, Y, Z)
    with pytest.raises(ValueError, match="iso"):  # not an empty mesh
        marching_cubes(vol, iso=float("nan"))
    with pytest.raises(ValueError, match="iso"):
        marching_cubes(torch.stack([vol, vol]), iso=torch.tensor([0.0, float("nan")]))
    # +inf and -inf samples make the fast check's sum NaN; they are valid samples
    vol = vol.clone()
    vol[0, 0, 0], vol[-1, -1, -1] = float("inf"), -float("inf")
    result = marching_cubes(vol)
    assert result.faces.shape[0] > 0 and torch.isfinite(result.verts).all()


@pytest.mark.parametrize("soft", [None, 0.5])
def test_empty_batch_gives_empty_result(soft):
    # unguarded: ValueError from torch.cat(): expected a non-empty list of Tensors
    for dtype in (torch.float32, torch.float64):
        result = marching_cubes(torch.zeros(0, 3, 4, 5, dtype=dtype), iso=torch.zeros(0),
                                origin=torch.zeros(0, 3), temperature=soft)
        shapes = [tuple(x.shape) for x in result]
        assert shapes == [(0, 3), (0, 3), (0, 3), (0,), (0,), (0,)]
        assert [x.dtype for x in result] == [dtype, torch.long, dtype, dtype, torch.long,
                                             torch.long]
        assert result.split() == []


@pytest.mark.parametrize("s", [1e-300, 1e-200, 1e200, 1e300])
@pytest.mark.parametrize("ambiguity", ["asymptotic", "separate"])
def test_any_float64_field_scale_gives_the_same_mesh(s, ambiguity):
    # unguarded: the decider's products g_a g_c - g_b g_d underflowed to 0 (ties) below ~1e-160
    # and overflowed to inf - inf = NaN above ~1e154, changing the triangulation
    gen = torch.Generator().manual_seed(3)
    vol = torch.randn(2, 7, 6, 5, generator=gen, dtype=torch.float64)
    want = marching_cubes(vol, ambiguity=ambiguity)
    got = marching_cubes(vol * s, ambiguity=ambiguity)
    assert torch.equal(got.faces, want.faces)
    torch.testing.assert_close(got.verts, want.verts, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(got.normals, want.normals, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("h", [1e-310, 1e-200, 1e200])
def test_normals_at_tiny_and_huge_spacing(h):
    # unguarded: grad / spacing overflowed to inf at a subnormal spacing (NaN normals)
    X, Y, Z, _, lo = grid(6)
    vol = torus(X, Y, Z)
    want = marching_cubes(vol, spacing=(1.0, 2.0, 0.5))
    got = marching_cubes(vol, spacing=(h, 2 * h, 0.5 * h))
    assert torch.equal(got.faces, want.faces)
    torch.testing.assert_close(got.normals, want.normals, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("s", [1e30, 8e37])
def test_float32_field_near_the_top_of_its_range(s):
    # unguarded: f2 - f1 and the central differences overflowed to inf beyond ~4e37: vertices
    # moved to the sample and normals were NaN (inf / inf) although every input was finite
    gen = torch.Generator().manual_seed(0)
    vol = torch.randn(2, 6, 6, 6, generator=gen, dtype=torch.float32)
    got = marching_cubes(vol * s, iso=torch.tensor([0.0, 0.25 * s]))
    assert torch.isfinite(got.verts).all() and torch.isfinite(got.normals).all()
    want = marching_cubes(vol.double(), iso=torch.tensor([0.0, 0.25], dtype=torch.float64))
    assert torch.equal(got.faces, want.faces)
    torch.testing.assert_close(got.verts.double(), want.verts, rtol=0, atol=1e-5)
    torch.testing.assert_close(got.normals.double(), want.normals, rtol=0, atol=1e-5)


def test_float64_field_near_the_top_of_its_range():
    # unguarded: f - iso overflowed to inf in the decider for samples and iso of opposite signs
    # near 1e308 (inf products, NaN decisions), changing the triangulation
    gen = torch.Generator().manual_seed(4)
    u = torch.rand(2, 6, 5, 7, generator=gen, dtype=torch.float64)
    inside = torch.rand(2, 6, 5, 7, generator=gen, dtype=torch.float64) < 0.5
    vol = torch.where(inside, -0.86 - 0.1 * u, 0.98 + 0.02 * u)  # many ambiguous cells
    iso = torch.tensor([-0.82, -0.84], dtype=torch.float64)
    want = marching_cubes(vol, iso=iso)
    got = marching_cubes(vol * 1e308, iso=iso * 1e308)
    assert torch.equal(got.faces, want.faces)
    torch.testing.assert_close(got.verts, want.verts, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(got.normals, want.normals, rtol=1e-12, atol=1e-12)


def test_soft_weights_near_the_top_of_the_range():
    # unguarded: iso - f overflowed to inf, so logits (iso - f) / tau saturated: weights 0 or 1
    gen = torch.Generator().manual_seed(5)
    u = torch.rand(6, 5, 7, generator=gen, dtype=torch.float64)
    inside = torch.rand(6, 5, 7, generator=gen, dtype=torch.float64) < 0.5
    vol = torch.where(inside, -0.86 - 0.1 * u, 0.98 + 0.02 * u)
    want = marching_cubes(vol, iso=-0.82, temperature=0.7)
    assert want.faces.shape[0] > 0 and (want.face_weights > 1e-200).all()
    s = 1e308
    got = marching_cubes(vol * s, iso=-0.82 * s, temperature=0.7 * s)
    assert torch.equal(got.faces, want.faces)
    torch.testing.assert_close(got.face_weights, want.face_weights, rtol=1e-12, atol=0.0)


def test_half_positions_saturate_instead_of_inf():
    # unguarded: float16 positions beyond 65504 (a large origin) were rounded to inf
    X, Y, Z, h, lo = grid(6)
    vol = sphere(X, Y, Z).half()
    origin = (65530.0, 0.0, 0.0)  # x beyond 65520 rounds to inf in float16
    got = marching_cubes(vol, origin=origin, spacing=(h, h, h))
    ref = marching_cubes(vol.float(), origin=origin, spacing=(h, h, h))
    assert torch.isfinite(got.verts).all()
    top = torch.finfo(torch.float16).max
    torch.testing.assert_close(got.verts, ref.verts.clamp(max=top).half())


# ------------------------------------------------------------ slabs of a large volume
_dense = importlib.import_module("torchgeo_cg.mesh.marching_cubes.dense")
_slabs = importlib.import_module("torchgeo_cg.mesh.marching_cubes._slabs")


def _slab_fields():
    """Fields whose surfaces cross many slab seams, with many samples exactly at iso."""
    g = torch.Generator().manual_seed(11)
    X, Y, Z, h, lo = grid(40, -1.5, 1.5)
    quantised = torch.round(double_torus(X, Y, Z) * 8) / 8  # exact zeros on many layers
    ties = torch.randint(-1, 2, (2, 23, 17, 19), generator=g).to(torch.float64)
    noise = torch.from_numpy(gaussian_filter(
        torch.randn(3, 26, 24, 22, generator=g).numpy(), (0, 1.5, 1.5, 1.5)))
    return {"quantised": quantised, "ties": ties, "noise": noise,
            "gyroid32": (torch.sin(4 * X) * torch.cos(4 * Y) + torch.sin(4 * Y)
                         * torch.cos(4 * Z) + torch.sin(4 * Z) * torch.cos(4 * X)).float()}


@pytest.mark.parametrize("ambiguity", ["asymptotic", "separate"])
@pytest.mark.parametrize("name", ["quantised", "ties", "noise", "gyroid32"])
def test_slabbed_equals_one_go_bit_for_bit(name, ambiguity, monkeypatch):
    """A volume extracted slab by slab gives exactly the one-go result: the same vertices
    (bits), normals, faces in the same order and counts, also for batches, with samples
    exactly at iso on the seams; a closed surface stays closed and oriented."""
    vol = _slab_fields()[name]
    frame = {}
    if vol.ndim == 4:  # per-volume frames and levels
        B = vol.shape[0]
        frame = {"origin": torch.linspace(-1, 1, 3 * B, dtype=vol.dtype).view(B, 3),
                 "spacing": torch.linspace(0.5, 2, 3 * B, dtype=vol.dtype).view(B, 3)}
    monkeypatch.setattr(_slabs, "SLAB_ACTIVE", 1 << 40)
    whole = marching_cubes(vol, ambiguity=ambiguity, **frame)
    monkeypatch.setattr(_slabs, "SLAB_ACTIVE", 256)
    seen = []
    real = _slabs.triangulate
    monkeypatch.setattr(_slabs, "triangulate",
                        lambda *a, **k: seen.append(k["layers"]) or real(*a, **k))
    slabbed = marching_cubes(vol, ambiguity=ambiguity, **frame)
    assert len(seen) > 3  # it did run in slabs
    for got, want in zip(slabbed, whole):
        assert got.dtype == want.dtype and torch.equal(got, want)
    stacked = vol.reshape(-1, *vol.shape[-2:])
    seams = sorted({a for a, _ in seen} - {0})
    crossed = [s for s in seams if (stacked[s] < 0).any() and (stacked[s] >= 0).any()]
    assert crossed  # the surface crosses seams
    if name in ("quantised", "ties"):
        assert any(bool((stacked[s] == 0).any()) for s in crossed)  # samples at iso on one
    if name == "quantised":  # the one closed surface (the others reach the border)
        ok, why = closed_and_oriented(slabbed.verts.numpy(), slabbed.faces.numpy())
        assert ok, why


def test_slabbed_equals_one_go_with_near_overflow_samples(monkeypatch):
    """Near-overflow samples (whose vertices are rescaled) in one part of the volume, and in
    another vertices whose stencils mix 1e300 and 1e-9 (rescaling those would push the
    small samples into subnormals and change their bits): the slabbed result equals the one-go
    result bit for bit, and the huge part equals the unscaled field's extraction."""
    g = torch.Generator().manual_seed(5)
    X, Y, Z, h, lo = grid(40, -1.5, 1.5)
    sphere = torch.sqrt((X + 0.75) ** 2 + Y**2 + Z**2) - 0.5
    choice = torch.randint(0, 4, X.shape, generator=g)
    small = (torch.rand(X.shape, generator=g, dtype=torch.float64) - 0.5) * 1e-9
    huge_pm = torch.where(choice == 2, -1e300, torch.full_like(small, 1e300))
    mixed = torch.where(choice < 2, small, huge_pm)
    for huge in (1e308, 2.0**1022):
        field = torch.where(X < 0, sphere * huge, mixed)
        assert field.abs().max() > torch.finfo(torch.float64).max / 4
        monkeypatch.setattr(_slabs, "SLAB_ACTIVE", 1 << 40)
        whole = marching_cubes(field)
        monkeypatch.setattr(_slabs, "SLAB_ACTIVE", 64)
        slabbed = marching_cubes(field)
        for got, want in zip(slabbed, whole):
            assert torch.equal(got, want)
    # scaled by an exact power of two, the huge part away from the seam x = 0 (index 19.5)
    # is the unscaled field's extraction, bit for bit
    reference = marching_cubes(torch.where(X < 0, sphere, mixed))
    far, far_ref = whole.verts[:, 0] < 18, reference.verts[:, 0] < 18
    assert far.sum() > 100
    assert torch.equal(whole.verts[far], reference.verts[far_ref])
    assert torch.equal(whole.normals[far], reference.normals[far_ref])


def test_slabs_keep_the_autograd_path(monkeypatch):
    """With autograd recording, the call runs in one go (the gradients are those of the
    one-go path); without, in slabs; the values agree exactly."""
    X, Y, Z, h, lo = grid(30)
    vol = torus(X, Y, Z)
    monkeypatch.setattr(_slabs, "SLAB_ACTIVE", 128)
    calls = []
    real = _dense.extract_slabbed
    monkeypatch.setattr(_dense, "extract_slabbed", lambda *a: calls.append(1) or real(*a))
    plain = marching_cubes(vol)
    assert calls == [1]
    v = vol.clone().requires_grad_(True)
    tracked = marching_cubes(v)
    assert calls == [1]  # not slabbed
    assert torch.equal(tracked.verts, plain.verts) and torch.equal(tracked.faces, plain.faces)
    tracked.verts.sum().backward()
    monkeypatch.setattr(_slabs, "SLAB_ACTIVE", 1 << 40)
    v2 = vol.clone().requires_grad_(True)
    marching_cubes(v2).verts.sum().backward()
    assert torch.equal(v.grad, v2.grad)
    with torch.no_grad():
        monkeypatch.setattr(_slabs, "SLAB_ACTIVE", 128)
        assert torch.equal(marching_cubes(v).verts, plain.verts)
    assert calls == [1, 1]


# ------------------------------------------------------------ public names
def test_ambiguous_cases_is_edge_connectivity_by_brute_force():
    """The public flag of a case: its inside or its outside corners are not connected
    along the cube's edges (union-find over the 12 edges, in the test)."""
    from torchgeo_cg.mesh.marching_cubes import AMBIGUOUS_CASES

    corners = [((c >> 2) & 1, (c >> 1) & 1, c & 1) for c in range(8)]
    edges = [(a, b) for a in range(8) for b in range(a + 1, 8)
             if sum(abs(p - q) for p, q in zip(corners[a], corners[b])) == 1]

    def connected(members):
        parent = {c: c for c in members}

        def root(c):
            while parent[c] != c:
                c = parent[c]
            return c
        for a, b in edges:
            if a in parent and b in parent:
                parent[root(a)] = root(b)
        return len({root(c) for c in members}) <= 1

    want = tuple(not (connected([c for c in range(8) if (case >> c) & 1])
                      and connected([c for c in range(8) if not (case >> c) & 1]))
                 for case in range(256))
    assert len(edges) == 12 and AMBIGUOUS_CASES == want and sum(want) == 128


@pytest.mark.parametrize("module", ["torchgeo_cg.mesh.marching_cubes.dense",
                                    "torchgeo_cg.mesh.marching_cubes.sparse",
                                    "torchgeo_cg.mesh.marching_cubes"])
def test_public_modules_define_only_public_or_private_names(module):
    """Every name a public module defines (function, class, assignment) is in its
    ``__all__`` or ``_``-prefixed."""
    import ast

    mod = importlib.import_module(module)
    tree = ast.parse(Path(mod.__file__).read_text(encoding="utf-8"))
    defined = []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            defined.append(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            defined += [t.id for t in targets if isinstance(t, ast.Name)]
    third = [n for n in defined if not n.startswith("_") and n not in mod.__all__]
    assert third == []
