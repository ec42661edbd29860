"""Two arguments whose batch shapes do not broadcast raise ``ShapeError`` naming both.

Each case calls a public function with two arguments that are valid alone but whose
leading (batch) dims clash; the error must name both arguments and their shapes,
never surface as a raw torch error. Shapes that are legal (one side of size 1, an
empty batch against a broadcastable one) must work.
"""

from __future__ import annotations

import re

import pytest
import torch

from torchgeo_cg.core import ShapeError, safe_div

F64 = torch.float64


def _raises_naming(call, *parts):
    with pytest.raises(ShapeError) as err:
        call()
    message = str(err.value)
    for part in parts:
        assert re.search(re.escape(part), message), (part, message)


def test_safe_div_mismatched_operands():
    _raises_naming(lambda: safe_div(torch.ones(3, dtype=F64), torch.ones(4, dtype=F64)),
                   "num (3)", "den (4)")
    _raises_naming(lambda: safe_div(torch.ones(3), torch.ones(4), eps=1e-8), "num", "den")
    out = safe_div(torch.ones(3, 1, dtype=F64), torch.full((4,), 2.0, dtype=F64))
    assert out.shape == (3, 4) and bool((out == 0.5).all())
