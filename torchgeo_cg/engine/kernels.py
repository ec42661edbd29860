"""Kernel sets defined at first use, compiled once per machine, launched on the tensors'
device.

A kernel module of the package holds one builder, a function of the ``warp`` module that
defines its ``@wp.func`` and ``@wp.kernel`` functions in its own scope and returns them;
:func:`register_kernels` turns it into a cached getter, so no kernel exists (and Warp is
not imported) until a call needs one::

    # torchgeo_cg/points/_knn_kernels.py: no ``from __future__ import annotations`` here,
    # Warp reads the annotations, and ``wp`` exists only in the builder's scope
    from torchgeo_cg.engine import launch, register_kernels

    def _build(wp):
        @wp.kernel
        def knn_kernel(points: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.int64)):
            ...
        return SimpleNamespace(knn=knn_kernel)

    _kernels = register_kernels(_build)   # at module level: nothing is built yet

    def knn_indices(points):              # the first call loads Warp and builds
        k = _kernels()
        launch(k.knn, n, [to_warp(points, ...), to_warp(out)], points.device)

Convention:
    One builder per Python module (Warp hashes a module's kernels together: a module
    whose kernel set depended on which builder ran first would compile once per order).
    The module's kernels compile without adjoints (``enable_backward=False``): kernels
    decide integers, torch differentiates; and without fused multiply-adds
    (``fuse_fp=False``), so a kernel's arithmetic rounds as the same torch expression
    does and both paths decide alike. :func:`warm` compiles every registered set;
    the compiled code is cached by Warp across processes (see
    :mod:`torchgeo_cg.engine.backend` for the cache directory).
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable, Sequence
from types import ModuleType
from typing import TypeVar

import torch

from torchgeo_cg.core.autograd import is_transform_wrapped
from torchgeo_cg.engine.backend import load_warp

__all__ = ["kernel_ready", "launch", "launch_rows", "register_kernels", "registered_kernels",
           "to_warp", "warm"]

#: The fewest rows a CPU thread takes when :func:`launch_rows` splits a launch (smaller
#: chunks lose: right after a torch op its OpenMP workers still spin on the other cores;
#: one ICP pair's 8,000 queries in two chunks ran 20% slower).
_ROWS_PER_THREAD = 4096

_T = TypeVar("_T")

#: Python module name -> the cached getter of its kernel set.
_REGISTRY: dict[str, Callable[[], object]] = {}
_LOCK = threading.RLock()


def register_kernels(builder: Callable[[ModuleType], _T]) -> Callable[[], _T]:
    """A getter that builds ``builder(warp)`` at its first call and then returns it.

    Args:
        builder: a function of the ``warp`` module that defines kernels in its scope and
            returns them (any object); one per Python module (a second one in the same
            module raises ``ValueError``; re-importing a module replaces its entry).

    Returns:
        A function of no argument returning the built kernels; it loads Warp (raising
        :func:`~torchgeo_cg.engine.load_warp`'s ``ImportError`` when it cannot).

    Example:
        >>> from torchgeo_cg.engine import warp_status
        >>> def _build(wp):  # a real builder defines @wp.kernel functions here
        ...     return {"name": wp.__name__}
        >>> kernels = register_kernels(_build)   # nothing loaded or built yet
        >>> kernels()["name"] if warp_status()[0] == "ok" else "warp"
        'warp'
    """
    name = builder.__module__
    with _LOCK:
        known = _REGISTRY.get(name)
        if known is not None and known.__qualname__ != builder.__qualname__:
            raise ValueError(f"register_kernels: module {name!r} already registered "
                             f"{known.__qualname__!r}; one kernel builder per module")

    @functools.wraps(builder)
    def kernels() -> _T:
        with _LOCK:
            if not built:
                wp = load_warp()
                wp.set_module_options({"enable_backward": False, "fuse_fp": False},
                                      module=name)
                built.append(builder(wp))
        return built[0]

    built: list = []
    with _LOCK:
        _REGISTRY[name] = kernels
    return kernels


def registered_kernels() -> list[str]:
    """The Python modules whose kernel sets are registered, sorted.

    Convention:
        ``import torchgeo_cg`` imports every area, so it registers all of the package's
        kernel sets.

    Example:
        >>> import torchgeo_cg
        >>> isinstance(registered_kernels(), list)
        True
    """
    with _LOCK:
        return sorted(_REGISTRY)


def warm(devices: Sequence[str] | None = None) -> dict[str, float]:
    """Build and compile every registered kernel set (the kernel cache is then warm).

    Args:
        devices: the Warp devices to compile for; None: ``"cpu"``, and ``"cuda:0"`` when
            torch and Warp both see CUDA.

    Returns:
        The seconds spent per kernel set, a dict by module name; a fraction of a second
        each with a warm cache, the compile time with a cold one.

    Raises:
        ImportError: Warp cannot be loaded (see :func:`~torchgeo_cg.engine.load_warp`).

    Example:
        >>> from torchgeo_cg.engine import warp_status
        >>> times = warm() if warp_status()[0] == "ok" else {}
        >>> all(t >= 0 for t in times.values())
        True
    """
    wp = load_warp()
    if devices is None:
        devices = ["cpu"]
        if torch.cuda.is_available() and wp.is_cuda_available():
            devices.append("cuda:0")
    with _LOCK:
        items = sorted(_REGISTRY.items())
    spent = {}
    for name, kernels in items:
        start = time.perf_counter()
        kernels()
        wp.load_module(name, device=list(devices))
        spent[name] = time.perf_counter() - start
    return spent


def kernel_ready(*tensors: torch.Tensor) -> bool:
    """Whether a kernel can read these tensors: plain tensors with storage. Under
    ``torch.func`` transforms (``vmap``, ``jacrev``: wrapped tensors) and tracing (fake or
    meta tensors) it is False, and a function runs its torch path instead.

    Example:
        >>> kernel_ready(torch.zeros(3), torch.ones(2))
        True
        >>> torch.func.vmap(lambda x: torch.tensor(kernel_ready(x)))(torch.zeros(2, 3))
        tensor([False, False])
    """
    for t in tensors:
        if is_transform_wrapped(t) or t.device.type == "meta":
            return False
        try:
            t.untyped_storage().data_ptr()
        except (RuntimeError, NotImplementedError):
            return False
    return True


def to_warp(tensor: torch.Tensor, dtype: object = None) -> object:
    """A Warp array viewing ``tensor`` (no copy; made contiguous first), for a launch.

    Args:
        tensor: a CPU or CUDA tensor.
        dtype: the Warp dtype (``wp.vec3`` views the last dimension as vectors); None:
            from the tensor's dtype.

    Returns:
        A ``warp.array`` sharing the tensor's memory (keep the tensor alive meanwhile).

    Example:
        >>> from torchgeo_cg.engine import warp_status
        >>> if warp_status()[0] == "ok":
        ...     print(to_warp(torch.zeros(4, 3)).shape)
        ... else:
        ...     print((4, 3))
        (4, 3)
    """
    wp = load_warp()
    return wp.from_torch(tensor.contiguous(), dtype=dtype, requires_grad=False)


def launch(kernel: object, dim: int | Sequence[int], inputs: Sequence,
           device: torch.device) -> None:
    """Launch ``kernel`` over ``dim`` threads on torch ``device``, ordered after the work
    torch queued there (on CUDA: torch's current stream); nothing runs for zero threads.

    Args:
        kernel: a kernel from a registered builder.
        dim: the launch size (an int or a tuple of up to 4 ints).
        inputs: the kernel's arguments (``to_warp`` arrays and scalars).
        device: the torch device of the arrays.

    Example:
        >>> launch(None, 0, [], torch.device("cpu"))  # zero threads: nothing happens
    """
    sizes = (dim,) if isinstance(dim, int) else tuple(dim)
    if any(int(s) == 0 for s in sizes):
        return
    wp = load_warp()
    target = wp.device_from_torch(device)
    stream = wp.stream_from_torch(device) if target.is_cuda else None
    wp.launch(kernel, dim=dim, inputs=list(inputs), device=target, stream=stream)


def launch_rows(kernel: object, rows: torch.Tensor, inputs: Sequence, rows_at: int,
                device: torch.device) -> None:
    """Launch ``kernel`` with one thread per entry of ``rows``, on all of torch's CPU threads.

    The kernel reads its work item from ``rows`` (argument ``rows_at``: thread ``i``
    answers item ``rows[i]``), so the rows can be cut into chunks and each chunk launched
    on its own. On the CPU, Warp runs a launch on one thread; this splits it into
    ``torch.get_num_threads()`` chunks of at least 4096 rows, launched from as many
    Python threads (Warp's compiled CPU code runs without the GIL; the module is loaded
    before they start). On CUDA, one launch. The kernel's threads must be independent
    (each writes only its own items' outputs); then the result does not depend on the
    split.

    Args:
        kernel: a kernel from a registered builder.
        rows: ``(R,)`` long, the work items.
        inputs: the kernel's arguments; the one at ``rows_at`` is replaced by ``rows``.
        rows_at: the position of the rows argument.
        device: the torch device of the arrays.

    Example:
        >>> launch_rows(None, torch.zeros(0, dtype=torch.long), [None], 0,
        ...             torch.device("cpu"))  # no rows: nothing happens
    """
    count = rows.numel()
    if count == 0:
        return
    parts = 1
    if device.type == "cpu":
        parts = max(1, min(torch.get_num_threads(), count // _ROWS_PER_THREAD))
    chunks = torch.tensor_split(rows, parts)
    calls = [[*inputs[:rows_at], to_warp(chunk), *inputs[rows_at + 1:]] for chunk in chunks]
    if parts == 1:
        launch(kernel, count, calls[0], device)
        return
    wp = load_warp()
    wp.load_module(kernel.module, device=wp.device_from_torch(device))  # once, not racing
    errors: list[BaseException] = []

    def run(chunk, args):
        try:
            launch(kernel, chunk.numel(), args, device)
        except BaseException as error:  # re-raised in the caller's thread
            errors.append(error)

    workers = [threading.Thread(target=run, args=pair) for pair in zip(chunks[1:], calls[1:])]
    for worker in workers:
        worker.start()
    run(chunks[0], calls[0])
    for worker in workers:
        worker.join()
    if errors:
        raise errors[0]
