"""The public surface of torchgeo_cg.sdf: names never silently disappear; docs are complete."""

from __future__ import annotations

import inspect

import torchgeo_cg.sdf as sdf

EXPECTED = {
    "sphere", "box", "capsule", "plane", "torus", "gyroid", "circle", "rectangle", "annulus",
    "Sphere", "Box", "Capsule", "Plane", "Torus", "Gyroid", "Circle", "Rectangle", "Annulus",
    "union", "intersection", "difference", "smooth_union", "smooth_intersection", "product",
    "translate", "rotate", "scale", "Union", "Intersection", "Difference", "SmoothUnion",
    "SmoothIntersection", "Product", "Translate", "Rotate", "Scale",
    "grid_spacing", "grid_points", "sample_grid", "grid_interpolate", "LevelSetPoints", "zero_level_set", "sdf_gradient", "sdf_normal",
    "eikonal_loss", "MeshSDFResult", "TriangleClosestPoint", "closest_point_on_triangle",
    "is_watertight", "winding_number", "mesh_sdf", "MeshSDF", "available_engines",
    "SDFSamples", "SDFSampler",
    "sample_mesh_surface", "save_samples", "load_samples",
}


def test_public_surface():
    assert set(sdf.__all__) == EXPECTED
    for name in EXPECTED:
        assert hasattr(sdf, name), name


def test_every_public_function_documents_an_example_and_geometric_ones_a_convention():
    non_geometric = {"eikonal_loss", "is_watertight", "save_samples", "load_samples"}
    for name in sdf.__all__:
        obj = getattr(sdf, name)
        doc = inspect.getdoc(obj) or ""
        assert doc, name
        if inspect.isfunction(obj):
            assert "Example" in doc, name
            assert "Returns" in doc, name
            if name not in non_geometric:
                assert "Convention" in doc, name
