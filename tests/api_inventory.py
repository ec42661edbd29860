"""The public API of torchgeo_cg, in one place: every public module and its ``__all__``.

This table is the single source of the public surface. ``tests/test_public_api.py``
checks the package against it in both directions (a name never disappears silently,
and a new one is never public by accident); the contract's completeness test
(``tests/contract/test_contract.py``) and the module-machinery test take their names
from it; the API reference (``docs/``) documents exactly these names, one page per
subpackage, and ``tests/test_docs.py`` fails when one is missing from the built site.

To add a name, add it to its module's list here in the same change (one name per line,
so that parallel additions merge). To see the current surface in this file's format
(to paste, after reviewing the diff)::

    python tests/api_inventory.py

Modules whose dotted path has a part starting with ``_`` (private modules,
``__main__``) are not public and are not listed.
"""

from __future__ import annotations

#: module -> the names of its ``__all__`` (order does not matter; kept sorted).
INVENTORY: dict[str, list[str]] = {
    "torchgeo_cg": [
        "ShapeError",
        "__version__",
        "core",
        "curves",
        "mesh",
        "points",
        "sdf",
        "transforms",
    ],
    "torchgeo_cg.cli": ["CommandError"],
    "torchgeo_cg.cli.bench": [],
    "torchgeo_cg.cli.fit_shapes": [],
    "torchgeo_cg.cli.gallery": [],
    "torchgeo_cg.cli.info": [],
    "torchgeo_cg.cli.main": ["main"],
    "torchgeo_cg.cli.sdf_samples": [],
    "torchgeo_cg.core": [
        "ShapeError",
        "as_tensor_like",
        "cast_back",
        "check_broadcastable",
        "check_float",
        "check_same_dtype",
        "check_shape",
        "check_tensor",
        "clamp_away_from_zero",
        "hypot",
        "safe_div",
        "safe_norm",
        "safe_sqrt",
        "working_dtype",
    ],
    "torchgeo_cg.core.check": [
        "ShapeError",
        "check_broadcastable",
        "check_float",
        "check_shape",
        "check_tensor",
    ],
    "torchgeo_cg.core.coerce": [
        "as_tensor_like",
        "check_same_dtype",
    ],
    "torchgeo_cg.core.numerics": [
        "cast_back",
        "clamp_away_from_zero",
        "hypot",
        "safe_div",
        "safe_norm",
        "safe_sqrt",
        "working_dtype",
    ],
    "torchgeo_cg.core.testing": [
        "DTYPES",
        "TOLERANCES",
        "assert_close",
        "available_devices",
        "tolerance",
    ],
    "torchgeo_cg.curves": [
        "BezierCurve",
        "BezierFit",
        "HermiteControls",
        "HermiteCurve",
        "HermiteSpline",
        "MarchingSquaresResult",
        "PchipInterpolator",
        "SplitResult",
        "bernstein_basis",
        "bezier",
        "bezier_arclength_params",
        "bezier_curvature",
        "bezier_derivative",
        "bezier_length",
        "bezier_normal",
        "bezier_tangent",
        "bezier_to_hermite",
        "cardinal_tangents",
        "catmull_rom_tangents",
        "circle",
        "cubic_bezier",
        "cycloid",
        "de_casteljau",
        "elevate_bezier",
        "figure_eight_implicit",
        "figure_eight_parametric",
        "fit_bezier",
        "fit_parameters",
        "grid_2d",
        "hermite",
        "hermite_basis",
        "hermite_spline",
        "hermite_to_bezier",
        "implicit_circle",
        "marching_squares",
        "pchip_interpolate",
        "pchip_tangents",
        "quartic_bezier",
        "split_bezier",
    ],
    "torchgeo_cg.curves.bernstein": ["bernstein_basis"],
    "torchgeo_cg.curves.bezier": [
        "BezierCurve",
        "SplitResult",
        "bezier",
        "bezier_arclength_params",
        "bezier_curvature",
        "bezier_derivative",
        "bezier_length",
        "bezier_normal",
        "bezier_tangent",
        "cubic_bezier",
        "de_casteljau",
        "elevate_bezier",
        "quartic_bezier",
        "split_bezier",
    ],
    "torchgeo_cg.curves.fitting": [
        "BezierFit",
        "fit_bezier",
        "fit_parameters",
    ],
    "torchgeo_cg.curves.hermite": [
        "HermiteControls",
        "HermiteCurve",
        "HermiteSpline",
        "PchipInterpolator",
        "bezier_to_hermite",
        "cardinal_tangents",
        "catmull_rom_tangents",
        "hermite",
        "hermite_basis",
        "hermite_spline",
        "hermite_to_bezier",
        "pchip_interpolate",
        "pchip_tangents",
    ],
    "torchgeo_cg.curves.marching_squares": [
        "MarchingSquaresResult",
        "SADDLE_RULES",
        "marching_squares",
    ],
    "torchgeo_cg.curves.parametric": [
        "circle",
        "cycloid",
        "figure_eight_implicit",
        "figure_eight_parametric",
        "grid_2d",
        "implicit_circle",
    ],
    "torchgeo_cg.mesh": [
        "CatmullClark",
        "FVAR_INTERPOLATIONS",
        "FaceVaryingSubdivision",
        "INFINITELY_SHARP",
        "LimitFrames",
        "LoopSubdivision",
        "MarchingCubes",
        "MarchingCubesResult",
        "Mesh",
        "MeshEdges",
        "SubdivisionOperator",
        "SubdivisionTags",
        "apply_operator",
        "bilinear_operator",
        "catmull_clark",
        "catmull_clark_operator",
        "check_faces",
        "edge_length_loss",
        "face_sizes",
        "face_varying_operator",
        "face_varying_subdivide",
        "from_trimesh",
        "laplacian_smoothing_loss",
        "limit_frames",
        "limit_positions",
        "load_mesh",
        "loop_operator",
        "loop_subdivide",
        "marching_cubes",
        "mesh_edges",
        "mesh_laplacian",
        "normal_consistency_loss",
        "pad_faces",
        "save_mesh",
        "to_trimesh",
        "triangulate_faces",
        "unpad_faces",
    ],
    "torchgeo_cg.mesh.bilinear": ["bilinear_operator"],
    "torchgeo_cg.mesh.creasing": [],
    "torchgeo_cg.mesh.data": [],
    "torchgeo_cg.mesh.data.make_rabbit": [],
    "torchgeo_cg.mesh.face_varying": [
        "FVAR_INTERPOLATIONS",
        "FaceVaryingSubdivision",
        "face_varying_operator",
        "face_varying_subdivide",
    ],
    "torchgeo_cg.mesh.faces": [
        "check_faces",
        "face_sizes",
        "pad_faces",
        "triangulate_faces",
        "unpad_faces",
    ],
    "torchgeo_cg.mesh.io": [
        "Mesh",
        "from_trimesh",
        "load_mesh",
        "save_mesh",
        "to_trimesh",
    ],
    "torchgeo_cg.mesh.io_obj": [],
    "torchgeo_cg.mesh.io_obj_tags": [],
    "torchgeo_cg.mesh.io_off": [],
    "torchgeo_cg.mesh.io_ply": [],
    "torchgeo_cg.mesh.io_text": [],
    "torchgeo_cg.mesh.limit": [
        "LimitFrames",
        "limit_frames",
    ],
    "torchgeo_cg.mesh.loop": [
        "LoopSubdivision",
        "loop_operator",
        "loop_subdivide",
    ],
    "torchgeo_cg.mesh.marching_cubes": [
        "AMBIGUITY_RULES",
        "MarchingCubes",
        "MarchingCubesResult",
        "marching_cubes",
    ],
    "torchgeo_cg.mesh.regularizers": [
        "MeshEdges",
        "edge_length_loss",
        "laplacian_smoothing_loss",
        "mesh_edges",
        "mesh_laplacian",
        "normal_consistency_loss",
    ],
    "torchgeo_cg.mesh.stencils": [],
    "torchgeo_cg.mesh.subdivision": [
        "CatmullClark",
        "SubdivisionOperator",
        "apply_operator",
        "catmull_clark",
        "catmull_clark_operator",
        "limit_positions",
    ],
    "torchgeo_cg.mesh.tags": [
        "INFINITELY_SHARP",
        "SubdivisionTags",
    ],
    "torchgeo_cg.points": [
        "ChamferDistance",
        "ChamferResult",
        "KNNResult",
        "chamfer_distance",
        "knn",
    ],
    "torchgeo_cg.points.chamfer": [
        "ChamferDistance",
        "ChamferResult",
        "chamfer_distance",
    ],
    "torchgeo_cg.points.nearest_neighbors": [
        "KNNResult",
        "knn",
    ],
    "torchgeo_cg.points.search_brute": [],
    "torchgeo_cg.points.search_grid": [],
    "torchgeo_cg.sdf": [
        "Annulus",
        "Box",
        "Capsule",
        "Circle",
        "Difference",
        "Gyroid",
        "Intersection",
        "LevelSetPoints",
        "MeshSDF",
        "MeshSDFResult",
        "Plane",
        "Product",
        "Rectangle",
        "Rotate",
        "SDFSampler",
        "SDFSamples",
        "Scale",
        "SmoothIntersection",
        "SmoothUnion",
        "Sphere",
        "Torus",
        "Translate",
        "TriangleClosestPoint",
        "Union",
        "Volume",
        "annulus",
        "available_engines",
        "box",
        "capsule",
        "circle",
        "closest_point_on_triangle",
        "difference",
        "eikonal_loss",
        "grid_interpolate",
        "grid_points",
        "grid_spacing",
        "gyroid",
        "index_to_world",
        "intersection",
        "is_watertight",
        "load_samples",
        "mesh_sdf",
        "plane",
        "product",
        "rectangle",
        "rotate",
        "sample_grid",
        "sample_mesh_surface",
        "save_samples",
        "scale",
        "sdf_gradient",
        "sdf_normal",
        "smooth_intersection",
        "smooth_union",
        "sphere",
        "torus",
        "translate",
        "union",
        "winding_number",
        "world_to_index",
        "zero_level_set",
    ],
    "torchgeo_cg.sdf.engine_warp": [],
    "torchgeo_cg.sdf.engines": [
        "ENGINES",
        "available_engines",
    ],
    "torchgeo_cg.sdf.gradients": [
        "eikonal_loss",
        "sdf_gradient",
        "sdf_normal",
    ],
    "torchgeo_cg.sdf.grid": [
        "Volume",
        "grid_interpolate",
        "grid_points",
        "grid_spacing",
        "index_to_world",
        "sample_grid",
        "world_to_index",
    ],
    "torchgeo_cg.sdf.level_set": [
        "LevelSetPoints",
        "zero_level_set",
    ],
    "torchgeo_cg.sdf.mesh_distance": [
        "MeshSDF",
        "MeshSDFResult",
        "TriangleClosestPoint",
        "closest_point_on_triangle",
        "is_watertight",
        "mesh_sdf",
        "winding_number",
    ],
    "torchgeo_cg.sdf.mesh_search": [],
    "torchgeo_cg.sdf.operators": [
        "Difference",
        "Intersection",
        "Product",
        "Rotate",
        "Scale",
        "SmoothIntersection",
        "SmoothUnion",
        "Translate",
        "Union",
        "difference",
        "intersection",
        "product",
        "rotate",
        "scale",
        "smooth_intersection",
        "smooth_union",
        "translate",
        "union",
    ],
    "torchgeo_cg.sdf.primitives": [
        "Annulus",
        "Box",
        "Capsule",
        "Circle",
        "Gyroid",
        "Plane",
        "Rectangle",
        "Sphere",
        "Torus",
        "annulus",
        "box",
        "capsule",
        "circle",
        "gyroid",
        "plane",
        "rectangle",
        "sphere",
        "torus",
    ],
    "torchgeo_cg.sdf.sampler": [
        "SDFSampler",
        "SDFSamples",
        "load_samples",
        "sample_mesh_surface",
        "save_samples",
    ],
    "torchgeo_cg.transforms": [
        "AffineDecomposition",
        "FitResult",
        "FixedTransform",
        "HartleyNormalization",
        "HomogeneousTransform",
        "HomographyFit",
        "HomographyModel",
        "Orbit",
        "RegistrationResult",
        "ReportShapes",
        "RobustFit",
        "SceneGraph",
        "ShapeFit",
        "TRSTransform",
        "WarpedImage",
        "WorldTransforms",
        "compose",
        "compose_trs",
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
        "homography",
        "inverse",
        "matrix_to_parameters",
        "parameters_to_matrix",
        "register_images",
        "report_shapes",
        "reprojection_error",
        "rotation",
        "scale_x",
        "scale_y",
        "scaling",
        "shear",
        "solar_system",
        "transform_points",
        "translation",
        "warp_image",
    ],
    "torchgeo_cg.transforms.decompose": [
        "AffineDecomposition",
        "decompose_affine",
    ],
    "torchgeo_cg.transforms.estimation": [
        "HartleyNormalization",
        "HomographyFit",
        "find_affine",
        "find_euclidean",
        "find_homography_dlt",
        "find_similarity",
        "find_translation",
        "hartley_normalize",
        "reprojection_error",
    ],
    "torchgeo_cg.transforms.fitting": [
        "FitResult",
        "HomographyModel",
        "LOSSES",
        "MODELS",
        "PARAMETRIZATIONS",
        "fit_transform",
        "matrix_to_parameters",
        "parameters_to_matrix",
    ],
    "torchgeo_cg.transforms.homogeneous": [
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
    ],
    "torchgeo_cg.transforms.modules": [
        "HomogeneousTransform",
        "TRSTransform",
    ],
    "torchgeo_cg.transforms.ransac": [
        "RobustFit",
        "SAMPLE_SIZES",
        "find_transform_ransac",
    ],
    "torchgeo_cg.transforms.registration": [
        "REGISTRATION_MODELS",
        "RegistrationResult",
        "WarpedImage",
        "register_images",
        "warp_image",
    ],
    "torchgeo_cg.transforms.report_shapes": [
        "ReportShapes",
        "ShapeFit",
        "fit_report_shapes",
        "format_report_table",
        "report_shapes",
    ],
    "torchgeo_cg.transforms.scene_graph": [
        "FixedTransform",
        "Orbit",
        "SceneGraph",
        "WorldTransforms",
        "solar_system",
    ],
    "torchgeo_cg.viz": [
        "GalleryFigure",
        "build_gallery",
        "figure",
        "registered_figures",
    ],
    "torchgeo_cg.viz.curves": [],
    "torchgeo_cg.viz.estimation": ["plot_report_fits"],
    "torchgeo_cg.viz.glyph_fit": [
        "GlyphFit",
        "GlyphPieces",
        "fit_glyph",
        "glyph_pieces",
        "plot_glyph_fit",
    ],
    "torchgeo_cg.viz.marching_cubes": [],
    "torchgeo_cg.viz.registration": [],
    "torchgeo_cg.viz.registry": [
        "GalleryFigure",
        "figure",
        "registered_figures",
    ],
    "torchgeo_cg.viz.sdf": [],
    "torchgeo_cg.viz.subdivision": [],
    "torchgeo_cg.viz.subdivision_tags": [],
    "torchgeo_cg.viz.torus_fit": [
        "TRUE_RADII",
        "TorusFit",
        "fit_torus_radii",
        "plot_torus_fit",
    ],
    "torchgeo_cg.viz.transforms": [],
}


