"""sparse_marching_cubes against dense marching_cubes on the fully sampled grid."""

from __future__ import annotations

import math
import os
import socket

import numpy as np
import pytest
import torch
import torch.multiprocessing as mp
from torch import nn

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.mesh import lipschitz_bound, marching_cubes, sparse_marching_cubes
from torchgeo_cg.sdf import box, difference, gyroid, mesh_sdf, sample_grid, sphere, torus

BOUNDS = (-1.0, 1.0)


def _dense(field, res, bounds=BOUNDS, ambiguity="asymptotic", dtype=torch.float64, grad=False):
    vol = sample_grid(field, res, bounds, dtype=dtype, grad=grad)
    return marching_cubes(vol, ambiguity=ambiguity)


def _face_set(faces: torch.Tensor) -> set:
    """Faces as rotation-canonical tuples (winding kept)."""
    f = faces.tolist()
    out = set()
    for a, b, c in f:
        m = min(a, b, c)
        out.add((a, b, c) if a == m else (b, c, a) if b == m else (c, a, b))
    return out


def _assert_watertight(faces: torch.Tensor) -> None:
    """Every directed edge once, with its reverse once: closed and edge-manifold."""
    f = faces.numpy()
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    keys = directed[:, 0].astype(np.int64) * (f.max() + 1) + directed[:, 1]
    rev = directed[:, 1].astype(np.int64) * (f.max() + 1) + directed[:, 0]
    assert np.unique(keys).shape[0] == keys.shape[0], "a directed edge is used twice"
    assert np.isin(rev, keys).all(), "an edge has one face only (hole)"


def _assert_equal(sparse, dense, watertight=True):
    assert sparse.verts.shape == dense.verts.shape
    assert (sparse.verts - dense.verts).abs().max() <= 1e-12
    assert (sparse.normals - dense.normals).abs().max() <= 1e-12
    assert sparse.faces.shape == dense.faces.shape
    assert _face_set(sparse.faces) == _face_set(dense.faces)
    assert int(sparse.verts_per_mesh) == sparse.verts.shape[0]
    if watertight:
        _assert_watertight(sparse.faces)


def _csg(p):
    return difference(box(p, torch.tensor([0.6, 0.5, 0.4], dtype=p.dtype)),
                      sphere(p, 0.55, torch.tensor([0.3, 0.2, 0.1], dtype=p.dtype)))


def _shell(p):
    return sphere(p, 0.6).abs() - 0.02


def _torus(p):
    return torus(p, 0.6, 0.25)


def _gyroid(p):
    return gyroid(p, 6.0, 0.3)


# gyroid: |grad g| <= sqrt(3) * sqrt(2) per unit of q = scale * p; f = |g| / scale - t / 2
FIELDS = {"sphere": (lambda p: sphere(p, 0.55), 1.0), "torus": (_torus, 1.0),
          "csg": (_csg, 1.0), "shell": (_shell, 1.0), "gyroid": (_gyroid, math.sqrt(6.0))}


@pytest.mark.parametrize("ambiguity", ["asymptotic", "separate"])
@pytest.mark.parametrize("name", list(FIELDS))
def test_exact_fields_equal_dense_at_64(name, ambiguity):
    field, L = FIELDS[name]
    bounds = torch.tensor(BOUNDS, dtype=torch.float64)
    sparse = sparse_marching_cubes(field, bounds, 64, lipschitz=L, ambiguity=ambiguity)
    dense = _dense(field, 64, ambiguity=ambiguity)
    # the gyroid is cut by the bounds: open at the border, so not watertight
    _assert_equal(sparse, dense, watertight=name != "gyroid")
    assert torch.equal(sparse.verts, dense.verts)  # same order, bit for bit


