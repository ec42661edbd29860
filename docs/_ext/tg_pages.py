"""Generated pages besides the API: the gallery, the examples and the layers picture.

- ``gallery.rst``: every figure registered in ``torchgeo_cg/viz`` (``viz/registry.py``),
  ordered by capability (the order of the guides), each caption followed by links to the
  public functions the figure calls (read from its code, so a new figure needs nothing
  here). Images come from ``TORCHGEO_CG_DOCS_FIGURES`` (a folder written by
  ``torchgeo-cg gallery --out DIR``), else from ``gallery/``; the build never renders.
- ``examples.rst``: every ``examples/*.py``, its docstring and source.
- ``layers.svg``: the ``ALLOWED`` table of ``tests/test_layers.py`` drawn as layers,
  every arrow pointing down to what an area may import.
"""

from __future__ import annotations

import ast
import html
import inspect
import os
import shutil
import types
from pathlib import Path

from tg_public import public_names

#: gallery sections in the order of the guides; others follow in registration order.
CAPABILITIES = [
    ("transforms", "Transforms and rotations"),
    ("estimation", "Estimation and registration"),
    ("curves", "Curves"),
    ("splines", "Splines and surfaces"),
    ("sdf", "Signed distance fields and sampling"),
    ("marching_cubes", "Marching cubes"),
    ("subdivision", "Subdivision"),
    ("points", "Point clouds"),
    ("cameras", "Cameras"),
    ("rays", "Rays"),
]


#: the guides in reading order; a guide not listed follows, by name.
GUIDE_ORDER = ["transforms", "estimation", "curves", "surfaces", "sdf", "marching_cubes",
               "marching_cubes_kernels",
               "subdivision", "points", "neighbourhoods", "cameras", "rays"]


def ordered_guides(docs: Path) -> list[Path]:
    """``docs/guide/*.md`` in reading order."""
    found = {p.stem: p for p in (docs / "guide").glob("*.md")}
    order = [n for n in GUIDE_ORDER if n in found] + sorted(n for n in found
                                                            if n not in GUIDE_ORDER)
    return [found[n] for n in order]


def guides_toctree(docs: Path) -> str:
    """The landing page's table of contents of the guides (included by ``index.md``)."""
    lines = ["```{toctree}", ":caption: Guides", ":maxdepth: 1", ""]
    lines += [f"guide/{p.stem}" for p in ordered_guides(docs)]
    return "\n".join(lines + ["```", ""])


def _text(text: str) -> str:
    """Plain text (a caption) as reST: markup characters escaped."""
    for char in "\\*`|_":
        text = text.replace(char, "\\" + char)
    return text


def _heading(text: str, char: str) -> list[str]:
    return [text, char * len(text), ""]


def functions_shown(render) -> list[str]:
    """Public paths of the public objects a figure's code uses (its own function and the
    private helpers of its module it calls), in first-use order."""
    known = {id(e.obj): e.path for e in public_names().values()}
    module = inspect.getmodule(render)
    seen_code, found = set(), []

    def walk(code: types.CodeType) -> None:
        if id(code) in seen_code:
            return
        seen_code.add(id(code))
        for name in code.co_names:
            obj = getattr(module, name, None)
            path = known.get(id(obj))
            if path and not path.startswith(("torchgeo_cg.viz", "torchgeo_cg.core")) \
                    and path not in found:
                found.append(path)
            if isinstance(obj, types.FunctionType) and obj.__module__ == module.__name__ \
                    and name.startswith("_"):
                walk(obj.__code__)
        for const in code.co_consts:
            if isinstance(const, types.CodeType):
                walk(const)

    walk(getattr(render, "__wrapped__", render).__code__)
    return found


def capability(fig) -> str:
    """The capability a figure shows: its section, with the mesh section split by module."""
    if fig.section == "mesh":
        module = fig.render.__module__
        return "marching_cubes" if "marching" in module or "torus" in module else "subdivision"
    return fig.section


def gallery_page(root: Path, generated: Path) -> str:
    from torchgeo_cg.viz import registered_figures
    from torchgeo_cg.viz.gallery import load_figure_modules

    load_figure_modules()
    source = os.environ.get("TORCHGEO_CG_DOCS_FIGURES") or (
        str(root / "gallery") if (root / "gallery").is_dir() else None)
    figures_dir = generated / "figures"
    shutil.rmtree(figures_dir, ignore_errors=True)  # only this build's figures
    lines = _heading("Gallery", "=") + [
        "The figures that ``torchgeo-cg gallery`` renders, by capability, each with the "
        "functions it calls.", ""]
    if not source:
        lines += ["The images are not part of this build: run ``torchgeo-cg gallery --out "
                  "DIR`` and build with ``TORCHGEO_CG_DOCS_FIGURES=DIR`` to embed them.", ""]
    order = [key for key, _ in CAPABILITIES]
    titles = dict(CAPABILITIES)
    groups: dict[str, list] = {}
    for fig in registered_figures():
        groups.setdefault(capability(fig), []).append(fig)
    for key in sorted(groups, key=lambda k: order.index(k) if k in order else len(order)):
        lines += _heading(titles.get(key, key.replace("_", " ").capitalize()), "-")
        for fig in groups[key]:
            lines += _figure(fig, source, figures_dir)
    return "\n".join(lines)


