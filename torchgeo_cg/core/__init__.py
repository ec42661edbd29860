"""Core helpers: the validation helper, scale-safe numerics, coercion and test support."""

from torchgeo_cg.core.check import (
    ShapeError,
    check_broadcastable,
    check_float,
    check_shape,
    check_tensor,
)
from torchgeo_cg.core.coerce import as_tensor_like, check_module_dtype, check_same_dtype
from torchgeo_cg.core.numerics import (
    cast_back,
    clamp_away_from_zero,
    hypot,
    safe_div,
    safe_norm,
    safe_sqrt,
    working_dtype,
)

__all__ = [
    "ShapeError",
    "as_tensor_like",
    "cast_back",
    "check_broadcastable",
    "check_float",
    "check_module_dtype",
    "check_same_dtype",
    "check_shape",
    "check_tensor",
    "clamp_away_from_zero",
    "hypot",
    "safe_div",
    "safe_norm",
    "safe_sqrt",
    "working_dtype",
]