@pytest.mark.parametrize("res", [256, pytest.param(512, marks=pytest.mark.slow)])
@pytest.mark.parametrize("name", ["torus", "csg"])
def test_exact_fields_equal_dense_large(name, res):
    if res == 512 and name == "csg":
        pytest.skip("one field at 512^3 is enough")
    field, L = FIELDS[name]
    bounds = torch.tensor(BOUNDS, dtype=torch.float64)
    sparse = sparse_marching_cubes(field, bounds, res, lipschitz=L)
    dense = _dense(field, res)
    assert torch.equal(sparse.verts, dense.verts)
    assert sparse.faces.shape == dense.faces.shape
    assert torch.equal(torch.sort(_rot_canonical(sparse.faces)).values,
                       torch.sort(_rot_canonical(dense.faces)).values)


def _rot_canonical(faces):
    """``(F,)`` int64 code of each face up to rotation (for large meshes)."""
    arg = faces.argmin(1, keepdim=True)
    idx = (arg + torch.arange(3)) % 3
    f = faces.gather(1, idx)
    n = int(faces.max()) + 1
    return (f[:, 0] * n + f[:, 1]) * n + f[:, 2]


@pytest.mark.parametrize("block", [1, 3, 4, 7])
@pytest.mark.parametrize("res", [13, 23, 30])
def test_any_resolution_partial_blocks(res, block):
    field = FIELDS["torus"][0]
    sparse = sparse_marching_cubes(field, torch.tensor(BOUNDS, dtype=torch.float64), res,
                                   block=block)
    _assert_equal(sparse, _dense(field, res))


def test_anisotropic_bounds_and_resolution():
    bounds = torch.tensor([[-1.0, -0.8, -0.5], [1.0, 0.8, 0.5]], dtype=torch.float64)
    field = FIELDS["torus"][0]
    sparse = sparse_marching_cubes(field, bounds, (37, 21, 18), block=4)
    _assert_equal(sparse, marching_cubes(sample_grid(field, (37, 21, 18), bounds)), False)


def test_seams_face_edge_corner_and_samples_at_iso():
    """Sphere centred on a block corner (8 blocks meet there, so the surface crosses
    seams at faces, edges and the corner), with samples exactly at iso on seams; and
    planes lying exactly on a block boundary."""
    bounds = torch.tensor(BOUNDS, dtype=torch.float64)  # 33 samples: spacing 1/16
    def field(p):
        return sphere(p, 0.5)  # (0.5, 0, 0) is sample 24 = a block corner
    vol = sample_grid(field, 33, bounds)
    assert int((vol.values == 0).sum()) >= 6
    for block in (4, 8):
        _assert_equal(sparse_marching_cubes(field, bounds, 33, block=block),
                      marching_cubes(vol))
    for axis in range(3):  # plane on the seam x = 0 (samples exactly 0, outside)
        def plane(p, a=axis):
            return p[:, a] - 0.0
        sparse = sparse_marching_cubes(plane, bounds, 33, block=4)
        dense = marching_cubes(sample_grid(plane, 33, bounds))
        _assert_equal(sparse, dense, watertight=False)
        assert sparse.faces.shape[0] == 2 * 32 * 32


def test_float32_points_and_equal_dense():
    bounds = torch.tensor(BOUNDS, dtype=torch.float32)
    field = FIELDS["csg"][0]
    sparse = sparse_marching_cubes(field, bounds, 40, block=4)
    dense = marching_cubes(sample_grid(field, 40, bounds))
    assert sparse.verts.dtype == torch.float32
    assert torch.equal(sparse.verts, dense.verts)
    assert _face_set(sparse.faces) == _face_set(dense.faces)


def test_iso_level_and_no_surface():
    bounds = torch.tensor(BOUNDS, dtype=torch.float64)
    def field(p):
        return sphere(p, 0.3)
    sparse = sparse_marching_cubes(field, bounds, 30, iso=0.25)
    _assert_equal(sparse, marching_cubes(sample_grid(field, 30, bounds), iso=0.25))
    empty = sparse_marching_cubes(field, bounds, 30, iso=5.0)
    assert empty.verts.shape == (0, 3) and empty.faces.shape == (0, 3)
    assert empty.verts.dtype == torch.float64


