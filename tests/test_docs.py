"""The documentation site (``docs/``) builds nitpicky and warning-free (``-n -W``); every
public name of ``tests/api_inventory.py`` is documented once, at its public path (the
shortest public module exporting it), and nowhere else; the landing page, the guides,
the conventions, the gallery (every registered figure, linked to the functions it shows),
the examples and the maintainer's map are there."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

from tests.api_inventory import INVENTORY

ROOT = Path(__file__).resolve().parent.parent
pytest.importorskip("sphinx")
pytest.importorskip("myst_parser")
pytest.importorskip("furo")
pytest.importorskip("matplotlib")
sys.path.insert(0, str(ROOT / "docs" / "_ext"))

from tg_public import public_names  # noqa: E402


def inventory_entries(objects_inv: Path) -> dict[str, str]:
    """``name -> role`` of the ``py`` entries of a Sphinx ``objects.inv`` (version 2)."""
    raw = objects_inv.read_bytes()
    header_end = 0
    for _ in range(4):  # four header lines, then zlib-compressed entries
        header_end = raw.index(b"\n", header_end) + 1
    assert raw.startswith(b"# Sphinx inventory version 2"), raw[:40]
    body = zlib.decompress(raw[header_end:]).decode("utf-8")
    entries = {}
    for line in body.splitlines():
        match = re.match(r"(.+?)\s+(py:\w+)\s+-?\d+\s", line)
        if match:
            entries[match.group(1)] = match.group(2)
    return entries


def expected_paths() -> tuple[set[str], set[str]]:
    """The public path of every public object, and every public module a page declares
    (a module whose name a function shadows, ``torchgeo_cg.curves.nurbs``, is not)."""
    objects = {e.path for e in public_names().values()}
    modules = {m for m in INVENTORY if m not in objects}
    return objects, modules


def reference_problems(entries: dict[str, str]) -> list[str]:
    """What the reference gets wrong: a public name missing at its public path, a public
    module missing, or one of our entries at any other path (a private one, a deeper
    re-export, a second copy). Members of documented classes are theirs."""
    objects, modules = expected_paths()
    problems = [f"missing: {p}" for p in sorted(objects) if p not in entries]
    problems += [f"missing module: {m}" for m in sorted(modules)
                 if entries.get(m) != "py:module"]
    classes = {p for p in objects if entries.get(p) in ("py:class", "py:exception")}
    for name, role in sorted(entries.items()):
        if not name.startswith("torchgeo_cg"):
            continue
        if any(part.startswith("_") and not part.startswith("__")
               for part in name.split(".")):
            problems.append(f"private path: {name}")
        elif name in objects or (name in modules and role == "py:module"):
            continue
        elif name.rsplit(".", 1)[0] not in classes:
            problems.append(f"not a public path: {name}")
    return problems


def test_reference_check_can_fail():
    """The check names a missing name, a private path and a deeper re-export."""
    objects, modules = expected_paths()
    good = {p: "py:function" for p in objects} | {m: "py:module" for m in modules}
    good["torchgeo_cg.core.ShapeError"] = "py:exception"  # an alias of torchgeo_cg.ShapeError
    assert reference_problems({k: v for k, v in good.items() if k in objects | modules}) == []
    bad = dict(good)
    del bad["torchgeo_cg.mesh.marching_cubes"]
    bad["torchgeo_cg.mesh.marching_cubes.dense.marching_cubes"] = "py:function"
    bad["torchgeo_cg.mesh.io._text.MeshFileWarning"] = "py:class"
    problems = reference_problems(bad)
    assert "missing: torchgeo_cg.mesh.marching_cubes" in problems
    assert "not a public path: torchgeo_cg.mesh.marching_cubes.dense.marching_cubes" in problems
    assert "private path: torchgeo_cg.mesh.io._text.MeshFileWarning" in problems
    assert "not a public path: torchgeo_cg.core.ShapeError" in problems


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site built with ``sphinx-build -n -W`` (one cheap figure rendered for it; no
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
        [sys.executable, "-m", "sphinx", "-b", "html", "-n", "-W", "--keep-going", "-E", "-q",
         str(ROOT / "docs"), str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"sphinx-build -n -W failed:\n{done.stdout}\n{done.stderr}"
    return out


def _page(site: Path, name: str) -> str:
    return (site / name).read_text(encoding="utf-8")


@pytest.mark.slow
def test_every_public_name_once_at_its_public_path(site):
    entries = inventory_entries(site / "objects.inv")
    assert len(entries) >= len(public_names())
    assert reference_problems(entries) == []


@pytest.mark.slow
def test_one_page_per_subpackage_with_a_summary_and_topics(site):
    from tests.api_inventory import subpackages

    for subpackage in subpackages():
        page = site / "_generated" / "api" / f"{subpackage.split('.')[-1]}.html"
        assert page.is_file(), page
        assert subpackage in page.read_text(encoding="utf-8")
    mesh = _page(site, "_generated/api/mesh.html")
    assert "tg-summary" in mesh
    assert 'id="torchgeo_cg.mesh.marching_cubes"' in mesh  # at the public path
    assert 'id="torchgeo_cg.mesh.marching_cubes.dense.marching_cubes"' not in mesh
    assert re.search(r'class="[^"]*tg-convention[^"]*admonition', mesh)  # titled notes


@pytest.mark.slow
def test_references_reach_python_torch_numpy_and_scipy(site):
    pages = "".join(p.read_text(encoding="utf-8") for p in (site / "_generated").rglob("*.html"))
    assert "https://docs.pytorch.org/docs/stable/tensors.html#torch.Tensor" in pages
    assert "https://docs.python.org/3/library/pathlib.html#pathlib.Path" in pages
    assert "https://numpy.org/doc/stable/reference/generated/numpy.ndarray.html" in pages


@pytest.mark.slow
def test_landing_page_and_guides(site):
    index = _page(site, "index.html")
    text = re.sub(r"<[^>]+>", "", index)  # highlighted code, as read
    assert "pip install torch==2.13.0" in text and "marching_cubes(volume)" in text
    assert len(re.findall(r'<img[^>]+_static/gallery/', index)) >= 4
    for path in sorted((ROOT / "docs" / "guide").glob("*.md")):
        assert (site / "guide" / f"{path.stem}.html").is_file(), path.name
        assert f'href="guide/{path.stem}.html"' in index, path.name


@pytest.mark.slow
def test_conventions_page_has_every_global_rule(site):
    page = _page(site, "conventions.html")
    for section in ("Frames", "Batching", "dtype and device", "Errors", "Scale", "Randomness"):
        assert f">{section}<" in page, section


@pytest.mark.slow
def test_gallery_page_shows_every_figure_and_its_functions(site):
    from torchgeo_cg.viz import registered_figures

    page = _page(site, "_generated/gallery.html")
    for fig in registered_figures():
        assert fig.filename in page, fig.filename
    assert re.search(r'<img[^>]+curves_cycloid\.png', page)
    assert list(site.rglob("curves_cycloid.png"))
    assert 'href="api/mesh.html#torchgeo_cg.mesh.marching_cubes"' in page


@pytest.mark.slow
def test_examples_page_shows_every_example(site):
    page = _page(site, "_generated/examples.html")
    for path in sorted((ROOT / "examples").glob("*.py")):
        assert path.name in page
        first_code_line = next(line for line in path.read_text().splitlines()
                               if line.startswith(("import", "from")))
        assert first_code_line.split()[1] in page, path.name


@pytest.mark.slow
def test_maintainers_map_draws_every_layer(site):
    from tests.test_layers import ALLOWED

    page = _page(site, "developing.html")
    assert "layers.svg" in page
    svg = next(site.rglob("layers.svg")).read_text(encoding="utf-8")
    for area in ALLOWED:
        if area:
            assert f">{area}" in svg, area


def test_gallery_links_the_functions_a_figure_calls():
    from tg_pages import functions_shown

    from torchgeo_cg.viz import registered_figures
    from torchgeo_cg.viz.gallery import load_figure_modules

    load_figure_modules()
    torus = next(f for f in registered_figures() if f.filename == "marching_cubes_torus.png")
    shown = functions_shown(torus.render)
    assert "torchgeo_cg.mesh.marching_cubes" in shown
    assert not any(p.startswith("torchgeo_cg.viz") or "._" in p for p in shown)
