"""Matplotlib figures for the gallery, one module per area (imported lazily).

Importing :mod:`torchgeo_cg.viz` does not import matplotlib; the figure modules
(``transforms.py``, ``curves.py``, ...) do, and only ``torchgeo-cg gallery``
loads them.
"""

from torchgeo_cg.viz.gallery import build_gallery
from torchgeo_cg.viz.registry import GalleryFigure, figure, registered_figures

__all__ = ["GalleryFigure", "build_gallery", "figure", "registered_figures"]
