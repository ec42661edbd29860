"""Where each public object of torchgeo_cg is documented: its public path.

An object re-exported by several public modules is documented once, under the shortest
of them (the module a user imports it from: ``torchgeo_cg.mesh.marching_cubes``, not
``torchgeo_cg.mesh.marching_cubes.dense.marching_cubes``). Its *topic* is the public
module that defines it; the reference groups each subpackage's page by topic, in source
order. Everything is read from ``tests/api_inventory.py``, so a new subpackage, module or
name is picked up without an edit here. ``tests/test_docs.py`` uses the same table.
"""

from __future__ import annotations

import ast
import importlib
import inspect
from functools import cache
from pathlib import Path
from typing import NamedTuple

from tests.api_inventory import INVENTORY, PACKAGE


class PublicName(NamedTuple):
    """One public object: where it is documented, and the topic it belongs to."""

    module: str  # the shortest public module exporting it
    name: str
    topic: str  # the public module defining it
    order: int  # position in the topic's source
    obj: object

    @property
    def path(self) -> str:
        return f"{self.module}.{self.name}"


def _depth(module: str) -> int:
    return module.count(".")


def _source_file(module: str) -> str | None:
    mod = importlib.import_module(module)
    return getattr(mod, "__file__", None)


@cache
def _assignments(module: str) -> dict[str, int]:
    """Module-level names assigned in ``module``'s own source -> line."""
    path = _source_file(module)
    if not path:
        return {}
    tree = ast.parse(Path(path).read_text(encoding="utf-8"))
    out: dict[str, int] = {}
    for node in tree.body:
        targets = []
        if isinstance(node, ast.Assign):
            targets = [t for t in node.targets if isinstance(t, ast.Name)]
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            targets = [node.target]
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.setdefault(node.name, node.lineno)
        for target in targets:
            out.setdefault(target.id, node.lineno)
    return out


def _defines(module: str, name: str, obj: object) -> bool:
    """Whether ``module``'s own source defines ``obj`` (as ``name``)."""
    if inspect.isclass(obj) or inspect.isfunction(obj):
        return getattr(obj, "__module__", None) == module
    if getattr(obj, "__module__", None) == module:  # e.g. an lru_cache-wrapped function
        return True
    return name in _assignments(module) and inspect.getmodule(obj) is None


def _order(topic: str, name: str, obj: object) -> int:
    line = _assignments(topic).get(name)
    if line is not None:
        return line
    try:
        if Path(inspect.getsourcefile(obj) or "") == Path(_source_file(topic) or "."):
            return inspect.getsourcelines(obj)[1]
    except (TypeError, OSError):
        pass
    return 10**6 + sorted(INVENTORY[topic]).index(name) if name in INVENTORY[topic] else 10**7


def _public_sibling(obj: object) -> str | None:
    """``pkg._topic`` -> ``pkg.topic`` when that public module exists: the topic of an
    object defined in a private module beside its public one."""
    module = getattr(obj, "__module__", None) or ""
    head, _, last = module.rpartition(".")
    sibling = f"{head}.{last.lstrip('_')}"
    return sibling if last.startswith("_") and sibling in INVENTORY else None


@cache
def public_names() -> dict[tuple[int, str], PublicName]:
    """``(id(obj), name)`` -> where the object is documented, for every non-module public
    object (an object exported under two names is documented under each)."""
    homes: dict[tuple[int, str], list[str]] = {}
    objects: dict[int, object] = {}
    for module, names in INVENTORY.items():
        mod = importlib.import_module(module)
        for name in names:
            obj = getattr(mod, name)
            if inspect.ismodule(obj):
                continue
            homes.setdefault((id(obj), name), []).append(module)
            objects[id(obj)] = obj
    out = {}
    for (key, name), places in homes.items():
        obj = objects[key]
        module = min(places, key=lambda m: (_depth(m), m))
        defining = [m for m in places if _defines(m, name, obj)]
        topic = defining[0] if defining else _public_sibling(obj) or max(
            places, key=lambda m: (_depth(m), m))
        out[key, name] = PublicName(module, name, topic, _order(topic, name, obj), obj)
    return out


@cache
def _path_of_id() -> dict[int, str]:
    out: dict[int, str] = {}
    for (key, _), entry in sorted(public_names().items(),
                                  key=lambda kv: (_depth(kv[1].module), kv[1].path)):
        out.setdefault(key, entry.path)
    return out


def public_path(obj: object) -> str | None:
    """The documented path of a public object (a module: its name), else None."""
    if inspect.ismodule(obj):
        return obj.__name__ if obj.__name__ in INVENTORY else None
    return _path_of_id().get(id(obj))


def subpackage_of(module: str) -> str:
    """``torchgeo_cg.mesh.io`` -> ``torchgeo_cg.mesh``; the package itself stays."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 else PACKAGE
