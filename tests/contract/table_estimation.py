"""Contract entries of transforms: estimation, fitting, RANSAC and registration.

``ENTRIES`` join ``table.TABLE``; ``PENDING`` names are not yet under contract;
``EXEMPT`` names have no geometry (result types, exceptions, validators).
"""

from __future__ import annotations

from tests.contract.spec import Entry

__all__ = ["ENTRIES", "PENDING", "EXEMPT"]

ENTRIES: list[Entry] = []

PENDING: dict[str, tuple[str, str]] = {
    "transforms.FitResult": ("i10", "not yet under contract"),
    "transforms.HartleyNormalization": ("i10", "not yet under contract"),
    "transforms.HomographyFit": ("i10", "not yet under contract"),
    "transforms.HomographyModel": ("i10", "not yet under contract"),
    "transforms.find_affine": ("i10", "not yet under contract"),
    "transforms.find_euclidean": ("i10", "not yet under contract"),
    "transforms.find_homography_dlt": ("i10", "not yet under contract"),
    "transforms.find_similarity": ("i10", "not yet under contract"),
    "transforms.find_translation": ("i10", "not yet under contract"),
    "transforms.fit_transform": ("i10", "not yet under contract"),
    "transforms.hartley_normalize": ("i10", "not yet under contract"),
    "transforms.matrix_to_parameters": ("i10", "not yet under contract"),
    "transforms.parameters_to_matrix": ("i10", "not yet under contract"),
    "transforms.reprojection_error": ("i10", "not yet under contract"),
    "transforms.find_transform_ransac": ("i10", "not yet under contract"),
    "transforms.RobustFit": ("i10", "not yet under contract"),
    "transforms.register_images": ("i10", "not yet under contract"),
    "transforms.RegistrationResult": ("i10", "not yet under contract"),
    "transforms.warp_image": ("i10", "not yet under contract"),
    "transforms.WarpedImage": ("i10", "not yet under contract"),
}

EXEMPT: dict[str, str] = {}
