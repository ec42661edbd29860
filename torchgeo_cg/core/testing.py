"""Test support shared by the whole suite: dtypes, devices and tolerances.

``tests/conftest.py`` turns these into the ``device`` and ``dtype`` fixtures, so
every test that asks for them runs over float32 and float64 on every device
present (the CPU, plus CUDA when available).
"""

from __future__ import annotations

import torch

__all__ = ["DTYPES", "TOLERANCES", "available_devices", "tolerance", "assert_close"]

DTYPES: tuple[torch.dtype, ...] = (torch.float32, torch.float64)

#: Default ``(rtol, atol)`` per dtype for comparing against references.
TOLERANCES: dict[torch.dtype, tuple[float, float]] = {
    torch.float16: (1e-2, 1e-2),
    torch.bfloat16: (2e-2, 2e-2),
    torch.float32: (1e-5, 1e-5),
    torch.float64: (1e-10, 1e-10),
}


def available_devices() -> list[str]:
    """The devices tests run on: ``["cpu"]`` plus ``"cuda"`` when available.

    Example:
        >>> "cpu" in available_devices()
        True
    """
    devices = ["cpu"]
    if torch.cuda.is_available():
        devices.append("cuda")
    return devices


def tolerance(dtype: torch.dtype) -> dict[str, float]:
    """``{"rtol": ..., "atol": ...}`` for ``dtype``, to splat into ``assert_close``.

    Example:
        >>> tolerance(torch.float64)
        {'rtol': 1e-10, 'atol': 1e-10}
    """
    rtol, atol = TOLERANCES[dtype]
    return {"rtol": rtol, "atol": atol}


def assert_close(actual, expected, *, scale: float = 1.0, **kwargs) -> None:
    """``torch.testing.assert_close`` with the dtype tolerance of ``actual``.

    ``scale`` multiplies both tolerances for ops that lose a few digits. Extra
    keyword arguments override the tolerances. ``expected`` may be a NumPy array
    or a tensor on another device or dtype; it is moved to ``actual``.

    Example:
        >>> assert_close(torch.tensor([1.0]), torch.tensor([1.0 + 1e-7]))
    """
    actual = torch.as_tensor(actual)
    if isinstance(expected, torch.Tensor):
        expected = expected.to(device=actual.device, dtype=actual.dtype)
    else:  # lists/arrays convert straight to the target dtype, without a float32 detour
        expected = torch.as_tensor(expected, dtype=actual.dtype, device=actual.device)
    tol = tolerance(actual.dtype) if actual.is_floating_point() else {"rtol": 0, "atol": 0}
    tol = {k: v * scale for k, v in tol.items()}
    tol.update(kwargs)
    torch.testing.assert_close(actual, expected, **tol)
