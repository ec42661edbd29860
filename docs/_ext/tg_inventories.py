"""Intersphinx inventories for Python, torch, numpy and scipy, written offline.

The build machines reach no documentation site, so the ``objects.inv`` files that
intersphinx would download are generated at build time from the installed packages,
with each project's real URL layout:

- Python (``docs.python.org/3``): builtin classes and functions on ``functions.html`` or
  ``stdtypes.html``, exceptions on ``exceptions.html``, constants on ``constants.html``,
  and ``<module>.<name>`` on ``library/<module>.html`` for the standard modules below;
- torch (``docs.pytorch.org/docs/stable``): ``generated/<name>.html`` for the functions
  and classes of ``torch``, ``torch.nn``, ``torch.nn.functional``, ``torch.linalg``,
  ``torch.fft``, ``torch.sparse``, ``torch.autograd``, ``torch.func`` and the methods of
  ``torch.Tensor``; ``torch.Tensor`` itself on ``tensors.html``, ``dtype``, ``device``,
  ``layout`` and ``memory_format`` on ``tensor_attributes.html``, ``Size`` on ``size.html``;
- numpy (``numpy.org/doc/stable``): ``reference/generated/<name>.html``;
- scipy (``docs.scipy.org/doc/scipy``): ``reference/generated/<name>.html`` for the names of
  its public subpackages used by geometry code, ``reference/<sub>.html`` for the modules.

Only names whose page exists under that rule are written; the few that live elsewhere
are listed in ``SPECIAL``. ``ALIASES`` maps every object to its documented name, so that
a reference to an implementation path (``torch.nn.modules.module.Module``,
``torch._C.Generator``) is resolved to the public one.
"""

from __future__ import annotations

import builtins
import importlib
import inspect
import zlib
from pathlib import Path

BASES = {
    "python": "https://docs.python.org/3/",
    "torch": "https://docs.pytorch.org/docs/stable/",
    "numpy": "https://numpy.org/doc/stable/",
    "scipy": "https://docs.scipy.org/doc/scipy/",
}
STDLIB = ("abc", "argparse", "collections", "collections.abc", "contextlib", "copy",
          "dataclasses", "enum", "functools", "importlib", "inspect", "io", "itertools",
          "json", "math", "numbers", "operator", "os", "os.path", "pathlib", "random", "re",
          "shutil", "subprocess", "tempfile", "threading", "time", "types", "typing",
          "warnings", "weakref", "zlib")
STDTYPES = {"str", "list", "tuple", "dict", "set", "frozenset", "bytes", "bytearray", "range",
            "memoryview"}
TORCH_MODULES = ("torch", "torch.nn", "torch.nn.functional", "torch.linalg", "torch.fft",
                 "torch.sparse", "torch.autograd", "torch.func")
SPECIAL = {
    "python": {
        "types.ModuleType": ("py:class", "library/types.html#types.ModuleType"),
    },
    "torch": {
        "torch.Tensor": ("py:class", "tensors.html#torch.Tensor"),
        "torch.dtype": ("py:class", "tensor_attributes.html#torch.dtype"),
        "torch.device": ("py:class", "tensor_attributes.html#torch.device"),
        "torch.layout": ("py:class", "tensor_attributes.html#torch.layout"),
        "torch.memory_format": ("py:class", "tensor_attributes.html#torch.memory_format"),
        "torch.Size": ("py:class", "size.html#torch.Size"),
        "torch.nn.Parameter": ("py:class", "generated/torch.nn.parameter.Parameter.html"
                               "#torch.nn.parameter.Parameter"),
        "torch.autograd.Function": ("py:class", "autograd.html#torch.autograd.Function"),
        "torch.distributed": ("py:module", "distributed.html#module-torch.distributed"),
    },
    "numpy": {
        "numpy.random.Generator": ("py:class", "reference/random/generator.html"
                                   "#numpy.random.Generator"),
    },
}
NUMPY_MODULES = ("numpy", "numpy.linalg")
SCIPY_MODULES = ("scipy.interpolate", "scipy.linalg", "scipy.ndimage", "scipy.optimize",
                 "scipy.sparse", "scipy.spatial", "scipy.spatial.transform", "scipy.special")

#: id(obj) -> its documented name, for every object written (filled by ``write_all``).
ALIASES: dict[int, str] = {}


def _role(obj: object) -> str:
    if inspect.isclass(obj):
        return "py:exception" if issubclass(obj, BaseException) else "py:class"
    if callable(obj):
        return "py:function"
    return "py:data"


