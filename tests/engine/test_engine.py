"""The kernel layer: lazy and quiet loading of Warp, backend choice, the kernel cache and
its fallback, kernel sets built at first use, DataLoader workers.

No ``from __future__ import annotations`` here: the builder below is read by Warp.
"""

import importlib.util
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import torch

from torchgeo_cg.engine import (
    BACKENDS,
    DISABLE_ENV,
    launch,
    load_warp,
    register_kernels,
    registered_kernels,
    resolve_backend,
    to_warp,
    warm,
    warp_status,
)
from torchgeo_cg.engine import backend as engine_backend

ROOT = Path(__file__).resolve().parents[2]
HAS_WARP = warp_status()[0] == "ok"
needs_warp = pytest.mark.skipif(not HAS_WARP, reason="Warp is not available here")


def _run(script: str, **env) -> subprocess.CompletedProcess:
    environment = {**os.environ, "PYTHONPATH": str(ROOT), **env}
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=300, env=environment, cwd=ROOT)


def _build(wp):
    @wp.kernel
    def square_plus_index(x: wp.array(dtype=wp.float32), y: wp.array(dtype=wp.float32)):
        i = wp.tid()
        y[i] = x[i] * x[i] + wp.float32(i)

    return square_plus_index


_kernels = register_kernels(_build)


def square_plus_index(x: torch.Tensor) -> torch.Tensor:
    """``x^2 + index`` by the test kernel (Warp) or by torch."""
    if resolve_backend("auto", x.device) == "torch":
        return x * x + torch.arange(x.shape[0], dtype=x.dtype, device=x.device)
    y = torch.empty_like(x)
    launch(_kernels(), x.shape[0], [to_warp(x), to_warp(y)], x.device)
    return y


class _Squares(torch.utils.data.Dataset):
    def __len__(self):
        return 4

    def __getitem__(self, i):
        return square_plus_index(torch.full((3,), float(i)))


def test_import_does_not_load_warp():
    out = _run("import sys, torchgeo_cg, torchgeo_cg.engine, torchgeo_cg.points\n"
               "import torchgeo_cg.sdf, torchgeo_cg.mesh\n"
               "print('warp' in sys.modules)")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


@needs_warp
def test_loading_is_quiet_and_kernels_run():
    script = ("import torch\nfrom tests.engine.test_engine import square_plus_index\n"
              "print(square_plus_index(torch.tensor([1.0, 2.0, 3.0])).tolist())")
    out = _run(script)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[1.0, 5.0, 11.0]"
    assert "Warp" not in out.stderr and "Warp" not in out.stdout.replace("[", "")


def test_resolve_backend_names():
    assert BACKENDS == ("auto", "torch", "warp")
    assert resolve_backend("torch") == "torch"
    assert resolve_backend("auto") == ("warp" if HAS_WARP else "torch")
    with pytest.raises(ValueError, match="backend: expected one of 'auto', 'torch', 'warp'"):
        resolve_backend("cuda")
    # a device Warp does not run on: auto is torch, warp says why
    assert resolve_backend("auto", torch.device("meta")) == "torch"
    with pytest.raises(ValueError, match="backend='warp'.*meta"):
        resolve_backend("warp", "meta")


@needs_warp
def test_warp_backend_and_kernel():
    assert resolve_backend("warp", "cpu") == "warp"
    assert load_warp().__name__ == "warp"
    x = torch.tensor([0.5, -2.0, 3.0, 0.0])
    assert torch.equal(square_plus_index(x), x * x + torch.arange(4.0))
    launch(_kernels(), 0, [], x.device)  # zero threads: a no-op


def test_one_builder_per_module():
    def _build(wp):  # noqa: F811  a second builder in this module
        return None

    with pytest.raises(ValueError, match="one kernel builder per module"):
        register_kernels(_build)
    assert __name__ in registered_kernels()


@needs_warp
def test_warm_compiles_every_registered_set():
    import torchgeo_cg  # noqa: F401  registers the package's kernel sets

    spent = warm(["cpu"])
    assert set(registered_kernels()) <= set(spent)
    assert "torchgeo_cg.sdf._engine_warp" in spent
    assert all(t >= 0 for t in spent.values())


