"""The check of a surface's degree pair, shared by the patches, the fits and the modules
(internals of :mod:`torchgeo_cg.surfaces.patches`)."""

from __future__ import annotations

from torchgeo_cg.curves.bernstein import check_degree

__all__ = ["check_surface_degree"]


def check_surface_degree(degree) -> tuple[int, int]:
    """``degree`` as a pair ``(p, q)`` of non-negative ints (an int means both).

    Example:
        >>> check_surface_degree(3), check_surface_degree((2, 1))
        ((3, 3), (2, 1))
    """
    if isinstance(degree, (tuple, list)):
        if len(degree) != 2:
            raise ValueError(f"degree: expected an int or a pair (p, q), got {degree!r}")
        return check_degree(degree[0], "degree[0]"), check_degree(degree[1], "degree[1]")
    d = check_degree(degree)
    return d, d
