"""Marching cubes with ``backend="warp"`` (kernels for the cube cases, the welded vertices and
the face lists) against ``backend="torch"``: identical results, every output, bit for bit."""

from __future__ import annotations

import importlib

import pytest
import torch

from torchgeo_cg.engine import warp_status
from torchgeo_cg.mesh import MarchingCubes, marching_cubes, sparse_marching_cubes

HAS_WARP = warp_status()[0] == "ok"
pytestmark = pytest.mark.skipif(not HAS_WARP, reason="Warp is not available here")
DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
_slabs = importlib.import_module("torchgeo_cg.mesh.marching_cubes._slabs")
_steps = importlib.import_module("torchgeo_cg.mesh.marching_cubes._steps")


def _assert_identical(got, want) -> None:
    assert type(got) is type(want)
    for name, a, b in zip(want._fields, got, want):
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert torch.equal(a, b), name


def _both(vol, *args, **kw):
    want = marching_cubes(vol, *args, **kw, backend="torch")
    got = marching_cubes(vol, *args, **kw, backend="warp")
    _assert_identical(got, want)
    return want


def _case_volumes(seed: int, device, dtype=torch.float64) -> torch.Tensor:
    """``(256, 2, 2, 2)``: volume ``c`` has cube case ``c`` (bit ``4 dx + 2 dy + dz`` inside)
    with random magnitudes, so the ambiguous cases take both face and interior decisions."""
    g = torch.Generator().manual_seed(seed)
    case = torch.arange(256)[:, None]
    corner = torch.arange(8)[None]
    inside = ((case >> corner) & 1).bool()  # (256, 8), corner c = 4 dx + 2 dy + dz
    mag = torch.rand(256, 8, generator=g, dtype=torch.float64) + 0.05
    vals = torch.where(inside, -mag, mag)
    return vals.view(256, 2, 2, 2).to(device=device, dtype=dtype)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("ambiguity", ["asymptotic", "separate"])
def test_all_256_cases_with_random_magnitudes(ambiguity, device):
    """Every cube case, with magnitudes drawn so that the asymptotic decider and the
    interior test of Marching Cubes 33 take both answers, alone and inside a 3^3 grid."""
    for seed in range(6):
        vols = _case_volumes(seed, device)
        mesh = _both(vols, ambiguity=ambiguity)
        assert int((mesh.faces_per_mesh > 0).sum()) == 254  # all but cases 0 and 255
        padded = torch.nn.functional.pad(vols, (0, 1, 1, 0, 0, 1), value=1.0)
        _both(padded, ambiguity=ambiguity)


@pytest.mark.parametrize("device", DEVICES)
def test_mc33_tube_cases_are_decided_alike(device):
    """Cases 4 (body diagonal), 6, 7, 10, 12, 13 with interior saddles on both sides of iso:
    the tube rows and the centre vertices (a nine-edge loop's fan) come out alike."""
    g = torch.Generator().manual_seed(3)
    vols = (torch.rand(4096, 2, 2, 2, generator=g, dtype=torch.float64) - 0.5).to(device)
    mesh = _both(vols)
    assert mesh.faces.shape[0] > 0


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape", [(2, 2, 2), (3, 5, 7), (4, 4, 64), (5, 3, 65), (2, 3, 2, 129),
                                   (3, 6, 7, 63), (1, 9, 8, 200)])
def test_random_fields_with_ties_batches_and_word_edges(shape, dtype, device):
    """Fields of -1, 0, 1 (many samples exactly at iso, which is outside), batches with
    one level per volume, sizes across the 64-sample words of the packed classification."""
    g = torch.Generator().manual_seed(sum(shape))
    vol = torch.randint(-1, 2, shape, generator=g).to(dtype=dtype, device=device)
    iso = 0.0 if len(shape) == 3 else torch.linspace(-0.5, 0.5, shape[0], dtype=dtype,
                                                     device=device)
    for ambiguity in ("asymptotic", "separate"):
        _both(vol, iso, ambiguity=ambiguity)


@pytest.mark.parametrize("device", DEVICES)
def test_smooth_batch_with_frames_and_mask(device):
    x = torch.linspace(-1, 1, 21, dtype=torch.float64, device=device)
    X, Y, Z = torch.meshgrid(x, x, x, indexing="ij")
    r = (X**2 + Y**2 + Z**2).sqrt()
    vol = torch.stack([r - 0.5, r - 0.7, (X * 3).sin() + (Y * 3).cos() + Z])
    origin = torch.tensor([[0.0, 0, 0], [1, 2, 3], [-1, 0, 1]], dtype=torch.float64,
                          device=device)
    spacing = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64, device=device)
    _both(vol, 0.0, origin, spacing)
    mask = torch.rand(21, 21, 21, generator=torch.Generator().manual_seed(0)) > 0.3
    _both(vol, 0.0, mask=mask.to(device))
    _both(vol, 0.0, temperature=0.1)


