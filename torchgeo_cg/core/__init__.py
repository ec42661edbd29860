"""Core helpers: the validation helper, scale-safe numerics, coercion, THE grid convention
(:mod:`torchgeo_cg.core.grid`), the autograd question (:func:`records_graph`) and test
support."""

from torchgeo_cg.core.autograd import is_transform_wrapped, records_graph
from torchgeo_cg.core.check import (
    ShapeError,
    check_broadcastable,
    check_choice,
    check_float,
    check_generator,
    check_shape,
    check_tensor,
)
from torchgeo_cg.core.coerce import as_tensor_like, check_module_dtype, check_same_dtype
from torchgeo_cg.core.grid import Volume, check_spacing, index_to_world, world_to_index
from torchgeo_cg.core.numerics import (
    cast_back,
    clamp_away_from_zero,
    hypot,
    power_of_two_scale,
    safe_div,
    safe_norm,
    safe_sqrt,
    working_dtype,
)

__all__ = [
    "ShapeError",
    "Volume",
    "as_tensor_like",
    "cast_back",
    "check_broadcastable",
    "check_choice",
    "check_generator",
    "check_float",
    "check_module_dtype",
    "check_same_dtype",
    "check_shape",
    "check_spacing",
    "check_tensor",
    "clamp_away_from_zero",
    "hypot",
    "index_to_world",
    "is_transform_wrapped",
    "power_of_two_scale",
    "records_graph",
    "safe_div",
    "safe_norm",
    "safe_sqrt",
    "working_dtype",
    "world_to_index",
]
