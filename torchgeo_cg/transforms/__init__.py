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
from torchgeo_cg.transforms.modules import HomogeneousTransform, TRSTransform
from torchgeo_cg.transforms.scene_graph import (
    FixedTransform,
    Orbit,
    SceneGraph,
    WorldTransforms,
    solar_system,
)

__all__ = [
    "FixedTransform",
    "HomogeneousTransform",
    "Orbit",
    "SceneGraph",
    "TRSTransform",
    "WorldTransforms",
    "solar_system",
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
