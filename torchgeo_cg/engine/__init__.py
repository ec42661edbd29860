"""The compiled kernel layer: NVIDIA Warp, loaded lazily, one kernel source for CPU and CUDA.

Kernels decide, torch differentiates: a kernel returns integers (neighbour indices, cube
cases, face lists); every differentiable value is recomputed from them in torch. Every
accelerated function keeps its torch path and takes ``backend="auto" | "torch" |
"warp"``, resolved by :func:`resolve_backend`.

- :mod:`~torchgeo_cg.engine.backend`: :func:`resolve_backend`, :func:`load_warp` and
  :func:`warp_status` (lazy, quiet loading; the kernel cache; the environment variable
  ``TORCHGEO_CG_DISABLE_WARP``);
- :mod:`~torchgeo_cg.engine.kernels`: :func:`register_kernels` (kernel sets defined at
  first use), :func:`warm` (compile them all), :func:`to_warp`, :func:`launch`,
  :func:`launch_rows` (a launch split across torch's CPU threads) and
  :func:`kernel_ready` (plain tensors: not under ``torch.func`` or tracing).

``import torchgeo_cg`` does not import Warp.
"""

from torchgeo_cg.engine.backend import (
    BACKENDS,
    DISABLE_ENV,
    load_warp,
    resolve_backend,
    warp_status,
)
from torchgeo_cg.engine.kernels import (
    kernel_ready,
    launch,
    launch_rows,
    register_kernels,
    registered_kernels,
    to_warp,
    warm,
)

__all__ = [
    "BACKENDS",
    "DISABLE_ENV",
    "kernel_ready",
    "launch",
    "launch_rows",
    "load_warp",
    "register_kernels",
    "registered_kernels",
    "resolve_backend",
    "to_warp",
    "warm",
    "warp_status",
]
