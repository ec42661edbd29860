"""The public surface, checked against ONE inventory (``tests/api_inventory.py``).

Every public module has ``__all__``; its names are exactly the inventory's (a
missing name and an unlisted extra both fail, each named); every name resolves
and every public function or class is documented.
"""

import importlib
import inspect

import pytest

import torchgeo_cg
from tests.api_inventory import INVENTORY, format_inventory, public_modules

MODULES = public_modules()


def test_inventory_lists_every_public_module():
    missing = sorted(set(MODULES) - set(INVENTORY))
    stale = sorted(set(INVENTORY) - set(MODULES))
    assert not missing and not stale, (
        f"public modules not in tests/api_inventory.py: {missing}; "
        f"listed there but gone: {stale} (python tests/api_inventory.py prints the current table)"
    )


@pytest.mark.parametrize("name", MODULES)
def test_module_surface_matches_inventory(name):
    module = importlib.import_module(name)
    assert hasattr(module, "__all__"), f"{name} has no __all__"
    exported, listed = set(module.__all__), set(INVENTORY.get(name, []))
    missing, extra = sorted(listed - exported), sorted(exported - listed)
    assert not missing and not extra, (
        f"{name}.__all__ differs from tests/api_inventory.py: missing {missing} "
        f"(in the inventory, not exported), extra {extra} (exported, not in the inventory)"
    )
    assert len(module.__all__) == len(exported), f"{name}.__all__ has duplicates"


@pytest.mark.parametrize("name", MODULES)
def test_every_name_resolves_and_is_documented(name):
    module = importlib.import_module(name)
    undocumented = []
    for attr in module.__all__:
        obj = getattr(module, attr)  # raises if missing
        if (inspect.isfunction(obj) or inspect.isclass(obj)) and not (obj.__doc__ or "").strip():
            undocumented.append(attr)
    assert undocumented == [], f"{name}: no docstring for {undocumented}"


def test_failure_message_names_the_difference(monkeypatch):
    """The check itself can fail, and says which names differ."""
    top = [n for n in INVENTORY["torchgeo_cg"] if n != "core"] + ["not_a_name"]
    monkeypatch.setitem(globals(), "INVENTORY", dict(INVENTORY, torchgeo_cg=top))
    with pytest.raises(AssertionError, match=r"missing \['not_a_name'\].*extra \['core'\]"):
        test_module_surface_matches_inventory("torchgeo_cg")


def test_format_round_trips():
    namespace: dict = {}
    exec("INVENTORY = {\n" + format_inventory(INVENTORY) + "\n}", namespace)
    assert namespace["INVENTORY"] == {k: sorted(v) for k, v in INVENTORY.items()}


def test_top_level():
    assert torchgeo_cg.__version__ == "0.1.0"
    assert issubclass(torchgeo_cg.ShapeError, ValueError)
