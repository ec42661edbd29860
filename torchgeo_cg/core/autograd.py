"""The one answer to "does autograd record this call?".

Fast paths (writing in place, a compiled kernel, a chunked loop, skipping a custom
derivative) are only valid when nothing will differentiate through the call. Every
such decision in torchgeo_cg asks :func:`records_graph`, so the three ways a call can
be differentiated are all seen, everywhere the same:

- reverse mode: grad mode is on and a tensor requires grad;
- forward mode: a tensor is a dual tensor of ``torch.autograd.forward_ad`` (with
  or without grad mode);
- ``torch.func`` transforms (``vmap``, ``grad``, ``jvp``, ...): the tensors are
  wrappers whose flags do not tell, so any active transform counts.

This module is the only place that calls a private torch function (the functorch
query, for which torch has no public spelling).
"""

from __future__ import annotations

import torch
from torch.autograd import forward_ad

__all__ = ["is_transform_wrapped", "records_graph"]


def _transforms_active() -> bool:
    query = getattr(torch._C, "_are_functorch_transforms_active", None)
    return True if query is None else bool(query())  # unknown torch: assume a transform


def _forward_mode(tensors) -> bool:
    if getattr(forward_ad, "_current_level", 0) < 0:  # no dual level entered: no tangents
        return False
    return any(forward_ad.unpack_dual(t).tangent is not None for t in tensors)


def records_graph(*tensors: torch.Tensor | None) -> bool:
    """Whether autograd records a computation on ``tensors`` (so no fast path may skip it).

    True when grad mode is on and any tensor requires grad, when any tensor carries a
    forward-mode tangent, or when a ``torch.func`` transform is active (then always, with
    or without tensors). ``None`` entries are ignored, so optional arguments can be
    passed as they are. Under ``torch.compile`` only the first case is asked (the
    compiler handles the others itself).

    Args:
        *tensors: the differentiable inputs of the call (tensors or ``None``).

    Returns:
        ``bool``.

    Example:
        >>> x = torch.ones(3, requires_grad=True)
        >>> records_graph(x), records_graph(x.detach()), records_graph(None, x)
        (True, False, True)
        >>> with torch.no_grad():
        ...     records_graph(x)
        False
        >>> import torch.autograd.forward_ad as fwAD
        >>> with fwAD.dual_level():
        ...     records_graph(fwAD.make_dual(torch.ones(3), torch.ones(3)))
        True
        >>> torch.func.vmap(lambda t: torch.tensor(records_graph(t)))(torch.ones(2))
        tensor([True, True])
    """
    present = [t for t in tensors if t is not None]
    if torch.is_grad_enabled() and any(t.requires_grad for t in present):
        return True
    if torch.compiler.is_compiling():
        return False
    return _transforms_active() or _forward_mode(present)


def is_transform_wrapped(tensor: torch.Tensor) -> bool:
    """Whether ``tensor`` is a ``torch.func`` wrapper (inside ``vmap``, ``grad``,
    ``jacrev``...), whose storage a compiled kernel cannot read.

    Args:
        tensor: any tensor.

    Returns:
        ``bool``.

    Example:
        >>> is_transform_wrapped(torch.zeros(3))
        False
        >>> torch.func.vmap(lambda x: torch.tensor(is_transform_wrapped(x)))(torch.zeros(2))
        tensor([True, True])
    """
    query = getattr(getattr(torch._C, "_functorch", None), "is_functorch_wrapped_tensor", None)
    return _transforms_active() if query is None else bool(query(tensor))
