"""The gallery's figure registry.

Each area keeps its figures in its own module ``torchgeo_cg/viz/<area>.py`` and
registers them with :func:`figure`::

    @figure("transforms", "transforms_basic.png", "Translation, rotation and scaling",
            "A unit square moved by T(2, 1), rotated by R(30°) and scaled by S(1.5).")
    def _basic(path: Path) -> None:
        ...  # write the file at ``path``

``torchgeo-cg gallery`` imports every module in :mod:`torchgeo_cg.viz`, then runs
each registered function, so adding a figure never touches shared files.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

__all__ = ["GalleryFigure", "figure", "registered_figures"]


class GalleryFigure(NamedTuple):
    """One gallery entry: ``render(path)`` writes ``filename`` (PNG or GIF)."""

    section: str
    filename: str
    title: str
    caption: str
    render: Callable[[Path], None]


_REGISTRY: dict[str, GalleryFigure] = {}


def figure(section: str, filename: str, title: str, caption: str):
    """Decorator registering ``fn(path) -> None`` as a gallery figure.

    Raises:
        ValueError: another figure already uses ``filename``.

    Example:
        >>> @figure("demo", "demo_doctest.png", "Demo", "Registered in a doctest.")
        ... def _demo(path):
        ...     pass
        >>> [f.title for f in registered_figures() if f.filename == "demo_doctest.png"]
        ['Demo']
        >>> _ = _REGISTRY.pop("demo_doctest.png")
    """

    def wrap(fn: Callable[[Path], None]) -> Callable[[Path], None]:
        existing = _REGISTRY.get(filename)
        same = existing is not None and (
            existing.render.__module__,
            existing.render.__qualname__,
        ) == (
            fn.__module__,
            fn.__qualname__,
        )  # the same function registered again, e.g. by a module re-import
        if existing is not None and not same:
            raise ValueError(f"figure: filename {filename!r} is already registered")
        _REGISTRY[filename] = GalleryFigure(section, filename, title, caption, fn)
        return fn

    return wrap


def registered_figures() -> list[GalleryFigure]:
    """All registered figures, in registration order."""
    return list(_REGISTRY.values())
