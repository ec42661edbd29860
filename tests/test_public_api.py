"""The public surface: every module has ``__all__``, every name resolves and is documented,
and the binding names of each issue never silently disappear."""

import importlib
import inspect
import pkgutil

import pytest

import torchgeo_cg

MODULES = sorted(
    m.name
    for m in pkgutil.walk_packages(torchgeo_cg.__path__, prefix="torchgeo_cg.")
    if not any(part.startswith("_") for part in m.name.split("."))
)

#: Binding names per subpackage (issue 2 here; other areas add theirs in their own tests).
BINDING = {
    "torchgeo_cg.core": ["ShapeError", "check_shape", "check_float"],
    "torchgeo_cg.transforms": [
        "translation", "rotation", "scaling", "scale_x", "scale_y", "shear", "homography",
        "compose", "compose_trs", "transform_points", "inverse", "SceneGraph", "solar_system",
    ],
}  # fmt: skip


@pytest.mark.parametrize("name", MODULES)
def test_module_has_all_and_every_name_resolves(name):
    module = importlib.import_module(name)
    assert hasattr(module, "__all__"), f"{name} has no __all__"
    for attr in module.__all__:
        obj = getattr(module, attr)  # raises if missing
        if inspect.isfunction(obj) or inspect.isclass(obj):
            assert obj.__doc__ and obj.__doc__.strip(), f"{name}.{attr} has no docstring"


@pytest.mark.parametrize("package, names", sorted(BINDING.items()))
def test_binding_names_exported(package, names):
    module = importlib.import_module(package)
    missing = [n for n in names if n not in module.__all__]
    assert missing == []


def test_top_level():
    assert torchgeo_cg.__version__ == "0.1.0"
    assert issubclass(torchgeo_cg.ShapeError, ValueError)
    for sub in ("core", "transforms", "curves", "sdf", "mesh"):
        assert sub in torchgeo_cg.__all__
