"""Homogeneous 2D and 3D transforms, rotations, articulated scene graphs and estimation."""

from torchgeo_cg.transforms import rotations
from torchgeo_cg.transforms._correspondences import TransformFit
from torchgeo_cg.transforms.correspondences import (
    HartleyNormalization,
    hartley_normalize,
    reprojection_error,
)
from torchgeo_cg.transforms.decompose import AffineDecomposition, decompose_affine
from torchgeo_cg.transforms.estimation import (
    find_affine,
    find_euclidean,
    find_similarity,
    find_translation,
)
from torchgeo_cg.transforms.fitting import FitResult, HomographyModel, fit_transform
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
from torchgeo_cg.transforms.homography_dlt import find_homography_dlt
from torchgeo_cg.transforms.modules import HomogeneousTransform, TRSTransform
from torchgeo_cg.transforms.parametrization import matrix_to_parameters, parameters_to_matrix
from torchgeo_cg.transforms.ransac import RobustFit, find_transform_ransac
from torchgeo_cg.transforms.registration import (
    RegistrationResult,
    WarpedImage,
    register_images,
    warp_image,
)
from torchgeo_cg.transforms.report_shapes import (
    ReportShapes,
    ShapeFit,
    fit_report_shapes,
    report_shapes,
)
from torchgeo_cg.transforms.robust import robust_loss, robust_weights
from torchgeo_cg.transforms.scene_graph import (
    FixedTransform,
    Orbit,
    SceneGraph,
    WorldTransforms,
    solar_system,
)

__all__ = [
    "AffineDecomposition",
    "FitResult",
    "HartleyNormalization",
    "TransformFit",
    "HomographyModel",
    "RegistrationResult",
    "ReportShapes",
    "RobustFit",
    "ShapeFit",
    "decompose_affine",
    "find_affine",
    "find_euclidean",
    "find_homography_dlt",
    "find_similarity",
    "find_transform_ransac",
    "find_translation",
    "fit_report_shapes",
    "fit_transform",
    "hartley_normalize",
    "matrix_to_parameters",
    "parameters_to_matrix",
    "report_shapes",
    "register_images",
    "reprojection_error",
    "robust_loss",
    "robust_weights",
    "rotations",
    "warp_image",
    "WarpedImage",
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
