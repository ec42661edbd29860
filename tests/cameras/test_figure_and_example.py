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


def test_example_renders_the_rabbit_and_lifts_the_depth_back(capsys, tmp_path):
    example = runpy.run_path(str(ROOT / "examples" / "camera_projection.py"), run_name="example")
    out_png = tmp_path / "depth.png"
    result = example["main"](["--out", str(out_png)] if _has_matplotlib() else [])
    # the rabbit fills part of the 160 x 120 image; the depth lifts back onto the surface
    assert 1000 < result["hits"] < 120 * 160
    assert result["lift_error"] < 1e-12 and result["reproject_px"] < 1e-9
    assert "pixels hit" in capsys.readouterr().out
    if _has_matplotlib():
        assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _has_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True
