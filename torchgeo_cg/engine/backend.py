"""Backend choice and the loading of NVIDIA Warp: lazily, once per process, quietly, with a
writable kernel cache.

``import torchgeo_cg`` never imports Warp; :func:`load_warp` does, at the first call that
needs a kernel. The outcome (the module, or why there is none) is kept for the process.

Convention:
    Three outcomes, told apart by :func:`warp_status`:

    - ``"ok"``: Warp imported and initialised;
    - ``"missing"``: not installed (a platform without a ``warp-lang`` wheel) or disabled
      by the environment variable ``TORCHGEO_CG_DISABLE_WARP=1``: the torch path is the
      documented behaviour there, so ``backend="auto"`` falls back silently;
    - ``"broken"``: installed, but its import or initialisation raised (a broken CUDA
      driver, a missing system library): ``backend="auto"`` falls back with one
      ``UserWarning`` per process.

    Initialisation is quiet: Warp's log level is raised to warnings (no banner, no
    kernel-load lines) and the native library's "no CUDA driver" line is dropped when
    torch sees no CUDA either. The kernel cache is Warp's default one (or
    ``WARP_CACHE_PATH``, or ``warp.config.kernel_cache_dir`` when set); when that
    directory cannot be written, a fresh temporary directory is used instead (kernels
    then compile once per process). Loading creates no CUDA context: a device is touched
    only by a launch on it.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import sys
import tempfile
import threading
import warnings
from types import ModuleType

import torch

from torchgeo_cg.core.check import check_choice

__all__ = ["BACKENDS", "DISABLE_ENV", "load_warp", "resolve_backend", "warp_status"]

#: The accepted values of every ``backend=`` argument of the package.
BACKENDS = ("auto", "torch", "warp")

#: The environment variable that, set to anything but ``""`` or ``"0"``, keeps Warp
#: unloaded: every ``backend="auto"`` is the torch path, ``backend="warp"`` raises.
DISABLE_ENV = "TORCHGEO_CG_DISABLE_WARP"

#: The one outcome of loading, per process: {"module": warp} or {"missing"|"broken": exc}.
_STATE: dict[str, object] = {}
_LOCK = threading.Lock()

#: What the native library prints on a machine without the CUDA driver.
_NO_DRIVER = "Could not find or load the NVIDIA CUDA driver"


def warp_status() -> tuple[str, Exception | None]:
    """Load Warp if not tried yet; ``("ok", None)``, ``("missing", why)`` or
    ``("broken", why)``.

    Returns:
        The outcome (see the module's convention) and the exception that explains a
        missing or broken Warp (None when it loaded).

    Example:
        >>> status, why = warp_status()
        >>> status in ("ok", "missing", "broken")
        True
    """
    with _LOCK:
        if not _STATE:
            _STATE.update(_load())
    if "module" in _STATE:
        return "ok", None
    kind = next(iter(_STATE))
    return kind, _STATE[kind]  # type: ignore[return-value]


def load_warp() -> ModuleType:
    """The imported and initialised ``warp`` module (loaded at the first call, then kept).

    Returns:
        The ``warp`` module, initialised quietly with a writable kernel cache.

    Raises:
        ImportError: Warp is not installed (names the extra ``fast``), is disabled by
            ``TORCHGEO_CG_DISABLE_WARP``, or failed to import or initialise (says why;
            chained from that exception).

    Example:
        >>> if warp_status()[0] == "ok":
        ...     print(load_warp().__name__)
        ... else:
        ...     print("warp")
        warp
    """
    status, why = warp_status()
    if status == "ok":
        return _STATE["module"]  # type: ignore[return-value]
    raise _unavailable_error(status, why)


def _unavailable_error(status: str, why: Exception | None) -> ImportError:
    """The ``ImportError`` that says why Warp cannot be used (``status`` not ``"ok"``),
    chained from ``why``."""
    if isinstance(why, _Disabled):
        error = ImportError(f"backend='warp': Warp is disabled by the environment variable "
                            f"{DISABLE_ENV}={os.environ.get(DISABLE_ENV)!r}")
    elif status == "missing":
        error = ImportError("backend='warp' needs NVIDIA Warp, which is not installed: it "
                            "comes with the optional extra 'fast': "
                            "pip install 'torchgeo_cg[fast]' (installs warp-lang)")
    else:
        error = ImportError(f"backend='warp': warp is installed but failed to import "
                            f"({type(why).__name__}: {why})")
    error.__cause__ = why
    return error


def resolve_backend(backend: str, device: torch.device | str | None = None) -> str:
    """``"auto"`` | ``"torch"`` | ``"warp"`` -> the backend a call runs: ``"torch"`` or
    ``"warp"``.

    Convention:
        ``"auto"`` is ``"warp"`` when Warp loads (and, for a CUDA ``device``, sees that
        device), else ``"torch"``: silently when Warp is missing or disabled (see
        :func:`warp_status`), or on a device Warp does not run on (``mps``...); with one
        ``UserWarning`` per process when an installed Warp failed to import or
        initialise. Resolving loads Warp but touches no device.

    Args:
        backend: ``"auto"``, ``"torch"`` or ``"warp"``.
        device: the device of the call's tensors (None: not checked).

    Returns:
        ``"torch"`` or ``"warp"``.

    Raises:
        ValueError: an unknown name, or ``"warp"`` on a device other than CPU and CUDA.
        ImportError: ``"warp"`` and Warp is missing (names the extra ``fast``), disabled,
            failed to load (chained from the cause), or sees no such CUDA device.

    Warns:
        UserWarning: ``"auto"`` falls back because an installed Warp failed to load (once
            per process).

    Example:
        >>> resolve_backend("torch")
        'torch'
        >>> resolve_backend("auto") in ("torch", "warp")
        True
        >>> resolve_backend("fast")
        Traceback (most recent call last):
        ...
        ValueError: backend: expected one of 'auto', 'torch', 'warp', got 'fast'
    """
    check_choice(backend, BACKENDS, "backend")
    if backend == "torch":
        return "torch"
    device = None if device is None else torch.device(device)
    if device is not None and device.type not in ("cpu", "cuda"):
        if backend == "auto":
            return "torch"
        raise ValueError(f"backend='warp': runs on 'cpu' and 'cuda' devices, got {device}")
    status, why = warp_status()
    if status == "ok" and device is not None and device.type == "cuda":
        status, why = _cuda_status(device)
    if status == "ok":
        return "warp"
    if backend == "warp":
        raise _unavailable_error(status, why)
    if status == "broken" and not _WARNED:
        _WARNED.add(status)
        warnings.warn(f"backend='auto': Warp is installed but failed to import "
                      f"({type(why).__name__}: {why}); using the torch path",
                      UserWarning, stacklevel=3)
    return "torch"


#: Non-empty once ``backend="auto"`` has warned about a broken Warp in this process.
_WARNED: set[str] = set()


def _cuda_status(device: torch.device) -> tuple[str, Exception | None]:
    """Whether the loaded Warp can run on CUDA ``device`` (asks the driver, no context)."""
    wp = _STATE["module"]
    index = torch.cuda.current_device() if device.index is None else device.index
    if not wp.is_cuda_available() or index >= wp.get_cuda_device_count():
        return "broken", RuntimeError(f"Warp sees no CUDA device {index} (torch does)")
    return "ok", None


class _Disabled(Exception):
    """Warp disabled by :data:`DISABLE_ENV`."""


def _load() -> dict[str, object]:
    if os.environ.get(DISABLE_ENV, "") not in ("", "0"):
        return {"missing": _Disabled(f"{DISABLE_ENV} is set")}
    try:
        if importlib.util.find_spec("warp") is None:
            return {"missing": ModuleNotFoundError("No module named 'warp'", name="warp")}
    except (ImportError, ValueError) as exc:  # a broken parent entry in sys.modules
        return {"broken": exc}
    try:
        import warp
    except ModuleNotFoundError as exc:
        return {"missing" if exc.name == "warp" else "broken": exc}
    except Exception as exc:  # noqa: BLE001  any failure of an installed Warp disables it
        return {"broken": exc}
    try:
        _initialise(warp)
    except Exception as exc:  # noqa: BLE001
        return {"broken": exc}
    return {"module": warp}


def _initialise(wp: ModuleType) -> None:
    """``wp.init()`` without the banner, with a writable kernel cache."""
    if wp.config.log_level < logging.WARNING:
        wp.config.log_level = logging.WARNING
    cache = _cache_candidate(wp)
    if cache is not None and not _writable(cache):
        wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="torchgeo_cg_warp_cache_")
    with _stderr_filtered(drop=_NO_DRIVER if not torch.cuda.is_available() else None):
        wp.init()
    if not _writable(wp.config.kernel_cache_dir):  # the default location, resolved by init
        wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="torchgeo_cg_warp_cache_")


def _cache_candidate(wp: ModuleType) -> str | None:
    """The cache directory Warp's init would create when it is set explicitly (config or
    ``WARP_CACHE_PATH``; Warp appends its version), else None (the user cache dir)."""
    base = wp.config.kernel_cache_dir or os.environ.get("WARP_CACHE_PATH")
    return None if base is None else os.path.join(os.path.realpath(base), wp.config.version)


def _writable(path: str | None) -> bool:
    """Whether files can be created in directory ``path`` (made if missing)."""
    if path is None:
        return False
    try:
        os.makedirs(path, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".probe_"):
            pass
    except OSError:
        return False
    return True


@contextlib.contextmanager
def _stderr_filtered(drop: str | None):
    """Capture what native code writes to file descriptor 2 and write it back without
    the lines containing ``drop`` (nothing captured when ``drop`` is None)."""
    if drop is None:
        yield
        return
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # no real stderr (a notebook kernel)
        fd = 2
    sys.stderr.flush()
    saved = os.dup(fd)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), fd)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, fd)
            os.close(saved)
            sink.seek(0)
            kept = [line for line in sink.read().decode(errors="replace").splitlines(True)
                    if drop not in line]
            if kept:
                sys.stderr.write("".join(kept))
