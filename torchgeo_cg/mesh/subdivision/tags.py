"""Subdivision tags: creases, corners and holes, with OpenSubdiv's meaning of sharpness.

The tags travel with a control mesh from the file that holds them (OpenSubdiv's ``t``
lines in OBJ, see :mod:`torchgeo_cg.mesh.io`) to the subdivision operators
(:mod:`torchgeo_cg.mesh.subdivision`, :mod:`torchgeo_cg.mesh.subdivision.loop`).

Convention:
    Sharpness is OpenSubdiv's: ``0`` is smooth, values ``>= 10`` are infinitely sharp,
    and a semi-sharp value ``s`` is used for ``ceil(s)`` levels, decreasing by 1 per
    level (``"uniform"``) or by OpenSubdiv's Chaikin rule (``"chaikin"``). Creases are
    undirected vertex pairs ``(a, b)`` that must be edges of the mesh; corners are vertex
    ids; holes are face ids (rows of ``faces``).
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_shape, check_tensor

__all__ = ["SubdivisionTags", "INFINITELY_SHARP", "check_tags"]

INFINITELY_SHARP = 10.0
"""OpenSubdiv's ``SHARPNESS_INFINITE``: a sharpness at or above it never decays."""


class SubdivisionTags(NamedTuple):
    """Sharp creases, corners and holes of a control mesh.

    Sharpness values are cast to the dtype of the operator's weights (the data's dtype
    in ``catmull_clark``/``loop_subdivide``); they do not scale with the positions.

    Attributes:
        creases: ``(E, 2)`` long, vertex pairs of the creased edges.
        crease_sharpness: ``(E,)`` float, sharpness of each crease.
        corners: ``(C,)`` long, vertex ids of the corners.
        corner_sharpness: ``(C,)`` float, sharpness of each corner.
        holes: ``(H,)`` long, ids of the faces that are holes.

    Example:
        >>> tags = SubdivisionTags.empty()
        >>> tags.creases.shape, tags.holes.shape
        (torch.Size([0, 2]), torch.Size([0]))
    """

    creases: torch.Tensor
    crease_sharpness: torch.Tensor
    corners: torch.Tensor
    corner_sharpness: torch.Tensor
    holes: torch.Tensor

    @classmethod
    def empty(cls, dtype: torch.dtype = torch.float32, device=None) -> SubdivisionTags:
        """Tags with no crease, corner or hole (the untagged mesh)."""
        long = {"dtype": torch.long, "device": device}
        real = {"dtype": dtype, "device": device}
        return cls(
            creases=torch.zeros(0, 2, **long),
            crease_sharpness=torch.zeros(0, **real),
            corners=torch.zeros(0, **long),
            corner_sharpness=torch.zeros(0, **real),
            holes=torch.zeros(0, **long),
        )


def check_tags(tags: SubdivisionTags) -> SubdivisionTags:
    """Raise unless the index fields are integer tensors and ``creases`` is ``(E, 2)``.

    A float index would be truncated and a wrong shape reshaped silently; the errors name
    the field (``TypeError`` for a dtype, ``ShapeError`` for a shape). Index ranges and
    sharpness values are checked where the mesh is known (OpenSubdiv's rules).

    Example:
        >>> check_tags(SubdivisionTags.empty()._replace(holes=torch.tensor([0.0])))
        Traceback (most recent call last):
        ...
        TypeError: tags.holes: expected an integer tensor, got dtype torch.float32
    """
    for name in ("creases", "corners", "holes"):
        ids = check_tensor(getattr(tags, name), f"tags.{name}")
        if ids.is_floating_point() or ids.is_complex() or ids.dtype == torch.bool:
            raise TypeError(f"tags.{name}: expected an integer tensor, got dtype {ids.dtype}")
    for name in ("crease_sharpness", "corner_sharpness"):
        values = check_tensor(getattr(tags, name), f"tags.{name}")
        if values.is_complex() or values.dtype == torch.bool:
            raise TypeError(f"tags.{name}: expected a real tensor, got dtype {values.dtype}")
    sizes = check_shape(tags.creases, ["E", 2], "tags.creases")
    check_shape(tags.crease_sharpness, ["E"], "tags.crease_sharpness", sizes)
    sizes = check_shape(tags.corners, ["C"], "tags.corners")
    check_shape(tags.corner_sharpness, ["C"], "tags.corner_sharpness", sizes)
    check_shape(tags.holes, ["H"], "tags.holes")
    return tags
