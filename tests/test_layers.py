"""The layers of the package, read from the source: every import arrow points down.

``core`` knows no area; ``transforms``, ``curves``, ``mesh``, ``points`` and ``engine`` (the
compiled kernel layer) use ``core``; ``sdf`` may use ``mesh``, ``points`` may use
``transforms``, ``surfaces`` may use ``curves``; ``points``, ``mesh`` and ``sdf`` may use
``engine``; ``viz`` and ``cli`` sit on top. Benchmarks use the public API only. No
module-level import cycle, no private name imported across modules, and no
function-level import of torchgeo_cg (which would hide a cycle or an upward arrow).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "torchgeo_cg"

#: area -> the areas it may import (besides itself); None: anything.
ALLOWED: dict[str, set[str] | None] = {
    "core": set(),
    "transforms": {"core"},
    "curves": {"core"},
    "mesh": {"core", "engine"},
    "points": {"core", "transforms", "engine"},
    "sdf": {"core", "mesh", "engine"},
    "engine": {"core"},
    "surfaces": {"core", "curves"},
    "cameras": {"core", "transforms", "curves"},
    "rays": {"core", "mesh", "sdf", "cameras", "engine"},
    "viz": None,
    "cli": None,
    "": None,  # torchgeo_cg/__init__.py and __main__.py
}

#: Function-level imports that stay, with why: (file, imported module) -> reason.
FUNCTION_LEVEL_OK: dict[tuple[str, str], str] = {
    ("viz/glyph_fit.py", "torchgeo_cg.viz._style"):
        "matplotlib (extra 'plot') only for the figure, not for the fit",
    ("viz/torus_fit.py", "torchgeo_cg.viz._style"):
        "matplotlib (extra 'plot') only for the figure, not for the fit",
}
#: Private imports across modules that stay, with why: (file, imported name) -> reason.
PRIVATE_OK: dict[tuple[str, str], str] = {}
#: The command line imports each subcommand's work only when it runs, so that
#: ``torchgeo-cg --help`` does not import torch and every area.
FUNCTION_LEVEL_OK_UNDER = ("cli/",)


def _modules(root: Path = PACKAGE) -> dict[str, Path]:
    out = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(path: Path, module: str):
    """``(imported module, names, lineno, at function level)`` for every torchgeo_cg import."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                      ast.Lambda))
            if isinstance(child, ast.Import):
                for alias in child.names:
                    if alias.name.split(".")[0] == "torchgeo_cg":
                        found.append((alias.name, [], child.lineno, in_function))
            elif isinstance(child, ast.ImportFrom):
                name = child.module or ""
                if child.level:  # relative import
                    base = package.split(".")[: len(package.split(".")) - child.level + 1]
                    name = ".".join(base + ([name] if name else []))
                if name.split(".")[0] == "torchgeo_cg":
                    found.append((name, [a.name for a in child.names], child.lineno,
                                  in_function))
            visit(child, inner)

    visit(tree, False)
    return found


def _where(path: Path) -> str:
    return path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else path.name


def _area(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] not in ("__main__",) else ""


def _upward_arrows(modules: dict[str, Path]) -> list[str]:
    bad = []
    for module, path in modules.items():
        allowed = ALLOWED.get(_area(module))
        if allowed is None:
            continue
        for target, _, line, _ in _imports(path, module):
            area = _area(target)
            if area and area != _area(module) and area not in allowed:
                bad.append(f"{_where(path)}:{line} imports {target}")
    return bad


def _function_level(modules: dict[str, Path]) -> list[str]:
    bad = []
    for module, path in modules.items():
        rel = str(path.as_posix()).rsplit("torchgeo_cg/", 1)[1]
        if rel.startswith(FUNCTION_LEVEL_OK_UNDER):
            continue
        for target, _, line, in_function in _imports(path, module):
            if in_function and (rel, target) not in FUNCTION_LEVEL_OK:
                bad.append(f"{_where(path)}:{line} imports {target} in a function")
    return bad


