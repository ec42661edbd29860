"""Core helpers: the validation helper, NaN-free numerics and test support."""

from torchgeo_cg.core.check import (
    ShapeError,
    check_broadcastable,
    check_float,
    check_shape,
    check_tensor,
)
from torchgeo_cg.core.numerics import clamp_away_from_zero, safe_div, safe_norm, safe_sqrt

__all__ = [
    "ShapeError",
    "check_broadcastable",
    "check_float",
    "check_shape",
    "check_tensor",
    "clamp_away_from_zero",
    "safe_div",
    "safe_norm",
    "safe_sqrt",
]
