"""Generated contract tests: every entry of ``table.TABLE`` against every clause.

Clauses: scale equivariance (s in 1e-6..1e6 in float64, 1e-3 and 1e3 in float32),
NaN propagation, empty inputs, wrong shapes (``ShapeError`` naming the argument),
integer input (``TypeError``), mixed dtypes, float16/bfloat16 per the policy,
non-contiguous and expanded inputs (same result), no input mutated, batches across
arguments (sizes that do not broadcast raise ``ShapeError``; an empty batch in any one
argument gives empty out), and the completeness of the table over the public API.

The examples per property come from ``CONTRACT_EXAMPLES`` (see ``conftest.py``):
few under ``HYPOTHESIS_PROFILE=ci``, many under ``thorough``.
"""

from __future__ import annotations

import re

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.api_inventory import public_callables
from tests.contract.conftest import CONTRACT_EXAMPLES
from tests.contract.table import EXEMPT, TABLE, apply_law, generate
from torchgeo_cg.core.check import ShapeError

pytestmark = pytest.mark.usefixtures("one_thread")  # tiny inputs: threads only add overhead

F32, F64 = torch.float32, torch.float64
ENTRIES = {e.name: e for e in TABLE}
NAMES = list(ENTRIES)
SEEDS = st.integers(0, 2**20)


def _inputs(entry, seed: int, dtype=F64) -> list[torch.Tensor]:
    tensors = generate(entry, seed)
    return [t.to(dtype) for t in tensors]


def _leaves(out) -> list[torch.Tensor]:
    if isinstance(out, torch.Tensor):
        return [out]
    return [x for item in out for x in _leaves(item)]


def _empty_pairs(entry):
    spec = entry.empty
    return spec if isinstance(spec[0], tuple) else (spec,)


def _run(entry, tensors):
    return entry.call(*tensors)


# ----------------------------------------------------------------------------- scale


def _compare_scaled(got, want, rtol: float, where: str) -> None:
    if not want.is_floating_point():
        assert torch.equal(got, want), where
        return
    assert got.dtype == want.dtype and got.shape == want.shape, where
    assert torch.isfinite(got).all() and torch.isfinite(want).all(), f"{where}: non-finite"
    top = want.abs().amax() if want.numel() else want.new_zeros(())
    bound = rtol * (want.abs() + top)
    err = (got - want).abs()
    assert bool((err <= bound).all()), f"{where}: max err {float((err / (top + 1e-300)).max())}"
    clear = want.abs() > 2 * bound  # same signs wherever the sign is not within rounding
    assert torch.equal(torch.sign(got[clear]), torch.sign(want[clear])), f"{where}: signs"


SCALE_CASES = [(F64, s) for s in (1e-6, 1e-3, 1e3, 1e6)] + [(F32, s) for s in (1e-3, 1e3)]


@pytest.mark.parametrize("dtype, s", SCALE_CASES, ids=lambda v: str(v).replace("torch.", ""))
@pytest.mark.parametrize("name", NAMES)
def test_scale_equivariance(name, dtype, s):
    entry = ENTRIES[name]
    if entry.out is None:
        pytest.skip("no scaling law (a fixed-size child shape)")
    rtol = entry.rtol if dtype == F64 else 1e-4 * entry.rtol32

    @settings(max_examples=CONTRACT_EXAMPLES, deadline=None, database=None)
    @given(seed=SEEDS)
    def check(seed):
        base64 = _inputs(entry, seed)
        scaled64 = [apply_law(a.law, x, s) for a, x in zip(entry.args, base64)]
        base = _run(entry, [x.to(dtype) for x in base64])
        got = _run(entry, [x.to(dtype) for x in scaled64])
        want = apply_law(entry.out, base, s)
        if isinstance(entry.out, str):
            got, want = (got,), (want,)
        for i, (g, w) in enumerate(zip(_leaves(got), _leaves(want))):
            _compare_scaled(g, w, rtol, f"{name} output {i} at s={s}")

    check()


# ----------------------------------------------------------------------------- NaN, empty


@pytest.mark.parametrize("name", NAMES)
def test_nan_in_nan_out(name):
    entry = ENTRIES[name]
    tensors = _inputs(entry, 0)
    base = _leaves(_run(entry, tensors))
    assert all(torch.isfinite(x).all() for x in base if x.is_floating_point()), "NaN born"
    if entry.nan == "skip":
        pytest.skip("a selection: NaN samples are simply not selected")
    bad = tensors[0].clone()
    bad.reshape(-1)[0] = float("nan")
    tensors[0] = bad
    if entry.nan == "raise":
        with pytest.raises(ValueError, match=re.escape(entry.args[0].name[:2])):
            _run(entry, tensors)
        return
    out = _leaves(_run(entry, tensors))
    assert any(bool(torch.isnan(x).any()) for x in out if x.is_floating_point())