def _private_across(modules: dict[str, Path]) -> list[str]:
    """Private names imported from another module, or private modules of another area."""
    bad = []
    for module, path in modules.items():
        rel = str(path.as_posix()).rsplit("torchgeo_cg/", 1)[1]
        for target, names, line, _ in _imports(path, module):
            where = f"{_where(path)}:{line}"
            bad += [f"{where} imports {target}.{n}" for n in names
                    if n.startswith("_") and (rel, f"{target}.{n}") not in PRIVATE_OK]
            private = [p for p in target.split(".")[1:] if p.startswith("_")]
            if private and _area(target) != _area(module) and (rel, target) not in PRIVATE_OK:
                bad.append(f"{where} imports the private module {target}")
    return bad


def _cycles(modules: dict[str, Path]) -> list[list[str]]:
    """Strongly connected components (size > 1) of the module-level import graph, where
    importing a module also imports its packages (``sdf.grid`` runs ``sdf/__init__``)."""
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        for target, names, _, in_function in _imports(path, module):
            if in_function:
                continue
            parts = target.split(".")
            # importing a.b.c first imports the packages a.b and a (their __init__ run)
            parents = [".".join(parts[:k]) for k in range(2, len(parts))]
            parents = [p for p in parents if not module.startswith(p + ".") and p != module]
            for t in [target] + [f"{target}.{n}" for n in names] + parents:
                if t in modules and t != module:
                    graph[module].add(t)
    index, low, stack, on, out = {}, {}, [], set(), []

    def strong(v):  # Tarjan's algorithm (the graph has ~100 nodes: recursion is fine)
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            strong(v)
    return out


MODULES = _modules()


def test_every_arrow_points_down():
    bad = _upward_arrows(MODULES)
    assert bad == [], "imports against the layers:\n" + "\n".join(bad)


def test_no_function_level_import_of_the_package():
    bad = _function_level(MODULES)
    assert bad == [], "move these imports to the top of their module:\n" + "\n".join(bad)


def test_no_private_name_crosses_modules():
    bad = _private_across(MODULES)
    assert bad == [], "promote a shared helper instead:\n" + "\n".join(bad)


def test_no_import_cycle():
    assert _cycles(MODULES) == []


def test_benchmarks_use_the_public_api_only():
    bad = []
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        for target, names, line, _ in _imports(path, "benchmarks." + path.stem):
            private = [p for p in target.split(".") if p.startswith("_")]
            private += [n for n in names if n.startswith("_")]
            if private or target.startswith("torchgeo_cg.viz"):
                bad.append(f"{_where(path)}:{line} imports {target} {names}")
    assert bad == [], "benchmarks: public API only, no figure code:\n" + "\n".join(bad)


@pytest.mark.parametrize("source, finds", [
    ("import torchgeo_cg.sdf\n", "_upward_arrows"),
    ("def f():\n    from torchgeo_cg.core import hypot\n", "_function_level"),
    ("from torchgeo_cg.core.numerics import _hypot_exact\n", "_private_across"),
])
def test_the_checks_can_fail(tmp_path, source, finds):
    package = tmp_path / "torchgeo_cg"
    (package / "mesh").mkdir(parents=True)
    (package / "core").mkdir()
    (package / "mesh" / "bad.py").write_text(source)
    modules = _modules(package)
    assert "torchgeo_cg.mesh.bad" in modules
    assert len(globals()[finds](modules)) == 1


def test_the_cycle_check_can_fail(tmp_path):
    package = tmp_path / "torchgeo_cg" / "core"
    package.mkdir(parents=True)
    (package / "a.py").write_text("from torchgeo_cg.core.b import x\n")
    (package / "b.py").write_text("from torchgeo_cg.core import a\nx = 1\n")
    assert _cycles(_modules(package.parent)) == [["torchgeo_cg.core.a", "torchgeo_cg.core.b"]]
