"""Contract of the kernel layer (:mod:`torchgeo_cg.engine`): its callables take names and
kernels, not geometry, so they are exempt (tested in ``tests/engine/test_engine.py``)."""

from __future__ import annotations

ENTRIES: list = []

_WHY = "engine plumbing, no tensor geometry (tests/engine/test_engine.py)"
EXEMPT: dict[str, str] = {f"engine.{name}": _WHY for name in (
    "kernel_ready", "launch", "launch_rows", "load_warp", "register_kernels",
    "registered_kernels", "resolve_backend", "to_warp", "warm", "warp_status")}
