"""The gallery registry and builder: duplicate names, failing figures, section filter."""

import pytest

from torchgeo_cg.viz import registry
from torchgeo_cg.viz.gallery import build_gallery


@pytest.fixture
def clean_registry(monkeypatch):
    monkeypatch.setattr(registry, "_REGISTRY", {})
    monkeypatch.setattr("torchgeo_cg.viz.gallery.load_figure_modules", lambda: [])
    return registry


def test_duplicate_filename_rejected(clean_registry):
    def first(path):
        pass

    def second(path):
        pass

    clean_registry.figure("a", "x.png", "X", "first")(first)
    clean_registry.figure("a", "x.png", "X", "first")(first)  # re-registering itself is fine
    with pytest.raises(ValueError, match="'x.png' is already registered"):
        clean_registry.figure("b", "x.png", "Y", "second")(second)


def test_failing_figure_is_reported_in_index_and_raised(clean_registry, tmp_path):
    @clean_registry.figure("ok", "good.txt", "Good", "writes a file")
    def good(path):
        path.write_text("hi")

    @clean_registry.figure("bad", "bad.png", "Bad", "raises")
    def bad(path):
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="1 figure\\(s\\) failed: bad.png: RuntimeError: boom"):
        build_gallery(tmp_path, progress=False)
    index = (tmp_path / "index.html").read_text()
    assert "good.txt" in index and "Figures that failed" in index and "boom" in index
    paths = build_gallery(tmp_path / "only", sections=["ok"], progress=False)
    assert [p.name for p in paths] == ["good.txt", "index.html"]