class _BrokenWarp:
    """Warp is found but its import raises what a missing CUDA library raises."""

    def find_spec(self, name, path=None, target=None):
        return importlib.util.spec_from_loader(name, self) if name == "warp" else None

    def create_module(self, spec):
        return None

    def exec_module(self, module):
        raise OSError("libcuda.so: cannot open shared object file")


@pytest.fixture
def forget_warp(monkeypatch):
    """Forget this process's load of Warp for one test (restored afterwards)."""
    monkeypatch.setattr(engine_backend, "_STATE", {})
    monkeypatch.setattr(engine_backend, "_WARNED", set())
    monkeypatch.delitem(sys.modules, "warp", raising=False)


def test_broken_warp_warns_once_and_raises_chained(forget_warp, monkeypatch):
    monkeypatch.setattr(sys, "meta_path", [_BrokenWarp(), *sys.meta_path])
    assert warp_status()[0] == "broken"
    with pytest.warns(UserWarning, match="failed to import.*OSError: libcuda") as record:
        assert resolve_backend("auto") == "torch"
        assert resolve_backend("auto", "cpu") == "torch"
    assert len(record) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert resolve_backend("auto") == "torch"
    with pytest.raises(ImportError, match="installed but failed to import") as info:
        resolve_backend("warp")
    assert isinstance(info.value.__cause__, OSError)
    with pytest.raises(ImportError, match="failed to import"):
        load_warp()


def test_missing_warp_is_silent_and_names_the_extra(forget_warp, monkeypatch):
    monkeypatch.setitem(sys.modules, "warp", None)  # find_spec finds nothing
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert resolve_backend("auto") == "torch"
    assert warp_status()[0] == "missing"
    with pytest.raises(ImportError, match="optional extra 'fast'") as info:
        resolve_backend("warp")
    assert isinstance(info.value.__cause__, ModuleNotFoundError)


def test_disabled_by_the_environment():
    script = """
import sys, warnings
warnings.simplefilter("error")
import torch
from torchgeo_cg.engine import resolve_backend, warp_status
from tests.engine.test_engine import square_plus_index
assert resolve_backend("auto") == "torch" and warp_status()[0] == "missing"
assert square_plus_index(torch.tensor([2.0, 2.0])).tolist() == [4.0, 5.0]
try:
    resolve_backend("warp")
    raise SystemExit("no ImportError")
except ImportError as e:
    assert "TORCHGEO_CG_DISABLE_WARP" in str(e), e
assert "warp" not in sys.modules
print("ok")
"""
    out = _run(script, **{DISABLE_ENV: "1"})
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]


@needs_warp
def test_unwritable_kernel_cache_falls_back_to_a_temporary_directory(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    script = """
import torch
from torchgeo_cg.engine import load_warp
from tests.engine.test_engine import square_plus_index
wp = load_warp()
print(wp.config.kernel_cache_dir)
assert square_plus_index(torch.tensor([3.0])).tolist() == [9.0]
"""
    out = _run(script, WARP_CACHE_PATH=str(blocker / "cache"))  # cannot be created
    assert out.returncode == 0, out.stderr[-2000:]
    cache = Path(out.stdout.strip())
    assert "torchgeo_cg_warp_cache_" in cache.name or "torchgeo_cg_warp_cache_" in str(cache)
    assert any(cache.rglob("*")), "the kernel was compiled into the temporary cache"


@needs_warp
@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0,
                    reason="a read-only directory is writable by root")
def test_read_only_kernel_cache(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    out = _run("from torchgeo_cg.engine import load_warp\n"
               "print(load_warp().config.kernel_cache_dir)", WARP_CACHE_PATH=str(ro))
    assert out.returncode == 0, out.stderr[-2000:]
    assert "torchgeo_cg_warp_cache_" in out.stdout


@needs_warp
@pytest.mark.slow
@pytest.mark.parametrize("context", ["fork", "spawn"])
def test_dataloader_workers(context):
    if context not in torch.multiprocessing.get_all_start_methods():
        pytest.skip(f"no {context} start method here")
    square_plus_index(torch.ones(2))  # Warp loaded in the parent before the fork
    loader = torch.utils.data.DataLoader(_Squares(), batch_size=2, num_workers=2,
                                         multiprocessing_context=context)
    got = torch.cat(list(loader))
    want = torch.stack([torch.full((3,), float(i)) ** 2 + torch.arange(3.0)
                        for i in range(4)])
    assert torch.equal(got, want)