def _figure(fig, source: str | None, figures_dir: Path) -> list[str]:
    lines = _heading(_text(fig.title), "~")
    image = Path(source) / fig.filename if source else None
    if image is not None and image.is_file():
        figures_dir.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(image, figures_dir / fig.filename)
        lines += [f".. image:: figures/{fig.filename}", f"   :alt: {_text(fig.title)}", ""]
    else:
        lines += [f"(``{fig.filename}``)", ""]
    lines += [_text(fig.caption), ""]
    shown = functions_shown(fig.render)
    if shown:
        lines += ["Shows: " + ", ".join(f":py:obj:`~{p}`" for p in shown), ""]
    return lines


def examples_page(root: Path) -> str:
    lines = _heading("Examples", "=") + [
        "Short scripts to copy, in ``examples/``; each runs as ``python examples/NAME.py``.", ""]
    for path in sorted((root / "examples").glob("*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        lines += _heading(f"``{path.name}``", "-")
        lines += [doc.split("\n\n")[0], "", f".. literalinclude:: ../../examples/{path.name}",
                  "   :language: python", ""]
    return "\n".join(lines)


def allowed_layers(test_file: Path) -> dict[str, set[str] | None]:
    """The ``ALLOWED`` table of ``tests/test_layers.py``, read without importing it."""
    tree = ast.parse(test_file.read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.AnnAssign) and getattr(node.target, "id", "") == "ALLOWED":
            table = {}
            for key, value in zip(node.value.keys, node.value.values):
                if isinstance(value, ast.Constant):
                    table[key.value] = None
                elif isinstance(value, ast.Set):
                    table[key.value] = {e.value for e in value.elts}
                else:  # set()
                    table[key.value] = set()
            return table
    raise ValueError(f"{test_file}: no ALLOWED table")


def layers_svg(allowed: dict[str, set[str] | None]) -> str:
    """The layers as an SVG picture: one row per level, arrows to the areas used."""
    areas = {a: deps for a, deps in allowed.items() if a}
    level: dict[str, int] = {}

    def depth(area: str) -> int:
        if area not in level:
            deps = areas[area]
            level[area] = (max((depth(d) for d in areas if areas[d] is not None),
                               default=0) + 1 if deps is None else
                           max((depth(d) + 1 for d in deps if d in areas), default=0))
        return level[area]

    for area in areas:
        depth(area)
    rows = max(level.values()) + 1
    box_w, box_h, gap_x, gap_y = 120, 34, 28, 70
    by_row = [sorted(a for a in areas if level[a] == r) for r in range(rows)]
    width = max(len(r) for r in by_row) * (box_w + gap_x) + gap_x
    height = rows * box_h + (rows - 1) * gap_y + 20
    pos = {}
    for r, names in enumerate(by_row):
        y = height - 10 - box_h - r * (box_h + gap_y)
        x0 = (width - len(names) * (box_w + gap_x) + gap_x) / 2
        for i, name in enumerate(names):
            pos[name] = (x0 + i * (box_w + gap_x), y)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" '
           f'width="{width}" height="{height}" font-family="sans-serif" font-size="14">',
           '<defs><marker id="a" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="7" '
           'markerHeight="7" orient="auto"><path d="M0,0L10,5L0,10z" fill="#555"/></marker>'
           '</defs>']
    for area, deps in sorted(areas.items()):
        targets = [d for d in areas if d != area] if deps is None else sorted(deps)
        targets = [d for d in targets if d in pos and (deps is not None or level[d] ==
                                                       level[area] - 1)]
        x, y = pos[area]
        for dep in targets:
            dx, dy = pos[dep]
            out.append(f'<line x1="{x + box_w / 2:.0f}" y1="{y + box_h}" x2="{dx + box_w / 2:.0f}"'
                       f' y2="{dy}" stroke="#777" stroke-width="1.3" marker-end="url(#a)"/>')
    for area, (x, y) in pos.items():
        note = " (anything)" if areas[area] is None else ""
        out.append(f'<rect x="{x}" y="{y}" width="{box_w}" height="{box_h}" rx="6" '
                   f'fill="#e8f0fb" stroke="#3b6fb6"/><text x="{x + box_w / 2}" '
                   f'y="{y + 22}" text-anchor="middle">{html.escape(area + note)}</text>')
    out.append("</svg>")
    return "\n".join(out)
