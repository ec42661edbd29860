"""Contract entries of marching cubes, mesh files, mesh regularizers.

``ENTRIES`` join ``table.TABLE``; ``PENDING`` names are not yet under contract;
``EXEMPT`` names have no geometry (result types, exceptions, validators).
"""

from __future__ import annotations

from tests.contract.spec import Entry

__all__ = ["ENTRIES", "PENDING", "EXEMPT"]

ENTRIES: list[Entry] = []

PENDING: dict[str, tuple[str, str]] = {
    "mesh.marching_cubes": ("i10", "not yet under contract"),
    "mesh.MarchingCubes": ("i10", "not yet under contract"),
    "mesh.MarchingCubesResult": ("i10", "not yet under contract"),
    "mesh.Mesh": ("i10", "not yet under contract"),
    "mesh.load_mesh": ("i10", "not yet under contract"),
    "mesh.save_mesh": ("i10", "not yet under contract"),
    "mesh.from_trimesh": ("i10", "not yet under contract"),
    "mesh.to_trimesh": ("i10", "not yet under contract"),
    "mesh.MeshEdges": ("i10", "not yet under contract"),
    "mesh.mesh_edges": ("i10", "not yet under contract"),
    "mesh.mesh_laplacian": ("i10", "not yet under contract"),
    "mesh.laplacian_smoothing_loss": ("i10", "not yet under contract"),
    "mesh.normal_consistency_loss": ("i10", "not yet under contract"),
    "mesh.edge_length_loss": ("i10", "not yet under contract"),
}

EXEMPT: dict[str, str] = {}
