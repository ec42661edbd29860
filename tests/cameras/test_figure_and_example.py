"""The cameras' gallery figure renders, and the example script runs."""

from __future__ import annotations

import runpy
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_cameras_figure_registered_and_renders(tmp_path):
    pytest.importorskip("matplotlib")
    import torchgeo_cg.viz.cameras  # noqa: F401 (registers the figure)
    from torchgeo_cg.viz.registry import registered_figures

    fig = next(f for f in registered_figures() if f.filename == "cameras_undistortion.png")
    assert fig.section == "cameras" and "folds" in fig.caption
    out = tmp_path / fig.filename
    fig.render(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000


def test_example_projects_and_unprojects_the_rabbit(capsys):
    runpy.run_path(str(ROOT / "examples" / "camera_projection.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "round trip" in out
