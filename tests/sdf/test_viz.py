"""The sdf gallery figures are registered, and the cheap one renders."""

from __future__ import annotations

import pytest

pytest.importorskip("matplotlib")


def test_sdf_figures_registered_and_slice_renders(tmp_path):
    import torchgeo_cg.viz.sdf as viz_sdf
    from torchgeo_cg.viz.registry import registered_figures

    names = {f.filename: f for f in registered_figures() if f.section == "sdf"}
    assert {"sdf_zero_level_set_torus.png", "sdf_level_set_tolerance.png", "sdf_slice.png",
            "sdf_sampler.png"} <= set(names)
    out = tmp_path / "sdf_slice.png"
    viz_sdf._slice(out)
    assert out.stat().st_size > 10_000
