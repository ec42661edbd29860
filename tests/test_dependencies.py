"""Every third-party import of the package is declared in ``pyproject.toml``.

Runtime code outside ``viz``/``cli`` may import only the hard dependencies (or the
``fast`` extra's engine, imported lazily); figures and the command line may also use
the ``plot`` extra. Packages used only by tests and benchmarks stay in those extras.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

ROOT = Path(__file__).resolve().parents[1]
#: import name -> distribution name, where they differ
DISTRIBUTION = {"skimage": "scikit-image", "PIL": "pillow", "mpl_toolkits": "matplotlib",
                "warp": "warp-lang"}


def _requirements(entries: list[str]) -> set[str]:
    return {re.split(r"[<>=!~\[ ;]", e, maxsplit=1)[0].lower() for e in entries}


def _imports() -> dict[str, set[str]]:
    """Third-party top-level import -> the subpackages importing it."""
    found: dict[str, set[str]] = {}
    for path in (ROOT / "torchgeo_cg").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top not in ("torchgeo_cg", "__future__"):
                    part = path.relative_to(ROOT / "torchgeo_cg").parts[0]
                    found.setdefault(top, set()).add(part)
    return found


def test_every_runtime_import_is_declared():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    hard = _requirements(project["dependencies"])
    extras = {k: _requirements(v) for k, v in project["optional-dependencies"].items()}
    imports = _imports()
    assert {"torch", "numpy"} <= set(imports), "the import scan found nothing: it is broken"
    undeclared = []
    for top, parts in imports.items():
        dist = DISTRIBUTION.get(top, top).lower()
        if parts <= {"viz", "cli"}:
            allowed = hard | extras["plot"]
        else:
            allowed = hard | extras["fast"]
        if dist not in allowed:
            undeclared.append(f"{top} ({dist}) imported by {sorted(parts)}")
    assert undeclared == [], f"declare these in pyproject.toml: {undeclared}"


def test_test_only_packages_are_not_hard_dependencies():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    hard = _requirements(project["dependencies"])
    used = {DISTRIBUTION.get(top, top).lower() for top in _imports()}
    assert hard - used == set(), "hard dependencies the package never imports"
