"""The slerp gallery figure is registered in the transforms section and renders."""

import pytest

pytest.importorskip("matplotlib")


def test_slerp_figure_registered_and_renders(tmp_path):
    import torchgeo_cg.viz.rotations  # noqa: F401 (registers the figure)
    from torchgeo_cg.viz.registry import registered_figures

    fig = next(f for f in registered_figures() if f.filename == "rotations_slerp_frames.png")
    assert fig.section == "transforms" and "slerp" in fig.caption
    out = tmp_path / fig.filename
    fig.render(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
