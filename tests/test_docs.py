"""The API reference (``docs/``) builds warning-free with ``-W`` and documents every name of
``tests/api_inventory.py``; its conventions page is the README's, its gallery page shows
every registered figure (with the image when one is rendered) and its examples page every
script of ``examples/``."""

from __future__ import annotations

import importlib
import inspect
import os
import re
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

from tests.api_inventory import public_names

ROOT = Path(__file__).resolve().parent.parent
pytest.importorskip("sphinx")
pytest.importorskip("myst_parser")
pytest.importorskip("matplotlib")


def documented_objects(objects_inv: Path) -> set[str]:
    """The ``py`` names in a Sphinx ``objects.inv`` (format version 2)."""
    raw = objects_inv.read_bytes()
    header_end = 0
    for _ in range(4):  # four header lines, then zlib-compressed entries
        header_end = raw.index(b"\n", header_end) + 1
    assert raw.startswith(b"# Sphinx inventory version 2"), raw[:40]
    body = zlib.decompress(raw[header_end:]).decode("utf-8")
    names = set()
    for line in body.splitlines():
        match = re.match(r"(.+?)\s+(py:\w+)\s+-?\d+\s", line)
        if match:
            names.add(match.group(1))
    return names


def missing_from_reference(names: list[tuple[str, str]], documented: set[str]) -> list[str]:
    """``module.name`` of every public name that the reference does not document, under its
    own module or under another public module holding the same object."""
    by_leaf: dict[str, list[str]] = {}
    for full in documented:
        by_leaf.setdefault(full.rsplit(".", 1)[-1], []).append(full)
    missing = []
    for module, name in names:
        obj = getattr(importlib.import_module(module), name)
        if inspect.ismodule(obj):
            if obj.__name__ not in documented:
                missing.append(f"{module}.{name}")
            continue
        if f"{module}.{name}" in documented:
            continue
        homes = [full.rsplit(".", 1)[0] for full in by_leaf.get(name, [])]
        if not any(_same(home, name, obj) for home in homes):
            missing.append(f"{module}.{name}")
    return missing


def _same(module: str, name: str, obj: object) -> bool:
    try:
        return getattr(importlib.import_module(module), name) is obj
    except ImportError:  # a class's member: "module.Class.name"
        return False


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The reference built with ``sphinx-build -W`` (one cheap figure rendered for it; no
    highlighted source pages, which add nothing to check and double the time)."""
    from torchgeo_cg.viz import registered_figures
    from torchgeo_cg.viz.gallery import load_figure_modules

    load_figure_modules()
    figures = tmp_path_factory.mktemp("figures")
    cheap = next(f for f in registered_figures() if f.filename == "curves_cycloid.png")
    cheap.render(figures / cheap.filename)
    out = tmp_path_factory.mktemp("html")
    env = dict(os.environ, TORCHGEO_CG_DOCS_FIGURES=str(figures), TORCHGEO_CG_DOCS_SOURCE="0",
               MPLBACKEND="Agg")
    done = subprocess.run(
        [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-E", "-q",
         str(ROOT / "docs"), str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"sphinx-build -W failed:\n{done.stdout}\n{done.stderr}"
    return out


@pytest.mark.slow
def test_every_public_name_is_in_the_reference(site):
    documented = documented_objects(site / "objects.inv")
    assert len(documented) > 100
    assert missing_from_reference(public_names(), documented) == []


def test_missing_name_check_can_fail():
    """The check names what the reference lacks (here a real name, with nothing built)."""
    names = [("torchgeo_cg.core", "safe_div"), ("torchgeo_cg", "core")]
    assert missing_from_reference(names, {"torchgeo_cg.core.numerics.safe_div"}) == [
        "torchgeo_cg.core"]
    assert missing_from_reference(names, {"torchgeo_cg.core"}) == ["torchgeo_cg.core.safe_div"]


@pytest.mark.slow
def test_one_page_per_subpackage(site):
    from tests.api_inventory import subpackages

    for subpackage in subpackages():
        page = site / "_generated" / "api" / f"{subpackage.split('.')[-1]}.html"
        assert page.is_file(), page
        assert subpackage in page.read_text(encoding="utf-8")


@pytest.mark.slow
def test_conventions_page_is_the_readme_section(site):
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    section = readme.split("<!-- conventions:start -->")[1].split("<!-- conventions:end -->")[0]
    page = (site / "conventions.html").read_text(encoding="utf-8")
    # every bold lead of the README's bullets is on the page
    leads = re.findall(r"^- \*\*(.+?)\*\*", section, flags=re.M)
    assert len(leads) >= 5
    for lead in leads:
        assert re.sub(r"`", "", lead).split()[0] in page, lead


@pytest.mark.slow
def test_gallery_page_shows_every_figure_and_the_rendered_image(site):
    from torchgeo_cg.viz import registered_figures

    page = (site / "_generated" / "gallery.html").read_text(encoding="utf-8")
    for fig in registered_figures():
        assert fig.filename in page, fig.filename
    assert re.search(r'<img[^>]+curves_cycloid\.png', page)
    assert list(site.rglob("curves_cycloid.png"))


@pytest.mark.slow
def test_examples_page_shows_every_example(site):
    page = (site / "_generated" / "examples.html").read_text(encoding="utf-8")
    for path in sorted((ROOT / "examples").glob("*.py")):
        assert path.name in page
        first_code_line = next(line for line in path.read_text().splitlines()
                               if line.startswith(("import", "from")))
        assert first_code_line.split()[1] in page, path.name
