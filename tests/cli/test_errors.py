"""The torchgeo-cg command never shows a traceback: one line on stderr, a non-zero exit."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

import torchgeo_cg
from torchgeo_cg.cli.main import main
from torchgeo_cg.viz import registry

ROOT = Path(__file__).resolve().parents[2]


def _exit_code(argv) -> int:
    """``main(argv)``'s exit code, whether it returns or argparse exits."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def _one_error_line(capsys, command: str) -> str:
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"torchgeo-cg {command}: error: "), lines[0]
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize("steps", ["-1", "0", str(2**70), "ten", "1e3"])
def test_fit_shapes_bad_steps(steps, capsys):
    assert _exit_code(["fit-shapes", "--steps", steps]) == 2
    line = _one_error_line(capsys, "fit-shapes")
    assert "--steps" in line and steps in line


def test_gallery_out_is_a_file(tmp_path, capsys):
    target = tmp_path / "a.png"
    target.write_text("x")
    assert _exit_code(["gallery", "--out", str(target), "--no-progress"]) == 1
    assert "is a file" in _one_error_line(capsys, "gallery")
    assert target.read_text() == "x"


def test_gallery_out_under_a_file(tmp_path, capsys):
    (tmp_path / "a.png").write_text("x")
    assert _exit_code(["gallery", "--out", str(tmp_path / "a.png" / "g"), "--no-progress"]) == 1
    assert "a part of its path is a file" in _one_error_line(capsys, "gallery")


def _unwritable(tmp_path: Path) -> Path:
    """A folder path that cannot be created: under a read-only folder, or in /sys for root."""
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    if not os.access(locked, os.W_OK):
        return locked / "gallery"
    if Path("/sys").is_dir() and not _can_create(Path("/sys/torchgeo_cg_probe")):
        return Path("/sys/torchgeo_cg_gallery")
    pytest.skip("no unwritable folder available (running as root without /sys)")


def _can_create(path: Path) -> bool:
    try:
        path.mkdir()
    except OSError:
        return False
    path.rmdir()
    return True


def test_gallery_out_unwritable(tmp_path, capsys):
    out = _unwritable(tmp_path)
    try:
        assert _exit_code(["gallery", "--out", str(out), "--no-progress"]) == 1
        assert "cannot create the output folder" in _one_error_line(capsys, "gallery")
    finally:
        (tmp_path / "locked").chmod(0o700)


@pytest.mark.parametrize("out", ["", "  "])
def test_gallery_out_empty(out, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert _exit_code(["gallery", "--out", out, "--no-progress"]) == 2
    assert "output folder is empty" in _one_error_line(capsys, "gallery")
    assert list(tmp_path.iterdir()) == []  # nothing written into the current folder


def test_gallery_unknown_section(tmp_path, capsys):
    out = tmp_path / "g"
    assert _exit_code(["gallery", "--out", str(out), "--section", "bogus"]) == 2
    line = _one_error_line(capsys, "gallery")
    assert "unknown gallery section 'bogus'" in line and "curves" in line
    assert not (out / "index.html").exists()


def test_gallery_failing_figure_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(registry, "_REGISTRY", {})
    monkeypatch.setattr("torchgeo_cg.viz.gallery.load_figure_modules", lambda: [])

    @registry.figure("demo", "bad.png", "Bad", "raises")
    def bad(path):
        raise RuntimeError("boom")

    assert _exit_code(["gallery", "--out", str(tmp_path), "--no-progress"]) == 1
    assert "1 figure(s) failed: bad.png: RuntimeError: boom" in _one_error_line(capsys, "gallery")
    assert (tmp_path / "index.html").exists()


def test_bench_unknown_area(capsys):
    assert _exit_code(["bench", "--only", "bogus"]) == 2
    line = _one_error_line(capsys, "bench")
    assert "unknown benchmark area 'bogus'" in line and "transforms" in line


def test_bench_missing_peer_names_the_extra(monkeypatch, capsys):
    from torchgeo_cg.cli.bench import _find_benchmarks, _load_benchmarks

    run = _load_benchmarks(_find_benchmarks())
    monkeypatch.setitem(run.PEERS, "transforms", ("no_such_peer_module",))
    assert _exit_code(["bench", "--only", "transforms", "--no-write"]) == 2
    line = _one_error_line(capsys, "bench")
    assert "'no_such_peer_module'" in line and ".[bench]" in line


def test_bench_outside_a_checkout_never_imports_the_current_folder(tmp_path, monkeypatch, capsys):
    """As from a wheel: the package is not in a checkout; ./benchmarks/run.py is a trap."""
    trap = tmp_path / "benchmarks"
    trap.mkdir()
    (trap / "__init__.py").write_text("")
    (trap / "run.py").write_text(f"open({str(tmp_path / 'ran')!r}, 'w').close()\n")
    fake = tmp_path / "site-packages" / "torchgeo_cg" / "__init__.py"
    monkeypatch.setattr(torchgeo_cg, "__file__", str(fake))
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    assert _exit_code(["bench"]) == 2
    line = _one_error_line(capsys, "bench")
    assert "not part of the installed package" in line and ".[bench]" in line
    assert not (tmp_path / "ran").exists()


def _python(*args, cwd=None):
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-W", "error::RuntimeWarning", *args],
                          capture_output=True, text=True, cwd=cwd, env=env)


@pytest.mark.parametrize("module", ["torchgeo_cg", "torchgeo_cg.cli.main"])
def test_python_dash_m_runs_without_warnings(module, tmp_path):
    done = _python("-m", module, "info", "--brief", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("torchgeo_cg 0.1.0 | torch ")
    assert done.stderr == ""


def test_bad_argument_in_a_real_process_has_no_traceback(tmp_path):
    done = _python("-m", "torchgeo_cg", "fit-shapes", "--steps", str(2**70), cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        "torchgeo-cg fit-shapes: error: argument --steps: must be an integer in "
        f"[1, 1000000], got {2**70}"
    ]


def test_closed_output_pipe_is_quiet(tmp_path):
    """`torchgeo-cg info | head -0`: the reader is gone before we print; no error, no traceback."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    proc = subprocess.Popen([sys.executable, "-m", "torchgeo_cg", "info"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # before the child has imported torch, let alone printed
    err = proc.stderr.read().decode()
    assert proc.wait() == 141
    assert err == ""