def test_python_iso_takes_the_field_dtype():
    """A Python (or numpy) iso is not rounded through float32 on a float64 field: at
    iso=0.05 (not a float32 number) sparse and dense are identical, bit for bit."""
    bounds = torch.tensor(BOUNDS, dtype=torch.float64)
    def field(p):
        return sphere(p, 0.5)
    dense = marching_cubes(sample_grid(field, 33, bounds), iso=0.05)
    for iso in (0.05, np.float64(0.05), torch.tensor(0.05, dtype=torch.float64)):
        sparse = sparse_marching_cubes(field, bounds, 33, iso=iso, block=4)
        assert torch.equal(sparse.verts, dense.verts)
        assert torch.equal(sparse.normals, dense.normals)
        assert _face_set(sparse.faces) == _face_set(dense.faces)


def test_pruning_skips_far_blocks():
    calls = []

    def field(p):
        calls.append(p.shape[0])
        return sphere(p, 0.5)

    sparse_marching_cubes(field, BOUNDS, 129, block=8)
    assert sum(calls) < 0.25 * 129**3  # the shell only


def test_bound_too_small_is_the_caller_s_promise():
    """A wrong (too small) bound prunes blocks holding the surface: the mesh has holes.
    This documents that the bound is trusted, not checked."""
    def field(p):
        return 10 * sphere(p, 0.5)
    sparse = sparse_marching_cubes(field, torch.tensor(BOUNDS, dtype=torch.float64), 33,
                                   lipschitz=10.0)
    _assert_equal(sparse, _dense(field, 33))
    holes = sparse_marching_cubes(field, torch.tensor(BOUNDS, dtype=torch.float64), 33,
                                  lipschitz=0.01, block=2)
    assert holes.faces.shape[0] < sparse.faces.shape[0]


# ----------------------------------------------------------------------------- narrow band


