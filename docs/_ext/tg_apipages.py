"""The API reference pages, generated from ``tests/api_inventory.py`` at build time.

One page per subpackage: its docstring, a summary table (each name with the first line
of its docstring), then one section per topic (the public module defining the names),
each object in source order and documented once, at its public path
(:mod:`tg_public`). Public modules that define nothing listed are named at the end.
"""

from __future__ import annotations

import importlib
import inspect
import re
from functools import cache
from pathlib import Path

from sphinx.pycode import ModuleAnalyzer
from tg_pages import ordered_guides
from tg_public import PublicName, public_names, subpackage_of

from tests.api_inventory import INVENTORY, PACKAGE, subpackages


def heading(text: str, char: str) -> list[str]:
    return [text, char * len(text), ""]


def _kind(obj: object) -> str:
    if inspect.isclass(obj):
        return "autoexception" if issubclass(obj, BaseException) else "autoclass"
    if inspect.isfunction(obj) or inspect.isbuiltin(obj) or callable(obj):
        return "autofunction"
    return "autodata"


def first_line(entry: PublicName) -> str:
    """The summary of an object: its docstring's first paragraph (data: its ``#:``
    comment, else its value when short)."""
    if _kind(entry.obj) == "autodata":
        docs = ModuleAnalyzer.for_module(entry.topic).find_attr_docs()
        lines = docs.get(("", entry.name))
        if lines:
            return " ".join(line.strip() for line in lines).split(". ")[0].strip()
        text = repr(entry.obj)
        return f"``{text}``" if len(text) <= 60 else ""
    doc = inspect.getdoc(entry.obj) or ""
    return doc.strip().split("\n\n")[0].replace("\n", " ").strip()


def _document(entry: PublicName) -> list[str]:
    kind = _kind(entry.obj)
    lines = [f".. {kind}:: {entry.path}"]
    if kind == "autodata":
        lines.append("   :no-value:" if len(repr(entry.obj)) > 60 else "   :annotation:")
    return lines + [""]


def topic_title(module: str, parent: str) -> str:
    """A short title for a topic: its docstring's lead up to a colon, else the module name."""
    if module == parent:
        return "General"
    doc = (importlib.import_module(module).__doc__ or "").strip().split("\n")[0]
    lead = re.sub(r"\s*\([^)]*\)", "", doc.split(":")[0]).strip().rstrip(".")
    for text in (lead, lead.split(", ")[0], lead.split(" with ")[0]):
        if 0 < len(text) <= 70 and "`" not in text and not text.startswith(PACKAGE):
            return text
    rel = module.removeprefix(parent + ".")
    return rel.replace("_", " ").replace(".", ": ").capitalize()


def entries_of(subpackage: str) -> dict[str, list[PublicName]]:
    """topic -> its objects in source order, for the objects documented on this page."""
    topics: dict[str, list[PublicName]] = {}
    for entry in public_names().values():
        if subpackage_of(entry.module) == subpackage and entry.module != PACKAGE:
            topics.setdefault(entry.topic, []).append(entry)
    for items in topics.values():
        items.sort(key=lambda e: (e.order, e.name))
    return dict(sorted(topics.items(), key=lambda kv: _topic_rank(*kv)))


@cache
def _guides_text() -> str:
    """The guides, in reading order."""
    docs = Path(__file__).resolve().parents[1]
    return "\n".join(p.read_text(encoding="utf-8") for p in ordered_guides(docs))


def _topic_rank(topic: str, items: list[PublicName]) -> tuple[int, str]:
    """Topics in the order a reader meets them in the guides (the first of its names to
    appear), then the others by name."""
    text = _guides_text()
    found = [m.start() for e in items
             for m in [re.search(rf"\b{re.escape(e.name)}\b", text)] if m]
    return (min(found) if found else len(text), topic)


def summary_table(topics: dict[str, list[PublicName]], parent: str) -> list[str]:
    """One small table per topic (name, summary), under the topic's title."""
    lines = []
    for topic, items in topics.items():
        lines += [f".. rubric:: {topic_title(topic, parent)}", "",
                  ".. list-table::", "   :class: tg-summary", "   :widths: 35 65", ""]
        for entry in items:
            lines += [f"   * - :py:obj:`~{entry.path}`", f"     - {first_line(entry)}"]
        lines.append("")
    return lines


def automodule(module: str) -> list[str]:
    """A module's docstring; not indexed when a function documented at the same path
    (``torchgeo_cg.curves.nurbs``) shadows the module's name."""
    lines = [f".. automodule:: {module}", "   :no-members:"]
    if module in {e.path for e in public_names().values()}:
        lines.append("   :no-index:")
    return lines + [""]


def api_page(subpackage: str) -> str:
    """The reST of one subpackage's page."""
    topics = entries_of(subpackage)
    lines = heading(f"``{subpackage}``", "=") + [
        f".. automodule:: {subpackage}", "   :no-members:", ""]
    if topics:
        lines += heading("Summary", "-") + summary_table(topics, subpackage)
    for topic, items in topics.items():
        lines += heading(topic_title(topic, subpackage), "-")
        if topic != subpackage:
            lines += automodule(topic)
        lines += [f".. currentmodule:: {subpackage}", ""]
        for entry in items:
            lines += _document(entry)
    others = [m for m in INVENTORY if subpackage_of(m) == subpackage
              and m != subpackage and m not in topics]
    if others:
        lines += heading("Other modules", "-")
        for module in sorted(others):
            lines += automodule(module)
    return "\n".join(lines)


def api_index() -> str:
    """The index: the package's own names, then a page per subpackage."""
    lines = heading("API reference", "=") + [
        f"Every public name of ``{PACKAGE}``, documented once at the path it is imported "
        "from, one page per subpackage, grouped by topic. The list is "
        "``tests/api_inventory.py``.", "",
        ".. toctree::", "   :maxdepth: 1", ""]
    lines += [f"   {s.split('.')[-1]}" for s in subpackages()]
    lines += ["", *heading(f"``{PACKAGE}``", "-"),
              f".. automodule:: {PACKAGE}", "   :no-members:", ""]
    for entry in sorted(public_names().values(), key=lambda e: e.name):
        if entry.module == PACKAGE:
            lines += _document(entry)
    return "\n".join(lines)
