"""Cross-references that Sphinx cannot resolve by name alone, resolved by object.

A docstring or a signature may name an object by a path that is not where it is
documented: a bare name (``Tensor``, ``marching_cubes``) or an implementation path
(``torchgeo_cg.mesh.subdivision._levels.SubdivisionModule``, ``torch._C.Generator``).
The handler imports the object and links it to its documented place: for our own
names the public path of :mod:`tg_public`, for others the name written in the offline
inventories (:mod:`tg_inventories`). A private object of ours (a ``_`` module or name)
is shown as code without a link. Anything else stays a warning, so ``-n -W`` still
catches a typo.
"""

from __future__ import annotations

import importlib
import inspect
import sys
from typing import NamedTuple

from sphinx.ext import intersphinx
from tg_inventories import ALIASES
from tg_public import public_path

PACKAGE = "torchgeo_cg"


#: packages without an inventory here: their objects are shown as code, without a link
NO_INVENTORY = ("trimesh", "warp", "open3d", "matplotlib", "skimage", "mpl_toolkits")


class Found(NamedTuple):
    """What a reference names: the object, and its owner when it is an attribute."""

    obj: object
    owner: object = None
    attr: str = ""
    ours: bool = False  # found in a module of the package


def _locate(name: str) -> Found | None:
    """The object at a dotted path (modules imported, then attributes), or None."""
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        owner = None
        for part in parts[cut:]:
            if not hasattr(obj, part):
                return None
            owner, obj = obj, getattr(obj, part)
        return Found(obj, owner, parts[-1] if owner is not None else "", parts[0] == PACKAGE)
    return None


def _in_package_namespaces(name: str, prefix: str) -> Found | None:
    """A bare name, found as a module attribute of the package: the one object it means
    in the modules under ``prefix`` (the reference's module), else in the whole package."""
    for scope in (prefix, PACKAGE):
        found = {}
        for module_name, module in list(sys.modules.items()):
            if (module_name + ".").startswith(scope + ".") and module is not None:
                obj = getattr(module, name, None)
                if obj is not None and not inspect.ismodule(obj):
                    found[id(obj)] = obj
                if module_name.endswith("." + name) and name.startswith("_"):
                    found[id(module)] = module
        if len(found) == 1:
            return Found(next(iter(found.values())), ours=True)
    return None


def find_object(target: str, context: list[str]) -> Found | None:
    """The object a reference means: as written, in its context module or class, or a
    bare name that means one object in the reference's module (or the package)."""
    for prefix in context:
        found = _locate(f"{prefix}.{target}" if prefix else target)
        if found is not None:
            return found
    if "." not in target:
        return _in_package_namespaces(target, context[-2] if len(context) > 1 else PACKAGE)
    return None


def _is_ours(found: Found) -> bool:
    """Whether a found object is ours: by its module, else (data) by where it was found."""
    obj = found.obj
    if public_path(obj) is not None:
        return True
    module = obj.__name__ if inspect.ismodule(obj) else getattr(obj, "__module__", None)
    if isinstance(module, str):
        return module.split(".")[0] == PACKAGE
    return found.ours


def _our_path(found: Found) -> str | None:
    """The documented path of one of our objects, or of an attribute of a public class."""
    path = public_path(found.obj)
    if path is None and inspect.isclass(found.owner) and public_path(found.owner):
        path = f"{public_path(found.owner)}.{found.attr}"
    return path


def _external_names(target: str, obj: object) -> list[str]:
    names = [target]
    if id(obj) in ALIASES:
        names.append(ALIASES[id(obj)])
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if module and qualname:
        names.append(qualname if module == "builtins" else f"{module}.{qualname}")
    return names


def resolve(app, env, node, contnode):
    """``missing-reference`` handler (Python domain only)."""
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"]
    module, cls = node.get("py:module"), node.get("py:class")
    context = [f"{module}.{cls}" if module and cls else None, module, ""]
    found = find_object(target, [c for c in context if c is not None])
    if found is None:
        return None
    if _is_ours(found):
        path = _our_path(found)
        if path is None:  # not public: shown as code, without a link
            return contnode
        domain = env.get_domain("py")
        fromdoc = node.get("refdoc", "")
        for role in (node["reftype"], "obj"):
            ref = domain.resolve_xref(env, fromdoc, app.builder, role, path, node, contnode)
            if ref is not None:
                return ref
        return None
    for name in _external_names(target, found.obj):
        node["reftarget"] = name
        ref = intersphinx.missing_reference(app, env, node, contnode)
        if ref is not None:
            return ref
    node["reftarget"] = target
    owner = getattr(found.obj, "__module__", None) or getattr(found.obj, "__name__", "")
    if owner.split(".")[0] in NO_INVENTORY:
        return contnode
    return None


def setup(app):
    app.connect("missing-reference", resolve, priority=900)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
