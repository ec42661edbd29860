"""Contract entries of mesh distance queries, SDF sampler, point clouds.

``ENTRIES`` join ``table.TABLE``; ``PENDING`` names are not yet under contract;
``EXEMPT`` names have no geometry (result types, exceptions, validators).
"""

from __future__ import annotations

from tests.contract.spec import Entry

__all__ = ["ENTRIES", "PENDING", "EXEMPT"]

ENTRIES: list[Entry] = []

PENDING: dict[str, tuple[str, str]] = {
    "sdf.MeshSDFResult": ("i10", "not yet under contract"),
    "sdf.TriangleClosestPoint": ("i10", "not yet under contract"),
    "sdf.closest_point_on_triangle": ("i10", "not yet under contract"),
    "sdf.is_watertight": ("i10", "not yet under contract"),
    "sdf.winding_number": ("i10", "not yet under contract"),
    "sdf.mesh_sdf": ("i10", "not yet under contract"),
    "sdf.MeshSDF": ("i10", "not yet under contract"),
    "sdf.available_engines": ("i10", "not yet under contract"),
    "sdf.SDFSamples": ("i10", "not yet under contract"),
    "sdf.SDFSampler": ("i10", "not yet under contract"),
    "sdf.sample_mesh_surface": ("i10", "not yet under contract"),
    "sdf.save_samples": ("i10", "not yet under contract"),
    "sdf.load_samples": ("i10", "not yet under contract"),
    "points.knn": ("i10", "not yet under contract"),
    "points.KNNResult": ("i10", "not yet under contract"),
    "points.chamfer_distance": ("i10", "not yet under contract"),
    "points.ChamferResult": ("i10", "not yet under contract"),
    "points.ChamferDistance": ("i10", "not yet under contract"),
}

EXEMPT: dict[str, str] = {}
