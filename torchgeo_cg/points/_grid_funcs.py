"""Warp functions shared by the grid kernels of the points area (kNN, radius search,
radius outliers): the row of a cell in the grid's tables, and the squared distance in the
torch search's order, so every kernel ranks and tests distances alike, and the insertion
into a row sorted by (distance, index).

Convention:
    No ``from __future__ import annotations``: Warp reads the annotations of the builder.
    A kernel builder takes the functions from :func:`grid_funcs` (built once).
"""

from types import SimpleNamespace
from typing import Any

from torchgeo_cg.engine import register_kernels

__all__ = ["grid_funcs"]


def _build(wp):
    """``sq_dist``, ``lookup`` and ``insert``."""

    @wp.func
    def sq_dist(x: Any, y: Any, z: Any, qx: Any, qy: Any, qz: Any, dim: int):
        """Squared distance, summed coordinate by coordinate (the torch search's order)."""
        dx = x - qx
        d2 = dx * dx
        dy = y - qy
        d2 = d2 + dy * dy
        if dim == 3:
            dz = z - qz
            d2 = d2 + dz * dz
        return d2

    @wp.func
    def lookup(keys: wp.array(dtype=wp.int64), sparse: int, key: wp.int64) -> wp.int64:
        """Row of cell ``key`` in the cell tables, ``-1`` for an empty sparse cell."""
        if sparse == 0:
            return key
        lo_k = int(0)  # noqa: UP018  a dynamic variable for Warp
        hi_k = keys.shape[0]
        while lo_k < hi_k:
            mid = (lo_k + hi_k) // 2
            if keys[mid] < key:
                lo_k = mid + 1
            else:
                hi_k = mid
        if lo_k < keys.shape[0] and keys[lo_k] == key:
            return wp.int64(lo_k)
        return wp.int64(-1)

    @wp.func
    def insert(best: wp.array2d(dtype=Any), best_i: wp.array2d(dtype=wp.int64), row: int,
               n: int, d2: Any, j: wp.int64) -> int:
        """Insert ``(d2, j)`` among the first ``n`` entries of row ``row``, sorted by
        (distance, index); returns ``n + 1`` (the caller keeps it within the row)."""
        s = n
        while s > 0 and (best[row, s - 1] > d2 or (best[row, s - 1] == d2
                                                     and best_i[row, s - 1] > j)):
            best[row, s] = best[row, s - 1]
            best_i[row, s] = best_i[row, s - 1]
            s = s - 1
        best[row, s] = d2
        best_i[row, s] = j
        return n + 1

    return SimpleNamespace(sq_dist=sq_dist, lookup=lookup, insert=insert)


#: The shared functions, built at the first call (loads Warp).
grid_funcs = register_kernels(_build)
