"""Contract entries of subdivision, faces, limit and face-varying.

``ENTRIES`` join ``table.TABLE``; ``PENDING`` names are not yet under contract;
``EXEMPT`` names have no geometry (result types, exceptions, validators).
"""

from __future__ import annotations

from tests.contract.spec import Entry

__all__ = ["ENTRIES", "PENDING", "EXEMPT"]

ENTRIES: list[Entry] = []

PENDING: dict[str, tuple[str, str]] = {
    "mesh.pad_faces": ("i10", "not yet under contract"),
    "mesh.face_sizes": ("i10", "not yet under contract"),
    "mesh.check_faces": ("i10", "not yet under contract"),
    "mesh.triangulate_faces": ("i10", "not yet under contract"),
    "mesh.unpad_faces": ("i10", "not yet under contract"),
    "mesh.SubdivisionOperator": ("i10", "not yet under contract"),
    "mesh.catmull_clark_operator": ("i10", "not yet under contract"),
    "mesh.apply_operator": ("i10", "not yet under contract"),
    "mesh.catmull_clark": ("i10", "not yet under contract"),
    "mesh.CatmullClark": ("i10", "not yet under contract"),
    "mesh.limit_positions": ("i10", "not yet under contract"),
    "mesh.loop_operator": ("i10", "not yet under contract"),
    "mesh.loop_subdivide": ("i10", "not yet under contract"),
    "mesh.LoopSubdivision": ("i10", "not yet under contract"),
    "mesh.SubdivisionTags": ("i10", "not yet under contract"),
    "mesh.bilinear_operator": ("i10", "not yet under contract"),
    "mesh.limit_frames": ("i10", "not yet under contract"),
    "mesh.LimitFrames": ("i10", "not yet under contract"),
    "mesh.face_varying_operator": ("i10", "not yet under contract"),
    "mesh.face_varying_subdivide": ("i10", "not yet under contract"),
    "mesh.FaceVaryingSubdivision": ("i10", "not yet under contract"),
}

EXEMPT: dict[str, str] = {}