def _public(module: str) -> list[tuple[str, object]]:
    mod = importlib.import_module(module)
    names = sorted(set(getattr(mod, "__all__", [])) |
                   {n for n in dir(mod) if not n.startswith("_")})
    out = []
    for name in names:
        obj = getattr(mod, name, None)
        if obj is not None and not inspect.ismodule(obj):
            out.append((name, obj))
    return out


def python_entries() -> dict[str, tuple[str, str]]:
    out: dict[str, tuple[str, str]] = {}
    for name in dir(builtins):
        obj = getattr(builtins, name)
        if name.startswith("_"):
            continue
        if inspect.isclass(obj) and issubclass(obj, BaseException):
            out[name] = ("py:exception", f"library/exceptions.html#{name}")
        elif name in STDTYPES:
            out[name] = ("py:class", f"library/stdtypes.html#{name}")
        elif name in ("None", "True", "False", "Ellipsis", "NotImplemented"):
            out[name] = ("py:data", f"library/constants.html#{name}")
        elif callable(obj):
            out[name] = (_role(obj), f"library/functions.html#{name}")
    for module in STDLIB:
        page = "os.path" if module == "os.path" else module
        out[module] = ("py:module", f"library/{page}.html#module-{module}")
        for name, obj in _public(module):
            if (getattr(obj, "__module__", None) or module).split(".")[0] == "builtins":
                continue
            out[f"{module}.{name}"] = (_role(obj), f"library/{page}.html#{module}.{name}")
    out.update(SPECIAL["python"])  # documented in its module, defined in builtins
    return out


def torch_entries() -> dict[str, tuple[str, str]]:
    import torch

    out: dict[str, tuple[str, str]] = {}
    for module in TORCH_MODULES:
        for name, obj in _public(module):
            if module == "torch" and not (inspect.isclass(obj) or callable(obj)):
                continue
            full = f"{module}.{name}"
            out[full] = (_role(obj), f"generated/{full}.html#{full}")
    for name in dir(torch.Tensor):
        if not name.startswith("_"):
            full = f"torch.Tensor.{name}"
            role = "py:method" if callable(getattr(torch.Tensor, name, None)) else "py:attribute"
            out[full] = (role, f"generated/{full}.html#{full}")
    for name in dir(torch.nn.Module):
        if not name.startswith("_"):
            full = f"torch.nn.Module.{name}"
            out[full] = ("py:method", f"generated/torch.nn.Module.html#{full}")
    out.update(SPECIAL["torch"])
    return out


def numpy_entries() -> dict[str, tuple[str, str]]:
    out: dict[str, tuple[str, str]] = {}
    for module in NUMPY_MODULES:
        for name, obj in _public(module):
            full = f"{module}.{name}"
            out[full] = (_role(obj), f"reference/generated/{full}.html#{full}")
    out.update(SPECIAL["numpy"])
    return out


def scipy_entries() -> dict[str, tuple[str, str]]:
    out: dict[str, tuple[str, str]] = {}
    for module in SCIPY_MODULES:
        page = module.removeprefix("scipy.")
        out[module] = ("py:module", f"reference/{page}.html#module-{module}")
        for name, obj in _public(module):
            full = f"{module}.{name}"
            out[full] = (_role(obj), f"reference/generated/{full}.html#{full}")
    return out


def write_inventory(path: Path, project: str, entries: dict[str, tuple[str, str]]) -> None:
    """A Sphinx ``objects.inv`` (version 2); rewritten only when its content changes."""
    body = "".join(f"{name} {role} 1 {uri} -\n" for name, (role, uri) in sorted(entries.items()))
    header = (f"# Sphinx inventory version 2\n# Project: {project}\n# Version: \n"
              "# The remainder of this file is compressed using zlib.\n").encode()
    data = header + zlib.compress(body.encode("utf-8"), 9)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_bytes() != data:
        path.write_bytes(data)


def _locate(name: str) -> object | None:
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for part in parts[cut:]:
            obj = getattr(obj, part, None)
        return obj
    return None


def write_all(folder: Path) -> dict[str, tuple[str, str]]:
    """Write the four inventories; returns ``intersphinx_mapping`` for them."""
    makers = {"python": python_entries, "torch": torch_entries, "numpy": numpy_entries,
              "scipy": scipy_entries}
    mapping = {}
    for project, make in makers.items():
        entries = make()
        for name, (role, _) in entries.items():
            if role != "py:module" and "." in name:
                obj = _locate(name)
                if obj is not None and (inspect.isclass(obj) or inspect.isfunction(obj)):
                    ALIASES.setdefault(id(obj), name)
        path = folder / f"{project}.inv"
        write_inventory(path, project, entries)
        mapping[project] = (BASES[project], str(path))
    return mapping