def _expected_band_faces(field, res, block, band):
    """Faces of the dense mesh whose cell lies within ``band`` blocks of a block with a
    coarse sign change (the documented rule), by brute force."""
    vol = sample_grid(field, res, BOUNDS, dtype=torch.float64)
    dense = marching_cubes(vol)
    inside = (vol.values < 0).numpy()
    n = res - 1
    nb = -(-n // block)
    corners = np.minimum(np.arange(nb + 1) * block, n)
    c = inside[np.ix_(corners, corners, corners)]
    mixed = np.zeros((nb,) * 3, bool)
    for dx in range(nb):
        for dy in range(nb):
            for dz in range(nb):
                w = c[dx:dx + 2, dy:dy + 2, dz:dz + 2]
                mixed[dx, dy, dz] = w.any() and not w.all()
    near = np.zeros_like(mixed)
    for bx, by, bz in zip(*np.nonzero(mixed)):
        near[max(0, bx - band):bx + band + 1, max(0, by - band):by + band + 1,
             max(0, bz - band):bz + band + 1] = True
    index_pos = (dense.verts - vol.origin) / vol.spacing  # (V, 3)
    centroid = index_pos[dense.faces].mean(1)
    cell = centroid.floor().long().clamp_max(n - 1)
    blocks = (cell // block).numpy()
    keep = near[blocks[:, 0], blocks[:, 1], blocks[:, 2]]
    return dense, dense.faces[torch.from_numpy(keep)]


def _droplets(p):
    """A big sphere and small droplets far from it (smaller than a block)."""
    big = sphere(p, 0.4, torch.tensor([-0.3, 0.0, 0.0], dtype=p.dtype))
    small = sphere(p, 0.04, torch.tensor([0.62, 0.61, 0.59], dtype=p.dtype))
    return torch.minimum(big, small)


@pytest.mark.parametrize("band", [0, 1])
def test_narrow_band_follows_the_documented_rule(band):
    sparse = sparse_marching_cubes(_droplets, torch.tensor(BOUNDS, dtype=torch.float64), 65,
                                   lipschitz=None, band=band, block=8)
    dense, expected = _expected_band_faces(_droplets, 65, 8, band)
    assert _face_set(sparse.faces.new_tensor(
        _remap(sparse, dense)[sparse.faces])) == _face_set(expected)
    fraction = sparse.faces.shape[0] / dense.faces.shape[0]
    assert fraction < 1.0  # the droplet is missed
    assert fraction > 0.9  # the big sphere is complete


def _remap(sparse, dense) -> torch.Tensor:
    """Index of each sparse vertex in the dense mesh (by position; they are equal)."""
    d = {tuple(v): i for i, v in enumerate(dense.verts.tolist())}
    return torch.tensor([d[tuple(v)] for v in sparse.verts.tolist()], dtype=torch.long)


def test_narrow_band_complete_for_a_smooth_surface():
    field = FIELDS["torus"][0]
    sparse = sparse_marching_cubes(field, torch.tensor(BOUNDS, dtype=torch.float64), 50,
                                   lipschitz=None, band=1, block=6)
    _assert_equal(sparse, _dense(field, 50))


# ----------------------------------------------------------------------------- networks


def _trained_mlp(dtype=torch.float32, steps=150) -> nn.Sequential:
    """A small softplus MLP fitted briefly to the SDF of a box mesh."""
    trimesh = pytest.importorskip("trimesh")
    mesh = trimesh.creation.box((1.0, 0.8, 0.6))
    verts = torch.tensor(mesh.vertices, dtype=torch.float64)
    faces = torch.tensor(mesh.faces, dtype=torch.long)
    g = torch.Generator().manual_seed(0)
    pts = torch.rand(4096, 3, generator=g, dtype=torch.float64) * 2 - 1
    target = mesh_sdf(verts, faces, pts).sdf
    torch.manual_seed(0)
    net = nn.Sequential(nn.Linear(3, 32), nn.Softplus(beta=10), nn.Linear(32, 32),
                        nn.Softplus(beta=10), nn.Linear(32, 1)).to(dtype)
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)
    for _ in range(steps):  # loop over optimisation steps
        opt.zero_grad()
        loss = (net(pts.to(dtype)).squeeze(1) - target.to(dtype)).abs().mean()
        loss.backward()
        opt.step()
    return net


@pytest.mark.slow
def test_trained_mlp_with_its_bound_and_narrow_band():
    net = _trained_mlp(torch.float64)
    L = lipschitz_bound(net)
    assert L > 1.0
    bounds = torch.tensor(BOUNDS, dtype=torch.float64)
    with torch.no_grad():
        sparse = sparse_marching_cubes(net, bounds, 48, lipschitz=L, block=4)
        dense = _dense(lambda p: net(p).squeeze(1), 48)
    _assert_equal(sparse, dense)
    with torch.no_grad():
        band = sparse_marching_cubes(net, bounds, 48, lipschitz=None, band=1, block=4)
    _, expected = _expected_band_faces(lambda p: net(p).squeeze(1), 48, 4, 1)
    assert _face_set(_remap(band, dense)[band.faces]) == _face_set(expected)
    assert band.faces.shape[0] / dense.faces.shape[0] == expected.shape[0] / dense.faces.shape[0]


def test_lipschitz_bound_is_a_bound():
    torch.manual_seed(1)
    net = nn.Sequential(nn.Linear(3, 16), nn.ReLU(), nn.Sequential(nn.Linear(16, 16),
                        nn.Tanh()), nn.Linear(16, 1)).double()
    L = lipschitz_bound(net)
    x = torch.randn(2000, 3, dtype=torch.float64)
    y = x + 1e-3 * torch.randn(2000, 3, dtype=torch.float64)
    with torch.no_grad():
        ratio = (net(x) - net(y)).abs().squeeze(1) / (x - y).norm(dim=1)
    assert float(ratio.max()) <= L
    expected = 1.0
    for layer in (net[0], net[2][0], net[3]):
        expected *= float(torch.linalg.svdvals(layer.weight.detach())[0])
    assert L == pytest.approx(expected, rel=1e-12)
    with pytest.raises(TypeError, match="module: module.1 is a GELU"):
        lipschitz_bound(nn.Sequential(nn.Linear(3, 3), nn.GELU()))


class _Bumpy(nn.Module):
    """A sphere with a small learnable MLP bump: ``|p| - 0.5 + 0.2 mlp(p)``."""

    def __init__(self) -> None:
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(3, 16), nn.Softplus(), nn.Linear(16, 1))

    def forward(self, p):
        return p.norm(dim=1) - 0.5 + 0.2 * self.mlp(p).squeeze(1)


