"""The one validation helper of torchgeo_cg.

Every public function checks its tensor arguments with :func:`check_shape` (and
:func:`check_float` where floats are needed) instead of ``assert``, so the checks
survive ``python -O`` and the message always names the argument, the expected
shape and the shape that was received.

Shape patterns are sequences of tokens:

- ``"*"`` (first token only): any number of leading batch dimensions, possibly none;
- an ``int`` or a digit string such as ``"3"``: that exact size;
- any other string such as ``"N"``: a named size, which must agree wherever the
  same name appears (in this call and in the ``sizes`` mapping passed in).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

import torch

__all__ = [
    "ShapeError",
    "check_shape",
    "check_float",
    "check_tensor",
    "check_broadcastable",
    "check_choice",
    "check_generator",
    "format_shape",
]


class ShapeError(ValueError):
    """Raised when a tensor argument has the wrong shape or rank.

    Subclasses :class:`ValueError`, so ``except ValueError`` catches it too.
    """


def format_shape(shape: Sequence[object]) -> str:
    """Format a shape or pattern as ``(*, N, 2)``.

    Example:
        >>> format_shape(["*", "N", 2])
        '(*, N, 2)'
        >>> format_shape(torch.Size([4, 3]))
        '(4, 3)'
    """
    return "(" + ", ".join(str(s) for s in shape) + ")"


def check_tensor(x: object, name: str) -> torch.Tensor:
    """Raise ``TypeError`` naming ``name`` unless ``x`` is a :class:`torch.Tensor`.

    Example:
        >>> check_tensor([1.0, 2.0], "points")
        Traceback (most recent call last):
        ...
        TypeError: points: expected a torch.Tensor, got list
    """
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    return x


def check_float(x: torch.Tensor, name: str, low_precision: bool = True) -> torch.Tensor:
    """Raise ``TypeError`` unless ``x`` is a floating-point tensor.

    Args:
        x: the tensor to check.
        name: the argument name used in the error message.
        low_precision: accept float16/bfloat16 (default). Ops whose dtype policy
            rejects them pass ``False`` and get a ``TypeError`` that says so.

    Example:
        >>> check_float(torch.zeros(2, dtype=torch.long), "offset")
        Traceback (most recent call last):
        ...
        TypeError: offset: expected a floating-point tensor, got dtype torch.int64
        >>> check_float(torch.zeros(2, dtype=torch.float16), "t", low_precision=False)
        Traceback (most recent call last):
        ...
        TypeError: t: torch.float16 is not supported here (too few digits); use float32 or ...
    """
    check_tensor(x, name)
    if not x.is_floating_point():
        raise TypeError(f"{name}: expected a floating-point tensor, got dtype {x.dtype}")
    if not low_precision and x.dtype in (torch.float16, torch.bfloat16):
        raise TypeError(f"{name}: {x.dtype} is not supported here (too few digits); use "
                        "float32 or float64")
    return x


def check_shape(
    x: torch.Tensor,
    shape: Sequence[str | int],
    name: str,
    sizes: Mapping[str, int] | None = None,
) -> dict[str, object]:
    """Check ``x`` against a shape pattern and return the bound sizes.

    Args:
        x: the tensor to check.
        shape: the pattern, e.g. ``["*", "N", "2"]``; ``"*"`` may only come first.
        name: the argument name used in the error message.
        sizes: sizes already bound by earlier checks, e.g. ``{"N": 5}``.

    Returns:
        A dict mapping each named token to its size, plus ``"*"`` to the tuple of
        leading batch dimensions when the pattern starts with ``"*"``. Sizes from
        ``sizes`` are included, so the result can be passed on to the next check.

    Raises:
        TypeError: ``x`` is not a tensor.
        ShapeError: the rank or a size does not match.

    Example:
        >>> pts = torch.zeros(4, 10, 2)
        >>> check_shape(pts, ["*", "N", "2"], "points")
        {'N': 10, '*': (4,)}
        >>> check_shape(pts, ["*", "N", "3"], "points")
        Traceback (most recent call last):
        ...
        torchgeo_cg.core.check.ShapeError: points: expected shape (*, N, 3), got (4, 10, 2)
    """
    check_tensor(x, name)
    pattern = list(shape)
    bound: dict[str, object] = dict(sizes or {})
    got = tuple(x.shape)
    star = len(pattern) > 0 and pattern[0] == "*"
    if "*" in pattern[1:]:
        raise ValueError(f"check_shape: '*' may only be the first token, got {pattern}")
    fixed = pattern[1:] if star else pattern

    def fail(reason: str = "") -> ShapeError:
        extra = f" ({reason})" if reason else ""
        return ShapeError(
            f"{name}: expected shape {format_shape(pattern)}, got {format_shape(got)}{extra}"
        )

    if (star and len(got) < len(fixed)) or (not star and len(got) != len(fixed)):
        raise fail()
    tail = got[len(got) - len(fixed) :] if fixed else ()
    for token, size in zip(fixed, tail):
        if isinstance(token, int) or (isinstance(token, str) and token.isdigit()):
            if size != int(token):
                raise fail()
        else:
            seen = bound.get(token)
            if seen is not None and seen != size:
                raise fail(f"{token}={size} but {token}={seen} elsewhere")
            bound[token] = size
    if star:
        bound["*"] = got[: len(got) - len(fixed)]
    return bound


def check_broadcastable(batches: Mapping[str, Sequence[int]]) -> tuple[int, ...]:
    """Broadcast the batch shapes of several arguments, or name the ones that clash.

    Args:
        batches: argument name -> its batch shape (e.g. ``x.shape[:-2]``).

    Returns:
        The broadcast batch shape.

    Raises:
        ShapeError: the batch shapes do not broadcast; the message names the arguments.

    Example:
        >>> check_broadcastable({"matrix": (4, 1), "points": (3,)})
        (4, 3)
        >>> check_broadcastable({"matrix": (4,), "points": (3,)})
        Traceback (most recent call last):
        ...
        torchgeo_cg.core.check.ShapeError: batch dims do not broadcast: matrix (4), points (3)
    """
    try:
        return tuple(torch.broadcast_shapes(*(tuple(b) for b in batches.values())))
    except RuntimeError:
        listed = ", ".join(f"{name} {format_shape(tuple(b))}" for name, b in batches.items())
        raise ShapeError(f"batch dims do not broadcast: {listed}") from None


def check_choice(value: object, choices: Collection, name: str) -> object:
    """Raise ``ValueError`` naming ``name`` and the accepted values unless ``value`` is one of them.

    Args:
        value: the argument received.
        choices: the accepted values (a tuple, list, dict's keys or set; sets are listed
            sorted).
        name: the argument name used in the error message.

    Returns:
        ``value``, unchanged.

    Example:
        >>> check_choice("mean", ("mean", "sum", "none"), "reduction")
        'mean'
        >>> check_choice("avg", ("mean", "sum", "none"), "reduction")
        Traceback (most recent call last):
        ...
        ValueError: reduction: expected one of 'mean', 'sum', 'none', got 'avg'
    """
    try:
        found = value in choices
    except TypeError:  # an unhashable value tested against a set or dict
        found = False
    if not found:
        ordered = sorted(choices) if isinstance(choices, (set, frozenset)) else list(choices)
        listed = ", ".join(repr(c) for c in ordered)
        raise ValueError(f"{name}: expected one of {listed}, got {value!r}")
    return value


def check_generator(generator: object, name: str = "generator", device: str | torch.device = "cpu"
                    ) -> torch.Generator:
    """Raise unless ``generator`` is a :class:`torch.Generator` on ``device``.

    Args:
        generator: the argument received.
        name: the argument name used in the error message.
        device: the device the draws are made on.

    Returns:
        ``generator``, unchanged.

    Raises:
        TypeError: ``generator`` is not a ``torch.Generator``.
        ValueError: it lives on another device.

    Example:
        >>> check_generator(torch.Generator()).device
        device(type='cpu')
        >>> check_generator(0)
        Traceback (most recent call last):
        ...
        TypeError: generator: expected a torch.Generator, got int
    """
    if not isinstance(generator, torch.Generator):
        raise TypeError(f"{name}: expected a torch.Generator, got {type(generator).__name__}")
    if generator.device.type != torch.device(device).type:
        raise ValueError(f"{name}: expected a generator on {torch.device(device).type}, "
                         f"got one on {generator.device}")
    return generator
