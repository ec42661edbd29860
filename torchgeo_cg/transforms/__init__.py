"""Homogeneous 2D transforms, articulated scene graphs and transform estimation."""

from torchgeo_cg.transforms.homogeneous import (
    compose,
    compose_trs,
    homography,
    inverse,
    rotation,
    scale_x,
    scale_y,
    scaling,
    shear,
    transform_points,
    translation,
)

__all__ = [
    "compose",
    "compose_trs",
    "homography",
    "inverse",
    "rotation",
    "scale_x",
    "scale_y",
    "scaling",
    "shear",
    "transform_points",
    "translation",
]
