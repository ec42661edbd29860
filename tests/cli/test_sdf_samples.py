"""``torchgeo-cg sdf-samples``: format, ranks (in-process and torchrun), resumption, errors."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from torchgeo_cg.cli.main import main
from torchgeo_cg.mesh import load_mesh, triangulate_faces
from torchgeo_cg.mesh.data import rabbit_path
from torchgeo_cg.sdf.mesh_distance import mesh_sdf

RABBIT = rabbit_path()
MESHES = ["ball.obj", "cyl.obj", "sub/box.ply", "sub/rabbit.obj", "sub/torus.off"]


@pytest.fixture
def mesh_dir(tmp_path) -> Path:
    """5 good meshes (OBJ, PLY, OFF, the quad control mesh) and one bad file."""
    root = tmp_path / "meshes"
    (root / "sub").mkdir(parents=True)
    trimesh.creation.icosphere(subdivisions=1).export(root / "ball.obj")
    trimesh.creation.cylinder(0.5, 1.0, sections=10).export(root / "cyl.obj")
    trimesh.creation.box().export(root / "sub" / "box.ply")
    trimesh.creation.torus(1.0, 0.3, major_sections=12, minor_sections=6).export(
        root / "sub" / "torus.off")
    shutil.copy(RABBIT, root / "sub" / "rabbit.obj")
    (root / "bad.obj").write_text("v 0 0 0\nf 1 2 3\n")
    return root


def _files(out: Path) -> dict[str, bytes]:
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*.npz"))}


def test_format_normalization_and_bad_mesh(mesh_dir, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sdf-samples", str(mesh_dir), str(out), "--points", "600",
                 "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert "skipped bad.obj" in captured.err and "Traceback" not in captured.err
    assert "5 written" in captured.out
    assert sorted(_files(out)) == sorted(f"{m}.npz" for m in MESHES)
    with np.load(out / "sub" / "rabbit.obj.npz") as data:
        assert set(data.files) == {"points", "sdf", "normalization"}
        points, sdf, norm = data["points"], data["sdf"], data["normalization"]
    assert points.shape == (600, 3) and sdf.shape == (600,) and points.dtype == np.float32
    mesh = load_mesh(RABBIT, dtype=torch.float64)
    verts = (mesh.verts + torch.from_numpy(norm[:3])) * norm[3]
    assert abs(float(verts.norm(dim=-1).max()) - 1.0) < 1e-12  # unit sphere
    lo, hi = verts.amin(0), verts.amax(0)
    assert torch.allclose((lo + hi) / 2, torch.zeros(3, dtype=torch.float64), atol=1e-12)
    ref = mesh_sdf(verts, triangulate_faces(mesh.faces), torch.from_numpy(points).double()).sdf
    np.testing.assert_allclose(sdf, ref.numpy(), atol=1e-6)


def test_ranks_union_equals_single_process(mesh_dir, tmp_path, monkeypatch):
    single, split = tmp_path / "single", tmp_path / "split"
    assert main(["sdf-samples", str(mesh_dir), str(single), "--points", "300",
                 "--no-progress"]) == 0
    monkeypatch.setenv("WORLD_SIZE", "2")
    for rank in ("0", "1"):
        monkeypatch.setenv("RANK", rank)
        assert main(["sdf-samples", str(mesh_dir), str(split), "--points", "300",
                     "--no-progress"]) == 0
    assert _files(single) == _files(split)  # bit for bit
    other = tmp_path / "other"
    monkeypatch.setenv("WORLD_SIZE", "1")
    monkeypatch.setenv("RANK", "0")
    assert main(["sdf-samples", str(mesh_dir), str(other), "--points", "300", "--seed", "1",
                 "--no-progress"]) == 0
    assert _files(other)["ball.obj.npz"] != _files(single)["ball.obj.npz"]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    return env


@pytest.mark.slow
def test_torchrun_two_processes_give_identical_files(mesh_dir, tmp_path):
    single, split = tmp_path / "single", tmp_path / "split"
    assert main(["sdf-samples", str(mesh_dir), str(single), "--points", "300",
                 "--no-progress"]) == 0
    bin_dir = Path(sys.executable).parent
    cmd = [str(bin_dir / "torchrun"), "--nproc_per_node", "2", "--no-python",
           str(bin_dir / "torchgeo-cg"), "sdf-samples", str(mesh_dir), str(split),
           "--points", "300", "--no-progress"]
    done = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "rank 0/2" in done.stdout and "rank 1/2" in done.stdout
    assert _files(single) == _files(split)


@pytest.mark.slow
def test_resume_after_a_killed_run_completes_only_the_missing(mesh_dir, tmp_path):
    reference, out = tmp_path / "reference", tmp_path / "out"
    args = ["sdf-samples", str(mesh_dir), "--points", "20000", "--no-progress"]
    assert main([args[0], args[1], str(reference), *args[2:]]) == 0
    cmd = [sys.executable, "-c", "from torchgeo_cg.cli.main import main; main()",
           args[0], args[1], str(out), *args[2:]]
    proc = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not list(out.rglob("*.npz")) and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.kill()
    proc.communicate()
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*.npz")}
    assert 1 <= len(before) < 5, "the run should be killed part-way"
    assert main([args[0], args[1], str(out), *args[2:], "--resume"]) == 0
    assert _files(out) == _files(reference)
    assert all(p.stat().st_mtime_ns == t for p, t in before.items())  # not recomputed
    assert not [p for p in out.rglob("*") if ".tmp-" in p.name]


def test_errors_are_one_line(tmp_path, capsys, monkeypatch):
    assert main(["sdf-samples", str(tmp_path / "missing"), str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "INPUT: no such file or directory" in err and len(err.strip().splitlines()) == 1
    assert main(["sdf-samples", str(tmp_path), str(tmp_path / "o"), "--points", "0"]) == 2
    assert "--points" in capsys.readouterr().err
    monkeypatch.setenv("RANK", "3")
    monkeypatch.setenv("WORLD_SIZE", "2")
    assert main(["sdf-samples", str(tmp_path), str(tmp_path / "o")]) == 2
    assert "RANK=3" in capsys.readouterr().err
