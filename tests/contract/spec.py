"""The vocabulary of the API contract: inputs (:class:`Arg`), entries (:class:`Entry`),
scaling laws and input generators.

Each :class:`Entry` says how to call one public callable on tensors (``call``), how
to generate valid tensor inputs (``args``: name, shape, generator, scaling law) and
how its output scales when every length in the inputs is multiplied by ``s``
(``out``). ``test_contract.py`` turns every entry of ``table.TABLE`` into the
generated tests.

Scaling laws (``LAWS``): ``"length"`` x s, ``"unitless"`` x 1, ``"inv_length"`` / s,
``"area"`` x s^2, ``"area2"`` x s^4, ``"volume"`` x s^3, ``"matrix"`` conjugation
``S M S^-1`` of a homogeneous 3x3 (translation x s, perspective row / s), ``"h8"`` the
8 free entries of a homography (same conjugation), ``"index"`` (integers, unchanged)
and ``None`` (not compared).

Generators: a name of :data:`GENERATORS` or a callable ``gen(shape, generator,
dtype) -> float64 tensor`` (an area's own, e.g. correspondences of a known homography).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import torch

__all__ = ["Arg", "Entry", "GENERATORS", "LAWS", "apply_law", "generate"]


@dataclass(frozen=True)
class Arg:
    """One tensor input: its name (as in error messages), shape, generator and law."""

    name: str
    shape: tuple[int, ...]
    gen: str | Callable = "normal"
    law: str | None = "length"


@dataclass
class Entry:
    """One public callable under contract.

    Attributes:
        name: ``"<subpackage>.<public name>"`` (a suffix ``[...]`` marks a variant).
        call: ``call(*tensors)`` calls the public callable with the tensors of ``args``.
        args: the tensor inputs; ``args[0]`` is the primary one (NaN, empty, int tests).
        out: output law, or a tuple of laws for a NamedTuple/tuple result.
        empty: ``(arg index, dim)`` set to size 0 for the empty-input test; ``None``
            skips it (e.g. a closed-form matrix builder without a point dimension).
        empty_scalar: the result of empty input is a scalar 0 (a reduction).
        bad: wrong shapes for ``args[bad_arg]``: each must raise ``ShapeError`` naming it.
        mixed: ``"raise"`` (TypeError naming both), ``"promote"`` (result float64),
            ``("follow", i)`` (result has the dtype of ``args[i]``) or ``None`` (n/a).
        low: float16/bfloat16 policy: ``"compute32"`` (same dtype out, close to the
            float32 result) or ``"reject"`` (TypeError).
        nan: ``"propagate"`` (NaN in the primary gives NaN out) or ``"raise"``
            (ValueError: the argument must be finite, e.g. strictly increasing knots).
        int_ok: integer tensors are valid for ``args[0]`` (e.g. grid indices).
        rtol: relative tolerance of the scale test in float64 (float32: 1e-4 x ``rtol32``).
        cross: why the cross-argument cases (a leading batch on every argument, sizes
            that do not broadcast, an empty batch in one argument) do not apply, e.g. a
            ``call`` that turns a tensor into Python numbers; ``None``: they apply.
    """

    name: str
    call: Callable
    args: tuple[Arg, ...]
    out: str | tuple | None = "length"
    empty: tuple[int, int] | None = (0, -2)
    empty_scalar: bool = False
    bad: tuple[tuple[int, ...], ...] = ()
    bad_arg: int = 0
    mixed: object = "raise"
    low: str = "compute32"
    nan: str = "propagate"
    int_ok: bool = False
    rtol: float = 1e-9
    rtol32: float = 1.0
    cross: str | None = None
    extra: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- laws


def _conjugate(m: torch.Tensor, s: float) -> torch.Tensor:
    d = m.shape[-1] - 1  # 3x3 (2D) or 4x4 (3D) homogeneous matrices
    out = m.clone()
    out[..., :d, d] = out[..., :d, d] * s
    out[..., d, :d] = out[..., d, :d] / s
    return out


def _h8(h: torch.Tensor, s: float) -> torch.Tensor:
    out = h.clone()
    out[..., [2, 5]] = out[..., [2, 5]] * s
    out[..., [6, 7]] = out[..., [6, 7]] / s
    return out


LAWS: dict[str, Callable[[torch.Tensor, float], torch.Tensor]] = {
    "length": lambda x, s: x * s,
    "unitless": lambda x, s: x,
    "index": lambda x, s: x,
    "inv_length": lambda x, s: x / s,
    "area": lambda x, s: x * (s * s),
    "area2": lambda x, s: x * (s * s) * (s * s),
    "volume": lambda x, s: x * (s * s * s),
    "matrix": _conjugate,
    "h8": _h8,
}


def apply_law(law, value, s: float):
    """Scale ``value`` (a tensor or a tuple of tensors) by ``law`` (or a tuple of laws)."""
    if law is None:
        return value
    if isinstance(law, tuple):
        return tuple(apply_law(w, v, s) for w, v in zip(law, value))
    return LAWS[law](value, s)


# ----------------------------------------------------------------------------- inputs


def _rotation(shape, g, dtype):
    d = shape[-1]
    q, r = torch.linalg.qr(torch.randn(shape, generator=g, dtype=torch.float64))
    q = q * torch.sign(torch.diagonal(r, dim1=-2, dim2=-1))[..., None, :]
    flip = torch.linalg.det(q) < 0
    q[..., :, 0] = torch.where(flip[..., None], -q[..., :, 0], q[..., :, 0])
    return (q.to(dtype) if d else q).contiguous()  # NaN injection writes through reshape


def _homography(shape, g, dtype):
    m = torch.eye(3, dtype=torch.float64).expand(*shape).clone()
    m = m + 0.2 * torch.randn(shape, generator=g, dtype=torch.float64)
    m[..., 2, :2] = 0.02 * torch.randn(*shape[:-2], 2, generator=g, dtype=torch.float64)
    m[..., 2, 2] = 1.0
    m[..., :2, 2] = 3 * torch.randn(*shape[:-2], 2, generator=g, dtype=torch.float64)
    return m


def _affine(shape, g, dtype):
    m = _homography(shape, g, dtype)
    m[..., 2, :2] = 0.0
    return m


GENERATORS: dict[str, Callable] = {
    "normal": lambda shape, g, dt: torch.randn(shape, generator=g, dtype=torch.float64),
    "positive": lambda shape, g, dt: 0.5 + torch.rand(shape, generator=g, dtype=torch.float64),
    "small_positive": lambda shape, g, dt: 0.1
    + 0.2 * torch.rand(shape, generator=g, dtype=torch.float64),
    "t01": lambda shape, g, dt: torch.rand(shape, generator=g, dtype=torch.float64),
    "angle": lambda shape, g, dt: 170 * (2 * torch.rand(shape, generator=g,
                                                        dtype=torch.float64) - 1),
    "increasing": lambda shape, g, dt: (0.2 + torch.rand(shape, generator=g,
                                                         dtype=torch.float64)).cumsum(-1),
    "inside": lambda shape, g, dt: 0.05 + 0.9 * torch.rand(shape, generator=g,
                                                           dtype=torch.float64),
    "rotation": _rotation,
    "bounds": lambda shape, g, dt: torch.randn(3, generator=g, dtype=torch.float64)
    + torch.tensor([[0.0], [1.0]], dtype=torch.float64)
    * (0.5 + torch.rand(3, generator=g, dtype=torch.float64)),
    "homography": _homography,
    "affine": _affine,
    "index": lambda shape, g, dt: torch.randint(0, 4, shape, generator=g).double(),
    "unit_vector": lambda shape, g, dt: torch.nn.functional.normalize(
        torch.randn(shape, generator=g, dtype=torch.float64), dim=-1),
}


def generate(entry: Entry, seed: int) -> list[torch.Tensor]:
    """float64 inputs for ``entry`` from ``seed`` (callers cast them)."""
    g = torch.Generator().manual_seed(seed)
    gens = [a.gen if callable(a.gen) else GENERATORS[a.gen] for a in entry.args]
    return [gen(a.shape, g, torch.float64) for gen, a in zip(gens, entry.args)]
