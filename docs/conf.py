"""Sphinx configuration of the torchgeo_cg documentation.

Why Sphinx (and not mkdocs + mkdocstrings): the docstrings are Google style with reST
inside (``code``, ``:func:`` roles, doctest blocks), which autodoc + napoleon read as they
are, and ``-n -W`` turns every docstring defect and broken reference into a build error
that the test suite sees. The guides are Markdown (myst-parser).

Theme: furo, for a readable body width, the page's contents on the right, code blocks
that scroll instead of being cut, light and dark modes, and no JavaScript framework.

Generated at build time into ``_generated/`` (see ``_ext/``), from the sources of truth,
so a new subpackage, name, figure, guide or example needs no edit here:

- ``api/<subpackage>.rst``: from ``tests/api_inventory.py`` (``tg_apipages``), every
  object once at its public path, grouped by topic under a summary table;
- ``inv/*.inv``: intersphinx inventories of Python, torch, numpy and scipy, written
  from the installed packages because the build is offline (``tg_inventories``);
- ``gallery.rst``, ``examples.rst``, ``layers.svg`` and the guides' table of contents,
  every ``guide/*.md`` in reading order (``tg_pages``).
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT), str(HERE / "_ext")]

import tg_apipages  # noqa: E402
import tg_inventories  # noqa: E402
import tg_pages  # noqa: E402

from tests.api_inventory import PACKAGE, subpackages  # noqa: E402

project = "torchgeo_cg"
author = "torchgeo_cg contributors"
copyright = "torchgeo_cg contributors, MIT licence"
release = importlib.import_module(PACKAGE).__version__

extensions = ["sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinx.ext.intersphinx",
              "sphinx.ext.mathjax", "myst_parser", "tg_convention", "tg_xref"]
# highlighted source pages, half of the build's time: the test suite's build
# (TORCHGEO_CG_DOCS_SOURCE=0) checks the docstrings and the names without them
if os.environ.get("TORCHGEO_CG_DOCS_SOURCE", "1") != "0":
    extensions.append("sphinx.ext.viewcode")
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "_ext", "_generated/guides_toctree.md"]
nitpicky = True

html_theme = "furo"
html_title = f"torchgeo_cg {release}"
html_static_path = ["_static"]
html_css_files = ["custom.css"]
html_theme_options = {"sidebar_hide_name": False, "navigation_with_keys": True}
pygments_style = "friendly"

napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True  # NamedTuple fields are documented once, by autodoc
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_inherit_docstrings = False  # not torch's text for every forward()
autodoc_default_options = {"members": True, "show-inheritance": True}
python_maximum_signature_line_length = 88  # long signatures: one parameter a line
add_module_names = False
toc_object_entries = False  # the page's contents: its topics (the summary lists names)
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]
suppress_warnings = ["myst.xref_missing"]  # the guides link files of the repository

GENERATED = HERE / "_generated"
intersphinx_mapping = tg_inventories.write_all(GENERATED / "inv")


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text(encoding="utf-8") != text:  # keep mtimes
        path.write_text(text, encoding="utf-8")


def generate(app=None) -> None:
    """Write every generated page (called by Sphinx when the build starts)."""
    for subpackage in subpackages():
        _write(GENERATED / "api" / f"{subpackage.split('.')[-1]}.rst",
               tg_apipages.api_page(subpackage))
    _write(GENERATED / "api" / "index.rst", tg_apipages.api_index())
    _write(GENERATED / "gallery.rst", tg_pages.gallery_page(ROOT, GENERATED))
    _write(GENERATED / "examples.rst", tg_pages.examples_page(ROOT))
    _write(GENERATED / "guides_toctree.md", tg_pages.guides_toctree(HERE))
    _write(GENERATED / "layers.svg",
           tg_pages.layers_svg(tg_pages.allowed_layers(ROOT / "tests" / "test_layers.py")))


def _drop_aliases(app, env) -> None:
    """autodoc records a class also under its defining path (``:canonical:``): a second
    path for one object, often a private one, so it is dropped from ``objects.inv``
    (references to it are resolved by object, ``tg_xref``)."""
    objects = env.get_domain("py").objects
    for name in [n for n, o in objects.items() if o.aliased and n.startswith(PACKAGE)]:
        del objects[name]


def _skip_namedtuple_fields(app, what, name, obj, skip, options):
    """A NamedTuple's fields are documented by its ``Attributes:`` section; autodoc would
    add each again as "Alias for field number N"."""
    doc = getattr(obj, "__doc__", None) or ""
    return True if doc.startswith("Alias for field number") else None


def setup(app):
    app.connect("builder-inited", generate)
    app.connect("autodoc-skip-member", _skip_namedtuple_fields)
    app.connect("env-updated", _drop_aliases)
    return {"parallel_read_safe": True}