@pytest.mark.grad
def test_gradients_equal_dense_path():
    torch.manual_seed(0)
    net = _Bumpy().double()
    bounds = torch.tensor(BOUNDS, dtype=torch.float64)

    def loss_of(mesh):
        return (mesh.verts ** 2).sum() + (mesh.normals[:, 0] * mesh.verts[:, 1]).sum()

    sparse = sparse_marching_cubes(net, bounds, 20, lipschitz=1 + 0.2 * lipschitz_bound(net.mlp),
                                  block=4)
    grads_sparse = torch.autograd.grad(loss_of(sparse), list(net.parameters()))
    dense = _dense(net, 20, grad=True)
    grads_dense = torch.autograd.grad(loss_of(dense), list(net.parameters()))
    assert sparse.faces.shape[0] > 0
    for a, b in zip(grads_sparse, grads_dense):
        assert (a - b).abs().max() <= 1e-10 * max(1.0, float(b.abs().max()))


@pytest.mark.grad
def test_gradcheck_tiny_field():
    bounds = torch.tensor(BOUNDS, dtype=torch.float64)
    centre = torch.tensor([0.05, -0.02, 0.03], dtype=torch.float64, requires_grad=True)
    radius = torch.tensor(0.55, dtype=torch.float64, requires_grad=True)

    def f(c, r):
        mesh = sparse_marching_cubes(lambda p: (p - c).norm(dim=1) - r, bounds, 9, block=2)
        return mesh.verts, mesh.normals

    assert torch.autograd.gradcheck(f, (centre, radius))
    iso = torch.tensor(0.1, dtype=torch.float64, requires_grad=True)
    def g(i):
        return sparse_marching_cubes(lambda p: p.norm(dim=1) - 0.5, bounds, 9, iso=i).verts
    assert torch.autograd.gradcheck(g, (iso,))


def test_no_grad_outputs_are_detached():
    net = nn.Sequential(nn.Linear(3, 8), nn.Softplus(), nn.Linear(8, 1))
    with torch.no_grad():
        mesh = sparse_marching_cubes(net, BOUNDS, 12, lipschitz=None)
    assert not mesh.verts.requires_grad


# ----------------------------------------------------------------------------- distributed


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _rank_main(rank: int, world: int, port: int, out_dir: str) -> None:
    import torch.distributed as dist

    os.environ["MASTER_ADDR"], os.environ["MASTER_PORT"] = "127.0.0.1", str(port)
    torch.set_num_threads(1)
    dist.init_process_group("gloo", rank=rank, world_size=world)
    try:
        torch.manual_seed(0)
        net = _Bumpy()
        with torch.no_grad():
            args = (net, BOUNDS, 40)
            kw = dict(lipschitz=None, block=4, max_points_per_call=1000)
            shared = sparse_marching_cubes(*args, **kw, distributed=True)
            single = sparse_marching_cubes(*args, **kw)
        torch.save({"shared": shared._asdict(), "single": single._asdict()},
                   os.path.join(out_dir, f"rank{rank}.pt"))
    finally:
        dist.destroy_process_group()


