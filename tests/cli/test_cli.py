"""The torchgeo-cg command: info, gallery and bench, in-process and as an installed script."""

import json
import shutil
import subprocess

import pytest

from torchgeo_cg.cli.main import _build_parser, main


def test_subcommands_are_discovered():
    parser = _build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert {"gallery", "bench", "info"} <= set(sub.choices)


def test_info_prints_versions_devices_threads(capsys):
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    for key in ("torchgeo_cg", "torch", "kornia", "devices", "threads"):
        assert any(line.split()[0] == key for line in out.splitlines() if line.strip()), key
    assert "cpu" in out


@pytest.mark.slow
def test_gallery_writes_figures_and_index(tmp_path):
    assert (
        main(["gallery", "--out", str(tmp_path), "--section", "transforms", "--no-progress"]) == 0
    )
    index = (tmp_path / "index.html").read_text()
    for name in ("transforms_basic.png", "transforms_pre_post.png", "solar_system.gif"):
        path = tmp_path / name
        assert path.stat().st_size > 5000, name
        assert f"src='{name}'" in index
    assert (tmp_path / "transforms_basic.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "solar_system.gif").read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    assert "Articulated motion" in index


@pytest.mark.slow
def test_bench_quick_runs_and_prints_ratios(capsys):
    assert main(["bench", "--quick", "--only", "transforms", "--no-write"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("transform_points")]
    assert len(rows) == 4  # fwd and fwd+bwd at 1 and 2 threads
    # columns: case words..., threads, ours ms, peer ms, ratio, "<=", target, ok/MISSED
    ratios = [float(r.split("<=")[0].split()[-1]) for r in rows]
    assert all(r > 0 for r in ratios)


def test_bench_results_json_is_well_formed():
    from torchgeo_cg.cli.bench import _find_benchmarks

    path = _find_benchmarks() / "results" / "transforms.json"
    data = json.loads(path.read_text())
    assert {"meta", "results"} <= set(data)
    assert {r["threads"] for r in data["results"]} == {1, 2}
    assert data["meta"]["torch"]


@pytest.mark.skipif(shutil.which("torchgeo-cg") is None, reason="console script not installed")
def test_console_script_entry_point():
    done = subprocess.run(["torchgeo-cg", "info", "--brief"], capture_output=True, text=True)
    assert done.returncode == 0
    assert done.stdout.startswith("torchgeo_cg 0.1.0 | torch ")
    bad = subprocess.run(["torchgeo-cg", "nope"], capture_output=True, text=True)
    assert bad.returncode == 2 and "invalid choice" in bad.stderr
