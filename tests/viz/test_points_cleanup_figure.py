"""The point-cloud cleanup figure is registered in the points section and renders."""

import pytest

pytest.importorskip("matplotlib")


def test_cleanup_figure_registered_and_renders(tmp_path):
    import torchgeo_cg.viz.points_cleanup  # noqa: F401 (registers the figure)
    from torchgeo_cg.viz.registry import registered_figures

    fig = next(f for f in registered_figures() if f.filename == "points_cleanup.png")
    assert fig.section == "points" and "voxel_downsample" in fig.caption
    out = tmp_path / fig.filename
    fig.render(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
