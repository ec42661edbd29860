"""Suite-wide fixtures: every test asking for ``device``/``dtype`` runs over all of them."""

from __future__ import annotations

import os

import pytest
import torch
from hypothesis import HealthCheck, settings

from torchgeo_cg.core.testing import DTYPES, available_devices, tolerance

settings.register_profile(
    "ci", max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture(params=available_devices())
def device(request) -> torch.device:
    return torch.device(request.param)


@pytest.fixture(params=DTYPES, ids=lambda d: str(d).replace("torch.", ""))
def dtype(request) -> torch.dtype:
    return request.param


@pytest.fixture
def tol(dtype) -> dict[str, float]:
    """``{"rtol", "atol"}`` for the current dtype."""
    return tolerance(dtype)
