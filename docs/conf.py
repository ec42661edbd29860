"""Sphinx configuration of the torchgeo_cg API reference.

Why Sphinx (and not mkdocs + mkdocstrings): the docstrings are Google style with RST
inside (``code``, ``:func:`` roles, doctest blocks), which autodoc + napoleon read as
they are, and ``-W`` turns every docstring defect into a build error that the test
suite sees. Sphinx needs no JavaScript toolchain, and myst-parser lets the README's
Markdown be included as it is (one source for the conventions).

The pages are generated at build time (``builder-inited``) into ``_generated/``:

- ``api/<subpackage>.rst``: one page per subpackage of ``tests/api_inventory.py``, the
  single source of the public surface, so a new subpackage or name appears without
  editing anything here;
- ``gallery.rst``: every figure registered in ``torchgeo_cg/viz`` (title, caption and
  image). Images are taken from ``TORCHGEO_CG_DOCS_FIGURES`` (a folder written by
  ``torchgeo-cg gallery --out DIR``), else from ``gallery/`` (what the README's gallery
  command writes). Rendering every figure takes minutes, so the build never renders:
  without images the page lists the figures and says how to render them;
- ``examples.rst``: every ``examples/*.py``, with its docstring and source.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import os
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

from tests.api_inventory import INVENTORY, PACKAGE, modules_of, subpackages  # noqa: E402

project = "torchgeo_cg"
author = "torchgeo_cg contributors"
copyright = "torchgeo_cg contributors, MIT licence"
release = importlib.import_module(PACKAGE).__version__

extensions = ["sphinx.ext.autodoc", "sphinx.ext.napoleon", "myst_parser"]
# highlighted source pages, half of the build's time: the test suite's build
# (TORCHGEO_CG_DOCS_SOURCE=0) checks the docstrings and the names without them
if os.environ.get("TORCHGEO_CG_DOCS_SOURCE", "1") != "0":
    extensions.append("sphinx.ext.viewcode")
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "README.md"]
html_theme = "alabaster"
html_static_path: list[str] = []
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True  # NamedTuple fields are documented once, by autodoc
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_default_options = {"members": True, "show-inheritance": True}
myst_heading_anchors = 3
suppress_warnings = ["myst.xref_missing"]  # README links to files of the repository

GENERATED = HERE / "_generated"


def _kind(obj: object) -> str:
    if inspect.isclass(obj):
        return "autoexception" if issubclass(obj, BaseException) else "autoclass"
    if inspect.isfunction(obj) or inspect.isbuiltin(obj):
        return "autofunction"
    return "autodata"


def _text(text: str) -> str:
    """Plain text (a figure's caption) as reST: markup characters escaped."""
    for char in "\\*`|_":
        text = text.replace(char, "\\" + char)
    return text


def _heading(text: str, char: str) -> list[str]:
    return [text, char * len(text), ""]


def _defining_module(module: str, name: str) -> str:
    """The public module under which ``module.name`` is documented: the deepest module
    inside ``module`` that lists the same object, else ``module`` itself."""
    obj = getattr(importlib.import_module(module), name)
    inner = sorted((m for m in INVENTORY if m.startswith(module + ".")),
                   key=lambda m: -m.count("."))
    for other in inner:
        if name in INVENTORY[other] and getattr(importlib.import_module(other), name) is obj:
            return other
    return module


def _document(module: str, name: str) -> list[str]:
    obj = getattr(importlib.import_module(module), name)
    if inspect.ismodule(obj):
        return [f"- :mod:`{obj.__name__}`", ""]
    kind = _kind(obj)
    lines = [f".. {kind}:: {module}.{name}"]
    if kind == "autodata":
        lines.append("   :no-value:" if len(repr(obj)) > 60 else "   :annotation:")
    return lines + [""]


def api_page(subpackage: str) -> str:
    """The reST of one subpackage's page: its docstring, the names importable from it, then
    each public module with the objects of its ``__all__``."""
    lines = _heading(f"``{subpackage}``", "=") + [
        f".. automodule:: {subpackage}", "   :no-members:", ""]
    if INVENTORY[subpackage]:
        lines += [f"Importable as ``from {subpackage} import ...``:", ""]
        for name in INVENTORY[subpackage]:
            where = _defining_module(subpackage, name)
            lines.append(f"- :py:obj:`{name} <{where}.{name}>`")
        lines.append("")
    for module in modules_of(subpackage):
        if module != subpackage:
            lines += _heading(f"``{module}``", "-") + [
                f".. automodule:: {module}", "   :no-members:", ""]
        for name in INVENTORY[module]:
            where = _defining_module(module, name)
            if where == module:
                lines += _document(module, name)
            elif module != subpackage:
                lines += [f"- :py:obj:`{name} <{where}.{name}>` (from ``{where}``)", ""]
    return "\n".join(lines)


def api_index() -> str:
    top = importlib.import_module(PACKAGE)
    lines = _heading("API reference", "=") + [
        f"Every public name of ``{PACKAGE}``, one page per subpackage; the list is "
        "``tests/api_inventory.py``.", "",
        f".. automodule:: {PACKAGE}", "   :no-members:", ""]
    for name in INVENTORY[PACKAGE]:
        if not inspect.ismodule(getattr(top, name)):
            where = _defining_module("torchgeo_cg.core", name) if name in INVENTORY.get(
                "torchgeo_cg.core", ()) else PACKAGE
            lines.append(f"- ``{PACKAGE}.{name}``" + (
                f": :py:obj:`{where}.{name}`" if where != PACKAGE else ""))
    lines += ["", ".. toctree::", "   :maxdepth: 1", ""]
    lines += [f"   {s.split('.')[-1]}" for s in subpackages()]
    lines += ["", ".. autodata:: torchgeo_cg.__version__", ""]
    return "\n".join(lines)


def gallery_page() -> str:
    from torchgeo_cg.viz import registered_figures
    from torchgeo_cg.viz.gallery import load_figure_modules

    load_figure_modules()
    source = os.environ.get("TORCHGEO_CG_DOCS_FIGURES") or (
        str(ROOT / "gallery") if (ROOT / "gallery").is_dir() else None)
    figures_dir = GENERATED / "figures"
    shutil.rmtree(figures_dir, ignore_errors=True)  # only this build's figures
    lines = _heading("Gallery", "=") + [
        "The figures that ``torchgeo-cg gallery`` renders, by section, with the captions "
        "registered beside them in ``torchgeo_cg/viz``.", ""]
    if not source:
        lines += ["The images are not part of this build: run ``torchgeo-cg gallery --out "
                  "DIR`` and build with ``TORCHGEO_CG_DOCS_FIGURES=DIR`` to embed them.", ""]
    sections: dict[str, list] = {}
    for fig in registered_figures():
        sections.setdefault(fig.section, []).append(fig)
    for section, figs in sections.items():
        lines += _heading(section.replace("_", " ").capitalize(), "-")
        for fig in figs:
            lines += [f"**{_text(fig.title)}**", "", _text(fig.caption), ""]
            image = Path(source) / fig.filename if source else None
            if image is not None and image.is_file():
                figures_dir.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(image, figures_dir / fig.filename)
                lines += [f".. image:: figures/{fig.filename}", f"   :alt: {_text(fig.title)}", ""]
            else:
                lines += [f"(``{fig.filename}``)", ""]
    return "\n".join(lines)


def examples_page() -> str:
    lines = _heading("Examples", "=") + [
        "Short scripts to copy, in ``examples/``; each runs as ``python examples/NAME.py``.", ""]
    for path in sorted((ROOT / "examples").glob("*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        lines += _heading(f"``{path.name}``", "-")
        lines += [doc.split("\n\n")[0], "", f".. literalinclude:: ../../examples/{path.name}",
                  "   :language: python", ""]
    return "\n".join(lines)


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text(encoding="utf-8") != text:  # keep mtimes
        path.write_text(text, encoding="utf-8")


def generate(app=None) -> None:
    """Write every generated page (called by Sphinx when the build starts)."""
    for subpackage in subpackages():
        _write(GENERATED / "api" / f"{subpackage.split('.')[-1]}.rst", api_page(subpackage))
    _write(GENERATED / "api" / "index.rst", api_index())
    _write(GENERATED / "gallery.rst", gallery_page())
    _write(GENERATED / "examples.rst", examples_page())


def setup(app):
    app.connect("builder-inited", generate)
    return {"parallel_read_safe": True}