@pytest.mark.parametrize("name", NAMES)
def test_empty_in_empty_out(name):
    entry = ENTRIES[name]
    if entry.empty is None:
        pytest.skip("no point/batch dimension to empty")
    tensors = _inputs(entry, 1)
    for index, dim in _empty_pairs(entry):
        tensors[index] = tensors[index].narrow(dim, 0, 0)
    out = _leaves(_run(entry, tensors))
    assert all(not torch.isnan(x).any() for x in out if x.is_floating_point())
    if entry.empty_scalar:
        assert all(x.numel() == 1 and x.item() == 0 for x in out)
    else:
        assert any(x.numel() == 0 for x in out)


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("name", [n for n in NAMES if ENTRIES[n].bad])
def test_wrong_shape_raises_shape_error_naming_argument(name):
    entry = ENTRIES[name]
    arg = entry.args[entry.bad_arg]
    for shape in entry.bad:
        tensors = _inputs(entry, 2)
        tensors[entry.bad_arg] = torch.randn(shape, dtype=F64)
        with pytest.raises(ShapeError, match=re.escape(arg.name)):
            _run(entry, tensors)


@pytest.mark.parametrize("name", NAMES)
def test_integer_input(name):
    entry = ENTRIES[name]
    tensors = _inputs(entry, 3)
    tensors[0] = tensors[0].round().long()
    if entry.int_ok:
        assert all(x.is_floating_point() for x in _leaves(_run(entry, tensors)))
        return
    with pytest.raises(TypeError, match=re.escape(entry.args[0].name[:2])):
        _run(entry, tensors)


@pytest.mark.parametrize("name", [n for n in NAMES if ENTRIES[n].mixed is not None
                                  and len(ENTRIES[n].args) > 1])
def test_mixed_dtypes(name):
    entry = ENTRIES[name]
    tensors = _inputs(entry, 4)
    tensors[1] = tensors[1].to(F32)
    if entry.mixed == "raise":
        with pytest.raises(TypeError) as err:
            _run(entry, tensors)
        message = str(err.value)
        assert entry.args[1].name in message and "float32" in message and "float64" in message
        assert any(a.name in message for i, a in enumerate(entry.args) if i != 1), message
        return
    want = F64 if entry.mixed == "promote" else tensors[entry.mixed[1]].dtype
    out = _leaves(_run(entry, tensors))
    assert all(x.dtype == want for x in out if x.is_floating_point())


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16], ids=["float16", "bfloat16"])
@pytest.mark.parametrize("name", NAMES)
def test_low_precision_policy(name, low):
    entry = ENTRIES[name]
    tensors = [x.to(low) for x in _inputs(entry, 5, F32)]
    if entry.low == "reject":
        with pytest.raises(TypeError, match="not supported"):
            _run(entry, tensors)
        return
    out = _leaves(_run(entry, tensors))
    ref = _leaves(_run(entry, [x.to(F32) for x in tensors]))
    for o, r in zip(out, ref):
        if not r.is_floating_point():
            continue
        assert o.dtype == low
        assert torch.isfinite(o).all()
        top = float(r.abs().amax()) if r.numel() else 0.0
        torch.testing.assert_close(o.to(F32), r, rtol=3e-2, atol=3e-2 * top + 1e-3)


# ----------------------------------------------------------------------------- batches


CROSS = [n for n in NAMES if len(ENTRIES[n].args) > 1 and ENTRIES[n].cross is None]


def _lead(x: torch.Tensor, size: int, ones: int) -> torch.Tensor:
    """``x`` with new leading dims ``(size, 1, ..., 1)`` (``ones`` ones)."""
    return x.reshape((1,) * (ones + 1) + x.shape).expand((size,) + (1,) * ones + x.shape)


def _names_an_argument(entry, message: str) -> bool:
    return any(a.name in message for a in entry.args)


def _alignments(count: int):
    """``(i, j, a, b)``: argument i gets leading ``(3, 1^a)``, argument j ``(2, 1^b)``.

    The table does not say how many leading dims of each argument are batch dims, so
    every relative offset up to 2 is tried: where the 3 and the 2 line up the batches
    do not broadcast, elsewhere they do.
    """
    offsets = [(0, 0), (1, 0), (2, 0), (0, 1), (0, 2)]
    return [(i, j, a, b) for i in range(count) for j in range(count) if i != j
            for a, b in offsets]


