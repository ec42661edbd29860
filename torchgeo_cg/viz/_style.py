"""Shared matplotlib helpers for the gallery figures (imports matplotlib)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

__all__ = ["closed", "save"]


def save(fig, path: Path, dpi: int = 110) -> None:
    """Save ``fig`` to ``path`` tightly and close it."""
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    plt.close(fig)


def closed(points):
    """Append the first point to a (N, 2) outline so it plots closed."""
    import numpy as np

    points = np.asarray(points)
    return np.concatenate([points, points[:1]], axis=0)
