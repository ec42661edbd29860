"""The check of strictly increasing knots shared by the Hermite splines and the B-spline
interpolation (internals of :mod:`torchgeo_cg.curves.hermite`)."""

from __future__ import annotations

import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape

__all__ = ["check_knots"]


def check_knots(knots: torch.Tensor, name: str = "knots") -> dict:
    """Check that knots are a float ``(*, K)`` tensor, ``K >= 2``, strictly increasing.

    Args:
        knots: ``(*, K)``.
        name: argument name for messages.

    Returns:
        The bound sizes (``{"K": K, "*": batch}``).

    Raises:
        ShapeError: fewer than 2 knots.
        ValueError: not strictly increasing (or NaN); names the first offending index.

    Example:
        >>> check_knots(torch.tensor([0.0, 1.0, 1.0, 2.0]))
        Traceback (most recent call last):
        ...
        ValueError: knots: must be strictly increasing, but knots[..., 2] = 1.0 is not ...
    """
    check_float(knots, name, low_precision=False)
    sizes = check_shape(knots, ["*", "K"], name)
    if sizes["K"] < 2:
        raise ShapeError(f"{name}: expected at least 2 knots, got shape {tuple(knots.shape)}")
    bad = ~(knots[..., 1:] > knots[..., :-1])  # (*, K - 1); NaN counts as bad
    if bool(bad.any()):
        flat = bad.reshape(-1, bad.shape[-1])
        column = int(flat.any(0).nonzero()[0, 0])
        row = int(flat[:, column].nonzero()[0, 0])
        k = knots.reshape(-1, knots.shape[-1])[row]
        raise ValueError(
            f"{name}: must be strictly increasing, but {name}[..., {column + 1}] = "
            f"{float(k[column + 1])} is not greater than {name}[..., {column}] = {float(k[column])}"
        )
    return sizes