@pytest.mark.parametrize("ambiguity", ["asymptotic", "separate"])
def test_slab_by_slab_path(ambiguity, monkeypatch):
    """The slab scheduler (many active cells) with kernels equals the torch path, and it
    did run in slabs."""
    monkeypatch.setattr(_slabs, "SLAB_ACTIVE", 256)
    g = torch.Generator().manual_seed(1)
    vol = torch.randint(-1, 2, (2, 17, 13, 70), generator=g).to(torch.float32)
    seen = []
    real = _slabs.triangulate
    monkeypatch.setattr(_slabs, "triangulate",
                        lambda *a, **k: seen.append(k["layers"]) or real(*a, **k))
    _both(vol, ambiguity=ambiguity)
    assert len(seen) > 6  # both backends ran in slabs


def test_empty_results_and_no_surface():
    vol = torch.ones(5, 6, 7)
    _both(vol)
    _both(torch.zeros(0, 4, 4, 4))
    _both(-torch.ones(2, 3, 3, 3))


def test_nan_field_raises_on_both_backends():
    vol = torch.zeros(4, 4, 4)
    vol[1, 2, 3] = float("nan")
    for backend in ("torch", "warp"):
        with pytest.raises(ValueError, match="NaN|nan"):
            marching_cubes(vol, backend=backend)


def test_half_volumes():
    """float16 samples are compared as they are (by the same torch comparison): same result."""
    x = torch.linspace(-1, 1, 12)
    X, Y, Z = torch.meshgrid(x, x, x, indexing="ij")
    _both(((X**2 + Y**2 + Z**2).sqrt() - 0.6).half())


@pytest.mark.grad
def test_gradients_are_the_torch_paths():
    """Kernels return integers only: positions, normals and their gradients come from the
    same torch code."""
    x = torch.linspace(-1, 1, 9, dtype=torch.float64)
    X, Y, Z = torch.meshgrid(x, x, x, indexing="ij")
    base = (X**2 + Y**2 + Z**2).sqrt() - 0.6
    grads = []
    for backend in ("torch", "warp"):
        vol = base.clone().requires_grad_(True)
        mesh = marching_cubes(vol, backend=backend)
        (mesh.verts.sum() + mesh.normals[:, 0].sum()).backward()
        grads.append(vol.grad)
    assert torch.equal(grads[0], grads[1]) and grads[0].abs().sum() > 0

    def f(v):
        return marching_cubes(v, backend="warp").verts
    assert torch.autograd.gradcheck(f, (base.clone().requires_grad_(True),))


def test_sparse_extraction_is_identical():
    def field(p):
        return torch.stack([p.norm(dim=1) - 0.5, (p - 0.3).norm(dim=1) - 0.3]).amin(0)
    bounds = torch.tensor((-1.0, 1.0), dtype=torch.float64)
    for ambiguity in ("asymptotic", "separate"):
        kw = dict(block=4, ambiguity=ambiguity)
        want = sparse_marching_cubes(field, bounds, 37, **kw, backend="torch")
        got = sparse_marching_cubes(field, bounds, 37, **kw, backend="warp")
        _assert_identical(got, want)
        assert want.faces.shape[0] > 0


def test_the_kernels_run_and_decide_the_integers(monkeypatch):
    """With backend="warp" the kernel steps produce the cases, vertices and faces; with
    "torch" they are not called."""
    calls = []
    kernels = importlib.import_module("torchgeo_cg.mesh.marching_cubes._kernels")
    for name in ("classify_cells", "weld_edges", "face_lists"):
        real = getattr(kernels, name)
        monkeypatch.setattr(_steps, name,
                            lambda *a, _n=name, _r=real: calls.append(_n) or _r(*a))
    vol = torch.randn(6, 7, 8, generator=torch.Generator().manual_seed(0))
    marching_cubes(vol, backend="torch")
    assert calls == []
    marching_cubes(vol, backend="warp")
    assert calls == ["classify_cells", "weld_edges", "face_lists"]
    assert MarchingCubes(backend="warp")(vol).faces.shape[0] > 0


def test_bad_backend_names_the_argument():
    with pytest.raises(ValueError, match="backend"):
        marching_cubes(torch.zeros(3, 3, 3), backend="fast")
    with pytest.raises(ValueError, match="backend"):
        MarchingCubes(backend="fast")
    with pytest.raises(ValueError, match="backend"):
        sparse_marching_cubes(lambda p: p.norm(dim=1) - 0.5, (-1.0, 1.0), 8, backend="fast")


def test_guide_section_runs():
    """The ```python blocks of docs/guide/marching_cubes_kernels.md run in order, in one
    namespace."""
    import re
    from pathlib import Path

    page = Path(__file__).resolve().parents[2] / "docs" / "guide" / "marching_cubes_kernels.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"), re.S)
    assert len(blocks) == 2
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(page), "exec"), namespace)
    assert namespace["fast"].faces.shape[0] > 0