PACKAGE = "torchgeo_cg"


def subpackages() -> list[str]:
    """The top-level subpackages (``torchgeo_cg.core``, ...): one reference page each."""
    return sorted(m for m in INVENTORY if m.count(".") == 1)


def modules_of(subpackage: str) -> list[str]:
    """``subpackage`` and its public modules, sorted (the subpackage first)."""
    return [subpackage] + sorted(m for m in INVENTORY if m.startswith(subpackage + "."))


def public_names() -> list[tuple[str, str]]:
    """Every ``(module, name)`` of the inventory, sorted."""
    return sorted((m, n) for m, names in INVENTORY.items() for n in names)


def public_callables() -> set[str]:
    """``"<subpackage>.<name>"`` (and top-level names) of every public callable that is not a
    module: what the contract table must cover or exempt."""
    import importlib
    import inspect

    out = set()
    for module in [PACKAGE] + subpackages():
        mod = importlib.import_module(module)
        prefix = module.removeprefix(PACKAGE).lstrip(".")
        for name in INVENTORY[module]:
            obj = getattr(mod, name)
            if callable(obj) and not inspect.ismodule(obj):
                out.add(f"{prefix}.{name}" if prefix else name)
    return out


def public_modules() -> list[str]:
    """Dotted names of every public module of the installed package, sorted."""
    import pkgutil

    import torchgeo_cg

    names = ["torchgeo_cg"] + [
        m.name for m in pkgutil.walk_packages(torchgeo_cg.__path__, prefix="torchgeo_cg.")
    ]
    return sorted(n for n in names if not any(p.startswith("_") for p in n.split(".")))


def current_surface() -> dict[str, list[str]]:
    """``{module: sorted(__all__)}`` of the package as imported now."""
    import importlib

    return {
        name: sorted(getattr(importlib.import_module(name), "__all__", []))
        for name in public_modules()
    }


def format_inventory(surface: dict[str, list[str]]) -> str:
    """``surface`` as the body of :data:`INVENTORY`: one module per line when it has at most
    one name, else one name per line (so that two changes to one module merge)."""
    lines = []
    for module, names in surface.items():
        if len(names) <= 1:
            body = "".join(f'"{n}"' for n in names)
            lines.append(f'    "{module}": [{body}],')
            continue
        lines.append(f'    "{module}": [')
        lines += [f'        "{n}",' for n in sorted(names)]
        lines.append("    ],")
    return "\n".join(lines)


if __name__ == "__main__":
    print("INVENTORY: dict[str, list[str]] = {")
    print(format_inventory(current_surface()))
    print("}")
