"""``Convention:`` sections of docstrings rendered as titled notes.

Every geometric docstring has a ``Convention:`` section (Google style, like ``Args:``).
Before napoleon reads a docstring, each such section becomes an ``admonition`` titled
"Convention" with the class ``note``, so the theme shows it as a note with that title.
"""

from __future__ import annotations

import re

HEADER = re.compile(r"^(\s*)Conventions?:\s*$")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def convert(lines: list[str]) -> list[str]:
    """The docstring's lines with every ``Convention:`` section made an admonition."""
    out: list[str] = []
    i = 0
    while i < len(lines):
        match = HEADER.match(lines[i])
        if not match:
            out.append(lines[i])
            i += 1
            continue
        base = len(match.group(1))
        body = []
        i += 1
        while i < len(lines) and (not lines[i].strip() or _indent(lines[i]) > base):
            body.append(lines[i])
            i += 1
        trailing = []
        while body and not body[-1].strip():
            trailing.append(body.pop())
        depth = min((_indent(b) for b in body if b.strip()), default=0)
        pad = " " * base
        out += [f"{pad}.. admonition:: Convention", f"{pad}   :class: note tg-convention", ""]
        out += [f"{pad}   {b[depth:]}" if b.strip() else "" for b in body]
        out += [""] + trailing
    return out


def process(app, what, name, obj, options, lines):
    lines[:] = convert(lines)


def setup(app):
    app.connect("autodoc-process-docstring", process, priority=100)  # before napoleon (500)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