@pytest.mark.parametrize("name", CROSS)
def test_batches_that_do_not_broadcast_raise_shape_error(name):
    """Two arguments with batches of 3 and 2: a ShapeError naming an argument where they
    line up (at least one offset), a result where they broadcast; never a raw error."""
    entry = ENTRIES[name]
    tensors = _inputs(entry, 7)
    refused: dict[tuple[int, int], int] = {}
    for i, j, a, b in _alignments(len(tensors)):
        batched = list(tensors)
        batched[i], batched[j] = _lead(tensors[i], 3, a), _lead(tensors[j], 2, b)
        try:
            out = _leaves(_run(entry, batched))
        except ShapeError as err:
            assert _names_an_argument(entry, str(err)), str(err)
            refused[i, j] = refused.get((i, j), 0) + 1
            continue
        assert any(3 in x.shape and 2 in x.shape for x in out), [x.shape for x in out]
    pairs = {(i, j) for i, j, _, _ in _alignments(len(tensors))}
    assert set(refused) == pairs, f"accepted batches of 3 and 2 at every offset: " \
                                  f"{sorted(pairs - set(refused))}"


@pytest.mark.parametrize("name", [n for n in NAMES if ENTRIES[n].cross is None])
def test_an_empty_batch_in_any_argument(name):
    """A leading empty dim on one argument: an empty result (the batches broadcast to an
    empty one), or a ShapeError naming an argument (that argument takes no further
    batch dim, or the 0 meets another argument's batch); never a raw error, never NaN."""
    entry = ENTRIES[name]
    tensors = _inputs(entry, 8)
    for i in range(len(tensors)):
        batched = list(tensors)
        batched[i] = tensors[i].unsqueeze(0)[:0]
        try:
            out = _leaves(_run(entry, batched))
        except ShapeError as err:
            assert _names_an_argument(entry, str(err)), str(err)
            continue
        assert all(not torch.isnan(x).any() for x in out if x.is_floating_point())
        if entry.empty_scalar:  # a reduction over nothing
            assert all(x.numel() == 1 and x.item() == 0 for x in out)
        else:
            assert any(x.numel() == 0 for x in out), f"argument {i}: {[x.shape for x in out]}"


# ----------------------------------------------------------------------------- layouts


def _strided(x: torch.Tensor) -> torch.Tensor:
    """The same values with every stride doubled (never contiguous)."""
    out = torch.empty(*x.shape, 2, dtype=x.dtype)[..., 0]
    out.copy_(x)
    return out


@pytest.mark.parametrize("name", NAMES)
def test_noncontiguous_expanded_and_no_mutation(name):
    entry = ENTRIES[name]
    tensors = _inputs(entry, 6)
    clones = [x.clone() for x in tensors]
    ref = _leaves(_run(entry, tensors))
    for x, c in zip(tensors, clones):
        assert torch.equal(x, c), "an input was modified in place"
    for i, x in enumerate(tensors):
        if x.dim() == 0:
            continue
        others = list(tensors)
        others[i] = _strided(x)
        assert not others[i].is_contiguous() or x.numel() <= 1
        for o, r in zip(_leaves(_run(entry, others)), ref):
            torch.testing.assert_close(o, r, rtol=1e-12, atol=1e-12)
        ordered = entry.args[i].gen in ("bounds", "increasing")  # rows must differ
        if x.dim() >= 2 and x.shape[0] >= 2 and not ordered:  # stride-0 dim == its copy
            others[i] = x[:1].expand_as(x)
            expanded = _leaves(_run(entry, others))
            others[i] = others[i].contiguous()
            for o, r in zip(expanded, _leaves(_run(entry, others))):
                torch.testing.assert_close(o, r, rtol=1e-12, atol=1e-12)


# ----------------------------------------------------------------------------- completeness


def test_every_public_callable_is_under_contract_or_exempt():
    public = public_callables()  # from tests/api_inventory.py
    covered = {e.name.split("[")[0] for e in TABLE}
    missing = sorted(public - covered - set(EXEMPT))
    assert missing == [], f"add these to a tests/contract/table_*.py (ENTRIES or EXEMPT): {missing}"
    stale = sorted((covered | set(EXEMPT)) - public)
    assert stale == [], f"not public (any more): {stale}"
    assert not covered & set(EXEMPT), "a name cannot be both covered and exempt"