@pytest.mark.slow
def test_two_gloo_ranks_byte_identical(tmp_path):
    mp.spawn(_rank_main, args=(2, _free_port(), str(tmp_path)), nprocs=2, join=True)
    r0 = torch.load(tmp_path / "rank0.pt")
    r1 = torch.load(tmp_path / "rank1.pt")
    assert r0["shared"]["faces"].shape[0] > 0
    for key in r0["single"]:
        a, b, c = r0["shared"][key], r1["shared"][key], r0["single"][key]
        assert a.dtype == c.dtype and a.shape == c.shape
        assert a.numpy().tobytes() == c.numpy().tobytes() == b.numpy().tobytes(), key


class _CountingTorus:
    """A torus SDF that counts the points it is asked for."""

    def __init__(self) -> None:
        self.points = 0

    def __call__(self, p):
        self.points += p.shape[0]
        return torus(p, 0.6, 0.25)


def _rank_share(rank: int, world: int, port: int, out_dir: str) -> None:
    import torch.distributed as dist

    os.environ["MASTER_ADDR"], os.environ["MASTER_PORT"] = "127.0.0.1", str(port)
    torch.set_num_threads(1)
    dist.init_process_group("gloo", rank=rank, world_size=world)
    try:
        bounds = torch.tensor(BOUNDS, dtype=torch.float64)
        shared_f, single_f = _CountingTorus(), _CountingTorus()
        kw = dict(block=8)  # the default max_points_per_call: stages smaller than a chunk
        shared = sparse_marching_cubes(shared_f, bounds, 128, **kw, distributed=True)
        single = sparse_marching_cubes(single_f, bounds, 128, **kw)
        torch.save({"shared": shared._asdict(), "single": single._asdict(),
                    "points": (shared_f.points, single_f.points)},
                   os.path.join(out_dir, f"rank{rank}.pt"))
    finally:
        dist.destroy_process_group()


@pytest.mark.slow
def test_two_ranks_share_the_points_evenly(tmp_path):
    """Every stage's points are split into equal shares per rank (then chunked): on a
    128^3 torus neither of 2 ranks evaluates more than 55% of the points, and the mesh
    equals the single-process one byte for byte."""
    mp.spawn(_rank_share, args=(2, _free_port(), str(tmp_path)), nprocs=2, join=True)
    r0, r1 = torch.load(tmp_path / "rank0.pt"), torch.load(tmp_path / "rank1.pt")
    total = r0["points"][1]
    assert total == r1["points"][1] > 0
    assert total <= r0["points"][0] + r1["points"][0] <= total + 1  # + one probe each
    assert max(r0["points"][0], r1["points"][0]) <= 0.55 * total
    for key in r0["single"]:
        a, b, c = r0["shared"][key], r1["shared"][key], r0["single"][key]
        assert a.numpy().tobytes() == c.numpy().tobytes() == b.numpy().tobytes(), key


