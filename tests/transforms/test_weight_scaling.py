"""Relative weights are scaled by core.power_of_two_scale, the one power-of-two scaling."""

from __future__ import annotations

import torch

from torchgeo_cg.core import power_of_two_scale
from torchgeo_cg.transforms._correspondences import pow2_normalize


def test_weights_scale_exactly_at_every_magnitude():
    base = torch.tensor([[0.3, 1.0, 0.0, 0.7]], dtype=torch.float64)
    for s in (1e-300, 1e-30, 1.0, 1e30, 1e300):
        w = pow2_normalize(base * s, -1)
        assert float(w.amax()) >= 0.5 and float(w.amax()) < 1.0
        torch.testing.assert_close(w, base * s / power_of_two_scale(base.amax() * s),
                                   rtol=0, atol=0)
        torch.testing.assert_close(w / w.amax(), base, rtol=1e-15, atol=0)


def test_subnormal_and_special_weights():
    tiny = torch.tensor([1e-45, 5e-46], dtype=torch.float32)  # subnormal float32
    w = pow2_normalize(tiny, -1)
    assert torch.isfinite(w).all() and float(w.amax()) >= 0.5
    assert torch.equal(pow2_normalize(torch.zeros(3), -1), torch.zeros(3))
    nan = pow2_normalize(torch.tensor([1.0, float("nan")]), -1)
    assert torch.isnan(nan[1]) and nan[0] == 1.0
    assert torch.equal(pow2_normalize(torch.tensor([-1.0, 2.0]), -1), torch.tensor([0.0, 0.5]))
