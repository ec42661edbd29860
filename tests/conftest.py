"""Suite-wide fixtures and settings, in the style of kornia's ``testing/base.py``.

- ``device`` / ``dtype``: every test asking for them runs over all of them (CPU,
  plus CUDA when present; float32 and float64); ``tol`` is the tolerance table of
  the current dtype.
- ``one_thread``: run a test with one torch thread (small batched ops are faster
  and shared CI cores are not oversubscribed); use it with
  ``pytestmark = pytest.mark.usefixtures("one_thread")`` or as an argument.
- ``rng``: a seeded ``torch.Generator`` per test, so tests never share a stream.
- Markers (registered in ``pyproject.toml``): ``slow`` for tests over ~5 s and
  ``grad`` for float64 gradchecks. CI (``.ci/run``) runs everything; locally,
  ``pytest -m "not slow"`` skips the slow ones.
- Under pytest-xdist (``-n auto``, as the README's command runs) every worker uses one
  torch thread: the workers already fill the cores, and oversubscribed OpenMP threads
  made small ops 10-100x slower on 2 shared cores.
- The Warp kernel cache is warmed once, in the controlling process, before any test runs
  (``pytest_configure``): the workers then load compiled kernels instead of compiling
  the same ones side by side. Nothing happens when Warp is missing, broken or disabled
  (``TORCHGEO_CG_DISABLE_WARP=1``).
- Hypothesis profiles, chosen with ``HYPOTHESIS_PROFILE``: ``ci`` (the default, 40
  examples, the same on every run) and ``thorough`` (500 examples, for a nightly or a
  release check).
"""

from __future__ import annotations

import os

import pytest
import torch
from hypothesis import HealthCheck, settings

from torchgeo_cg.core.testing import DTYPES, available_devices, tolerance

# ci draws the same examples on every run (derandomize), so a result never depends on
# the run; "thorough" explores new ones
settings.register_profile(
    "ci", max_examples=40, deadline=None, derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile(
    "thorough",
    max_examples=500,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))



def pytest_configure(config):
    """Compile every kernel set of the package once, in the controller only (an xdist
    worker has ``workerinput``), so the workers find a warm kernel cache."""
    if hasattr(config, "workerinput"):
        return
    import torchgeo_cg  # noqa: F401  registers every kernel set of the package
    from torchgeo_cg.engine import warm, warp_status

    if warp_status()[0] == "ok":
        warm()


if os.environ.get("PYTEST_XDIST_WORKER"):  # the workers share the cores: no oversubscription
    torch.set_num_threads(1)


@pytest.fixture(params=available_devices())
def device(request) -> torch.device:
    """Every available device: ``cpu``, then ``cuda`` when present."""
    return torch.device(request.param)


@pytest.fixture(params=DTYPES, ids=lambda d: str(d).replace("torch.", ""))
def dtype(request) -> torch.dtype:
    """Every float dtype of :data:`torchgeo_cg.core.testing.DTYPES`."""
    return request.param


@pytest.fixture
def tol(dtype) -> dict[str, float]:
    """``{"rtol", "atol"}`` for the current dtype."""
    return tolerance(dtype)


@pytest.fixture
def one_thread():
    """Run the test with one torch thread, restoring the previous count afterwards."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


@pytest.fixture
def rng(request) -> torch.Generator:
    """A CPU ``torch.Generator`` seeded from the test's name (stable across runs and workers)."""
    import zlib

    return torch.Generator().manual_seed(zlib.crc32(request.node.nodeid.encode()))