def test_distributed_needs_a_process_group():
    with pytest.raises(ValueError, match="distributed"):
        sparse_marching_cubes(lambda p: p.norm(dim=1) - 0.5, BOUNDS, 8, distributed=True)


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("field, error, match", [
    (lambda p: p.norm(dim=1, keepdim=True).expand(-1, 2), ShapeError, "field: expected output"),
    (lambda p: p.norm(dim=1)[:-1], ShapeError, "field: expected output"),
    (lambda p: (p.norm(dim=1) - 0.5).float(), TypeError, "field: expected output of dtype"),
    (lambda p: torch.zeros(p.shape[0], dtype=p.dtype, device="meta"), ValueError,
     "field: expected output on"),
    (lambda p: torch.full((p.shape[0],), math.nan, dtype=p.dtype), ValueError,
     "field: returned NaN"),
    (lambda p: p.norm(dim=1).tolist(), TypeError, "field: expected a tensor"),
    (42, TypeError, "field: expected a callable"),
])
def test_bad_field(field, error, match):
    with pytest.raises(error, match=match):
        sparse_marching_cubes(field, torch.tensor(BOUNDS, dtype=torch.float64), 8)


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(bounds=(0.0, math.nan)), ValueError, "bounds: expected finite"),
    (dict(bounds=(0.0, math.inf)), ValueError, "bounds: expected finite"),
    (dict(bounds=(1.0, 1.0)), ValueError, "bounds: expected finite bounds with lo < hi"),
    (dict(bounds=((0, 0, 0), (1, 1, 0))), ValueError, "bounds: expected finite bounds"),
    (dict(bounds=(0.0, 1.0, 2.0)), ShapeError, "bounds: expected shape"),
    (dict(resolution=1), ValueError, "resolution: expected at least 2"),
    (dict(resolution=(8, 1, 8)), ValueError, "resolution: expected at least 2"),
    (dict(resolution=2.5), TypeError, "resolution"),
    (dict(lipschitz=-1.0), ValueError, "lipschitz"),
    (dict(lipschitz=math.inf), ValueError, "lipschitz"),
    (dict(block=0), ValueError, "block"),
    (dict(band=-1), ValueError, "band"),
    (dict(max_points_per_call=0), ValueError, "max_points_per_call"),
    (dict(ambiguity="nope"), ValueError, "ambiguity"),
    (dict(iso=math.nan), ValueError, "iso"),
])
def test_bad_arguments(kwargs, error, match):
    args = dict(bounds=BOUNDS, resolution=8)
    args.update(kwargs)
    bounds, res = args.pop("bounds"), args.pop("resolution")
    with pytest.raises(error, match=match):
        sparse_marching_cubes(lambda p: p.norm(dim=1) - 0.5, bounds, res, **args)


def test_chunks_respect_max_points_per_call():
    sizes = []

    def field(p):
        sizes.append(p.shape[0])
        return sphere(p, 0.5)

    sparse_marching_cubes(field, BOUNDS, 33, max_points_per_call=777)
    assert max(sizes) <= 777


def test_a_torchgeo_sdf_module_as_field():
    from torchgeo_cg.sdf import Torus

    field = Torus(0.6, 0.25).double()  # module state and bounds share one dtype
    sparse = sparse_marching_cubes(field, torch.tensor(BOUNDS, dtype=torch.float64), 30)
    _assert_equal(sparse, _dense(field, 30))


def test_dense_centre_vertices_are_the_mean_in_float64():
    """MC33 centre vertices (fans around a vertex at the mean of a nine-edge loop) are
    weighted in the working dtype: in float64 the centre is the mean to rounding, in any
    coordinate frame (float32 weights gave mean x (1 + 7e-9))."""
    g = torch.Generator().manual_seed(3)
    vol = torch.randn(12, 12, 12, generator=g, dtype=torch.float64)
    for origin in ((0.0, 0.0, 0.0), (1e3, -2e3, 5e2)):
        mesh = marching_cubes(vol, origin=origin)
        v = vol.numpy()
        crossing = sum(int(((np.take(v, range(n - 1), a) < 0) != (np.take(v, range(1, n), a) < 0))
                           .sum()) for a, n in enumerate(v.shape))
        centres = range(crossing, mesh.verts.shape[0])
        assert len(centres) > 0
        faces = mesh.faces.numpy()
        for c in centres:  # loop over the few centre vertices of the test volume
            ring = np.unique(faces[(faces == c).any(1)])
            ring = ring[ring != c]
            mean = mesh.verts[torch.from_numpy(ring)].mean(0)
            err = (mesh.verts[c] - mean).abs().max() / mean.abs().max()
            assert float(err) <= 8 * torch.finfo(torch.float64).eps
