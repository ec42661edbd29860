"""Contract entries of transforms in 3D: rotations, 3D estimation, joints and robust losses.

``ENTRIES`` join ``table.TABLE``; ``PENDING`` names are not yet under contract;
``EXEMPT`` names have no geometry (result types). Rotations are scale-free
(law ``"unitless"``); translations and points scale by ``s``.
"""

from __future__ import annotations

import torchgeo_cg.transforms as T
from tests.contract.spec import Arg, Entry

__all__ = ["ENTRIES", "PENDING", "EXEMPT"]

SQ = Arg("squared_residuals", (3, 7), "positive", "area")
SCALE = Arg("scale", (3, 1), "positive", "length")

ENTRIES: list[Entry] = [
    # --- robust losses: residuals and scale both x s
    *[Entry(f"transforms.robust_weights[{loss}]",
            lambda sq, c, loss=loss: T.robust_weights(sq, loss, c), (SQ, SCALE),
            out="unitless", empty=(0, -1), mixed="promote", bad=())
      for loss in ("huber", "cauchy", "tukey")],
    *[Entry(f"transforms.robust_loss[{loss}]",
            lambda sq, c, loss=loss: T.robust_loss(sq, loss, c), (SQ, SCALE),
            out="area", empty=(0, -1), mixed="promote", bad=())
      for loss in ("huber", "cauchy", "tukey")],
]

PENDING: dict[str, tuple[str, str]] = {}

EXEMPT: dict[str, str] = {}
