"""The one coercion helper: numbers, numpy and tensors become tensors like a reference.

Every public function that accepts "a number or a tensor" for an argument calls
:func:`as_tensor_like`, so the rules and the error messages are the same
everywhere:

- Python numbers (``int``, ``float``), numpy scalars of any real kind
  (``np.float32``, ``np.int64``, ...), numpy arrays and (nested) lists of numbers
  become tensors of the reference's dtype and device (the default dtype on the
  CPU when there is no reference; numpy floating values then keep their own
  float dtype).
- ``bool`` values and anything non-numeric raise ``TypeError`` naming the argument.
- Tensors are never silently converted from integers: an integer or bool tensor
  raises ``TypeError``. A float tensor of another dtype or device than the
  reference either raises ``TypeError`` naming both arguments (``cast=False``, the
  default) or is moved to the reference's dtype and device (``cast=True``, for
  parameters that follow the main input, e.g. SDF radii follow the points).
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping

import numpy as np
import torch

__all__ = ["as_tensor_like", "check_module_dtype", "check_same_dtype"]


def _describe(x: torch.Tensor) -> str:
    return f"{x.dtype} on {x.device}"


def _numeric_array(value: object, name: str) -> np.ndarray:
    """``value`` as a numpy array of real numbers, or a ``TypeError`` naming ``name``."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name}: expected a float tensor or a number, got bool")
    if isinstance(value, (numbers.Real, np.ndarray, np.generic, list, tuple)):
        try:
            array = np.asarray(value)
        except (TypeError, ValueError):
            array = None
        if array is not None and array.dtype.kind in "iuf":
            return array
    raise TypeError(
        f"{name}: expected a float tensor or a number, got {type(value).__name__}"
        + (f" {value!r}" if isinstance(value, (list, tuple, np.ndarray)) else "")
    )


def as_tensor_like(
    value: object,
    like: torch.Tensor | None,
    name: str,
    *,
    like_name: str | None = None,
    cast: bool = False,
) -> torch.Tensor:
    """``value`` as a float tensor with the dtype and device of ``like``.

    Args:
        value: a float tensor, a Python or numpy number, a numpy array, or a
            (nested) list/tuple of numbers.
        like: the reference tensor (dtype and device), or ``None`` for the default
            dtype on the CPU (numpy floating values then keep their float dtype).
        name: the argument's name, used in every error message.
        like_name: the reference argument's name, for the mixed-dtype message.
        cast: move a float tensor of another dtype/device to ``like``'s instead of
            raising (gradients flow through the cast).

    Returns:
        A tensor (the same object when ``value`` is already a matching tensor).

    Raises:
        TypeError: ``value`` is a bool, non-numeric, an integer/bool tensor, or (with
            ``cast=False``) a float tensor whose dtype or device differs from ``like``.

    Example:
        >>> import numpy as np
        >>> ref = torch.zeros(2, dtype=torch.float64)
        >>> as_tensor_like(np.float32(1.5), ref, "angle")
        tensor(1.5000, dtype=torch.float64)
        >>> as_tensor_like(np.int64(90), None, "angle")
        tensor(90.)
        >>> as_tensor_like(torch.ones(2), ref, "scale", like_name="offset")
        Traceback (most recent call last):
        ...
        TypeError: scale is torch.float32 on cpu but offset is torch.float64 on cpu; ...
        >>> as_tensor_like(True, ref, "radius")
        Traceback (most recent call last):
        ...
        TypeError: radius: expected a float tensor or a number, got bool
    """
    if isinstance(value, torch.Tensor):
        if not value.is_floating_point():
            raise TypeError(f"{name}: expected a floating-point tensor, got dtype {value.dtype}")
        if like is None or (value.dtype == like.dtype and value.device == like.device):
            return value
        if cast:
            return value.to(dtype=like.dtype, device=like.device)
        other = like_name or "the reference"
        raise TypeError(
            f"{name} is {_describe(value)} but {other} is {_describe(like)}; "
            "convert one with .to()"
        )
    if like is not None and type(value) in (float, int):  # the common case, fast
        return torch.tensor(float(value), dtype=like.dtype, device=like.device)
    array = _numeric_array(value, name)
    if like is not None:
        return torch.as_tensor(array, dtype=like.dtype, device=like.device)
    if array.dtype.kind == "f" and isinstance(value, (np.ndarray, np.generic)):
        return torch.as_tensor(array)
    return torch.as_tensor(array, dtype=torch.get_default_dtype())


def check_same_dtype(tensors: Mapping[str, torch.Tensor]) -> torch.Tensor:
    """Raise ``TypeError`` naming two arguments unless all share one dtype and device.

    Args:
        tensors: argument name -> tensor, in the order they are reported.

    Returns:
        The first tensor (a reference for what follows).

    Example:
        >>> check_same_dtype({"matrices[0]": torch.eye(3), "matrices[1]": torch.eye(3).double()})
        Traceback (most recent call last):
        ...
        TypeError: matrices[1] is torch.float64 on cpu but matrices[0] is torch.float32 ...
    """
    items = list(tensors.items())
    first_name, first = items[0]
    for name, x in items[1:]:
        if x.dtype != first.dtype or x.device != first.device:
            raise TypeError(
                f"{name} is {_describe(x)} but {first_name} is {_describe(first)}; "
                "convert one with .to()"
            )
    return first


def check_module_dtype(module: torch.nn.Module, x: torch.Tensor, name: str,
                       exclude: tuple[str, ...] = ()) -> None:
    """Raise ``TypeError`` unless the module's own floating state has the dtype of ``x``.

    The rule of every public module: its parameters and buffers (``recurse=False``:
    submodules check their own inputs) and a floating input must share one dtype, as
    :class:`torch.nn.Linear` requires; nothing is cast silently in either direction.
    Convert the module (``.to(dtype)``, ``.double()``) or the input. Non-floating
    inputs are left to the function's own checks. float16, bfloat16 and float32 meet each
    other, as the low-precision dtypes are computed in float32.

    Args:
        module: the module whose parameters and buffers are checked.
        x: its input.
        name: the input's name in the message.
        exclude: prefixes of state names not mixed with the input (e.g. topology
            parameters that only built the module's operators).

    Example:
        >>> lin = torch.nn.Module()
        >>> lin.register_buffer("scale", torch.ones(2, dtype=torch.float64))
        >>> check_module_dtype(lin, torch.ones(2, dtype=torch.float64), "points")
        >>> check_module_dtype(lin, torch.ones(2), "points")
        Traceback (most recent call last):
        ...
        TypeError: points is torch.float32 but Module.scale is torch.float64; convert the module ...
    """
    if not isinstance(x, torch.Tensor) or not x.is_floating_point():
        return
    for state, tensor in (*module.named_parameters(recurse=False),
                          *module.named_buffers(recurse=False)):
        low = {x.dtype, tensor.dtype} <= {torch.float16, torch.bfloat16, torch.float32}
        if (not tensor.is_floating_point() or tensor.dtype == x.dtype or low
                or state.startswith(exclude)):
            continue
        raise TypeError(f"{name} is {x.dtype} but {type(module).__name__}.{state} is "
                        f"{tensor.dtype}; convert the module (.to({x.dtype})) or the "
                        f"input (.to({tensor.dtype}))")
