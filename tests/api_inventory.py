"""The public API of torchgeo_cg, in one place: every public module and its ``__all__``.

``tests/test_public_api.py`` checks the installed package against this table in
both directions, so a name never disappears silently and a new one is never
public by accident. To add a name, add it here in the same change. To see the
current surface in this file's format (to paste, after reviewing the diff)::

    python tests/api_inventory.py

Modules whose dotted path has a part starting with ``_`` (private modules,
``__main__``) are not public and are not listed.
"""

from __future__ import annotations

#: module -> the names of its ``__all__`` (order does not matter; kept sorted).
INVENTORY: dict[str, list[str]] = {
    "torchgeo_cg": [
        "ShapeError", "__version__", "core", "curves", "mesh", "points", "sdf", "transforms"
    ],
    "torchgeo_cg.cli": ["CommandError"],
    "torchgeo_cg.cli.bench": [
        "NEEDS_CHECKOUT", "add_parser", "find_benchmarks", "load_benchmarks"
    ],
    "torchgeo_cg.cli.fit_shapes": ["MAX_STEPS", "add_parser", "steps_argument"],
    "torchgeo_cg.cli.gallery": ["add_parser"],
    "torchgeo_cg.cli.info": ["add_parser", "collect_info"],
    "torchgeo_cg.cli.main": ["OneLineParser", "build_parser", "main"],
    "torchgeo_cg.cli.sdf_samples": [
        "add_parser", "find_meshes", "mesh_seed", "sdf_samples_for_mesh", "write_npz"
    ],
    "torchgeo_cg.core": [
        "ShapeError", "as_tensor_like", "cast_back", "check_broadcastable", "check_float",
        "check_same_dtype", "check_shape", "check_tensor", "clamp_away_from_zero", "hypot",
        "safe_div", "safe_norm", "safe_sqrt", "working_dtype"
    ],
    "torchgeo_cg.core.check": [
        "ShapeError", "check_broadcastable", "check_float", "check_shape", "check_tensor",
        "format_shape"
    ],
    "torchgeo_cg.core.coerce": ["as_tensor_like", "check_same_dtype"],
    "torchgeo_cg.core.numerics": [
        "cast_back", "clamp_away_from_zero", "hypot", "safe_div", "safe_norm", "safe_sqrt",
        "working_dtype"
    ],
    "torchgeo_cg.core.testing": [
        "DTYPES", "TOLERANCES", "assert_close", "available_devices", "tolerance"
    ],
    "torchgeo_cg.curves": [
        "BezierCurve", "BezierFit", "HermiteControls", "HermiteCurve", "HermiteSpline",
        "MarchingSquaresResult", "PchipInterpolator", "SplitResult", "bernstein_basis",
        "bezier", "bezier_arclength_params", "bezier_curvature", "bezier_derivative",
        "bezier_length", "bezier_normal", "bezier_tangent", "bezier_to_hermite",
        "cardinal_tangents", "catmull_rom_tangents", "check_knots", "circle", "cubic_bezier",
        "cycloid", "de_casteljau", "elevate_bezier", "figure_eight_implicit",
        "figure_eight_parametric", "fit_bezier", "fit_parameters", "grid_2d", "hermite",
        "hermite_basis", "hermite_spline", "hermite_to_bezier", "implicit_circle",
        "marching_squares", "pchip_interpolate", "pchip_tangents", "quartic_bezier",
        "split_bezier"
    ],
    "torchgeo_cg.curves.bernstein": ["bernstein_basis", "check_degree"],
    "torchgeo_cg.curves.bezier": [
        "BezierCurve", "SplitResult", "bezier", "bezier_arclength_params", "bezier_curvature",
        "bezier_derivative", "bezier_length", "bezier_normal", "bezier_tangent", "cubic_bezier",
        "de_casteljau", "elevate_bezier", "quartic_bezier", "split_bezier"
    ],
    "torchgeo_cg.curves.fitting": [
        "BezierFit", "as_padded_strokes", "fit_bezier", "fit_parameters"
    ],
    "torchgeo_cg.curves.hermite": [
        "HermiteControls", "HermiteCurve", "HermiteSpline", "PchipInterpolator",
        "bezier_to_hermite", "cardinal_tangents", "catmull_rom_tangents", "check_knots",
        "hermite", "hermite_basis", "hermite_spline", "hermite_to_bezier", "pchip_interpolate",
        "pchip_tangents"
    ],
    "torchgeo_cg.curves.marching_squares": [
        "MarchingSquaresResult", "SADDLE_RULES", "marching_squares"
    ],
    "torchgeo_cg.curves.parametric": [
        "circle", "cycloid", "figure_eight_implicit", "figure_eight_parametric", "grid_2d",
        "implicit_circle"
    ],
    "torchgeo_cg.mesh": [
        "CatmullClark", "FVAR_INTERPOLATIONS", "FaceVaryingSubdivision", "INFINITELY_SHARP",
        "LimitFrames", "LoopSubdivision", "MarchingCubes", "MarchingCubesResult", "Mesh",
        "MeshEdges", "SubdivisionOperator", "SubdivisionTags", "apply_operator",
        "bilinear_operator", "catmull_clark", "catmull_clark_operator", "check_faces",
        "edge_length_loss", "face_sizes", "face_varying_operator", "face_varying_subdivide",
        "from_trimesh", "laplacian_smoothing_loss", "limit_frames", "limit_positions",
        "load_mesh", "loop_operator", "loop_subdivide", "marching_cubes", "mesh_edges",
        "mesh_laplacian", "normal_consistency_loss", "pad_faces", "save_mesh", "to_trimesh",
        "triangulate_faces", "unpad_faces"
    ],
    "torchgeo_cg.mesh.bilinear": ["bilinear_operator"],
    "torchgeo_cg.mesh.creasing": [
        "CREASE_METHODS", "SubdivisionRules", "child_tags", "component_labels",
        "decrement_sharpness", "limit_rules", "subdivision_rules", "vertex_rule"
    ],
    "torchgeo_cg.mesh.data": [],
    "torchgeo_cg.mesh.data.make_rabbit": ["cube_sphere", "extrude", "main", "make_rabbit"],
    "torchgeo_cg.mesh.face_varying": [
        "FVAR_INTERPOLATIONS", "FaceVaryingSubdivision", "ValueMesh", "face_varying_operator",
        "face_varying_subdivide", "face_varying_tags", "value_mesh"
    ],
    "torchgeo_cg.mesh.faces": [
        "check_faces", "face_sizes", "pad_faces", "triangulate_faces", "unpad_faces"
    ],
    "torchgeo_cg.mesh.io": ["Mesh", "from_trimesh", "load_mesh", "save_mesh", "to_trimesh"],
    "torchgeo_cg.mesh.io_obj": ["OBJ_STATEMENTS", "ObjContent", "format_obj", "read_obj"],
    "torchgeo_cg.mesh.io_obj_tags": [
        "OPTION_TAGS", "ObjTags", "check_tags", "format_tags", "parse_tags"
    ],
    "torchgeo_cg.mesh.io_off": ["format_off", "read_off"],
    "torchgeo_cg.mesh.io_ply": [
        "PlyElement", "PlyHeader", "PlyProperty", "format_ply", "read_ply", "read_ply_header"
    ],
    "torchgeo_cg.mesh.io_text": [
        "LineTokens", "TextLines", "blank_comments", "chars_at", "check_padding", "file_error",
        "first_chars", "format_faces", "format_rows", "gather_lines", "line_tokens",
        "parse_numbers", "read_text"
    ],
    "torchgeo_cg.mesh.limit": ["LimitFrames", "limit_frames"],
    "torchgeo_cg.mesh.loop": [
        "LoopSubdivision", "loop_beta", "loop_limit_stencils", "loop_operator", "loop_subdivide"
    ],
    "torchgeo_cg.mesh.marching_cubes": [
        "AMBIGUITY_RULES", "MarchingCubes", "MarchingCubesResult", "marching_cubes"
    ],
    "torchgeo_cg.mesh.regularizers": [
        "MeshEdges", "edge_length_loss", "laplacian_smoothing_loss", "mesh_edges",
        "mesh_laplacian", "normal_consistency_loss"
    ],
    "torchgeo_cg.mesh.stencils": ["StencilMatrix", "apply_stencils", "stencil_matrix"],
    "torchgeo_cg.mesh.subdivision": [
        "CatmullClark", "SubdivisionOperator", "apply_operator", "catmark_limit_stencils",
        "catmull_clark", "catmull_clark_operator", "limit_positions", "mesh_topology"
    ],
    "torchgeo_cg.mesh.tags": ["INFINITELY_SHARP", "SubdivisionTags"],
    "torchgeo_cg.points": [
        "ChamferDistance", "ChamferResult", "ICPResult", "KNNResult", "SampleResult",
        "chamfer_distance", "estimate_normals", "farthest_point_sampling", "icp", "knn"
    ],
    "torchgeo_cg.points.icp": ["ICPResult", "METHODS", "MODELS", "icp"],
    "torchgeo_cg.points.icp_steps": [
        "apply_transform", "point_to_plane_step", "rodrigues", "weighted_procrustes"
    ],
    "torchgeo_cg.points.normals": ["estimate_normals"],
    "torchgeo_cg.points.sampling": ["SampleResult", "farthest_point_sampling"],
    "torchgeo_cg.points.chamfer": ["ChamferDistance", "ChamferResult", "chamfer_distance"],
    "torchgeo_cg.points.nearest_neighbors": [
        "BRUTE_FORCE_PAIRS", "KNNResult", "check_lengths", "knn"
    ],
    "torchgeo_cg.points.search_brute": ["brute_knn_indices"],
    "torchgeo_cg.points.search_grid": [
        "GridIndex", "MAX_RING", "build_grid", "grid_knn_indices", "grid_per_cell",
        "ring_offsets", "segment_ids"
    ],
    "torchgeo_cg.sdf": [
        "Annulus", "Box", "Capsule", "Circle", "Difference", "Gyroid", "Intersection",
        "LevelSetPoints", "MeshSDF", "MeshSDFResult", "Plane", "Product", "Rectangle", "Rotate",
        "SDFSampler", "SDFSamples", "Scale", "SmoothIntersection", "SmoothUnion", "Sphere",
        "Torus", "Translate", "TriangleClosestPoint", "Union", "Volume", "annulus",
        "available_engines", "box", "capsule", "circle", "closest_point_on_triangle",
        "difference", "eikonal_loss", "grid_interpolate", "grid_points", "grid_spacing",
        "gyroid", "index_to_world", "intersection", "is_watertight", "load_samples", "mesh_sdf",
        "plane", "product", "rectangle", "rotate", "sample_grid", "sample_mesh_surface",
        "save_samples", "scale", "sdf_gradient", "sdf_normal", "smooth_intersection",
        "smooth_union", "sphere", "torus", "translate", "union", "winding_number",
        "world_to_index", "zero_level_set"
    ],
    "torchgeo_cg.sdf.engine_warp": [
        "WarpAnswer", "WarpSearch", "build_warp_search", "face_rings", "morton_order",
        "warp_closest_faces"
    ],
    "torchgeo_cg.sdf.engines": [
        "ENGINES", "available_engines", "build_search", "engine_sdf", "new_cache_key",
        "resolve_backend", "search_faces"
    ],
    "torchgeo_cg.sdf.gradients": ["eikonal_loss", "sdf_gradient", "sdf_normal"],
    "torchgeo_cg.sdf.grid": [
        "Volume", "check_spacing", "grid_interpolate", "grid_points", "grid_spacing",
        "index_to_world", "parse_bounds", "sample_grid", "world_to_index"
    ],
    "torchgeo_cg.sdf.level_set": ["LevelSetPoints", "zero_level_set"],
    "torchgeo_cg.sdf.mesh_distance": [
        "FEATURES", "MeshSDF", "MeshSDFResult", "TriangleClosestPoint", "batch_mesh_points",
        "check_mesh", "closest_point_on_triangle", "evaluate_sdf", "gather_triangles",
        "is_watertight", "mesh_sdf", "pseudo_normals", "resolve_sign", "search_and_evaluate",
        "winding_number"
    ],
    "torchgeo_cg.sdf.mesh_search": [
        "FaceGrid", "TorchSearch", "build_torch_search", "face_table", "far_radius", "pair_d2",
        "power_of_two_scale", "pull_in_far_points", "torch_closest_faces"
    ],
    "torchgeo_cg.sdf.operators": [
        "Difference", "Intersection", "Product", "Rotate", "Scale", "SmoothIntersection",
        "SmoothUnion", "Translate", "Union", "difference", "intersection", "product", "rotate",
        "scale", "smooth_intersection", "smooth_union", "translate", "union"
    ],
    "torchgeo_cg.sdf.primitives": [
        "Annulus", "Box", "Capsule", "Circle", "Gyroid", "Plane", "Rectangle", "Sphere",
        "Torus", "annulus", "box", "capsule", "circle", "gyroid", "plane", "rectangle",
        "sphere", "torus"
    ],
    "torchgeo_cg.sdf.sampler": [
        "SDFSampler", "SDFSamples", "load_samples", "sample_mesh_surface", "save_samples",
        "triangle_mesh", "worker_seed"
    ],
    "torchgeo_cg.transforms": [
        "AffineDecomposition", "FitResult", "FixedTransform", "HartleyNormalization",
        "HomogeneousTransform", "HomographyFit", "HomographyModel", "Orbit",
        "RegistrationResult", "ReportShapes", "RobustFit", "SceneGraph", "ShapeFit",
        "TRSTransform", "WarpedImage", "WorldTransforms", "compose", "compose_trs",
        "decompose_affine", "find_affine", "find_euclidean", "find_homography_dlt",
        "find_similarity", "find_transform_ransac", "find_translation", "fit_report_shapes",
        "fit_transform", "hartley_normalize", "homography", "inverse", "matrix_to_parameters",
        "parameters_to_matrix", "register_images", "report_shapes", "reprojection_error",
        "robust_loss", "robust_weights", "rotation", "scale_x", "scale_y", "scaling", "shear",
        "solar_system",
        "transform_points", "translation", "warp_image"
    ],
    "torchgeo_cg.transforms.decompose": ["AffineDecomposition", "decompose_affine"],
    "torchgeo_cg.transforms.correspondences": [
        "HartleyNormalization", "hartley_normalize", "reprojection_error"
    ],
    "torchgeo_cg.transforms.estimation": [
        "find_affine", "find_euclidean", "find_similarity", "find_translation"
    ],
    "torchgeo_cg.transforms.fitting": ["FitResult", "HomographyModel", "fit_transform"],
    "torchgeo_cg.transforms.homogeneous": [
        "compose", "compose_trs", "homography", "inverse", "rotation", "scale_x", "scale_y",
        "scaling", "shear", "transform_points", "translation"
    ],
    "torchgeo_cg.transforms.homography_dlt": ["find_homography_dlt"],
    "torchgeo_cg.transforms.modules": ["HomogeneousTransform", "TRSTransform"],
    "torchgeo_cg.transforms.parametrization": [
        "MODELS", "PARAMETRIZATIONS", "matrix_to_parameters", "parameters_to_matrix"
    ],
    "torchgeo_cg.transforms.ransac": ["RobustFit", "SAMPLE_SIZES", "find_transform_ransac"],
    "torchgeo_cg.transforms.registration": [
        "REGISTRATION_MODELS", "RegistrationResult", "WarpedImage", "register_images",
        "warp_image"
    ],
    "torchgeo_cg.transforms.report_shapes": [
        "REPORT_FORMULAS", "REPORT_NAMES", "ReportShapes", "ShapeFit", "fit_report_shapes",
        "format_report_table", "format_transform", "report_shapes"
    ],
    "torchgeo_cg.transforms.robust": ["LOSSES", "robust_loss", "robust_weights"],
    "torchgeo_cg.transforms.scene_graph": [
        "FixedTransform", "Orbit", "SceneGraph", "WorldTransforms", "solar_system"
    ],
    "torchgeo_cg.viz": ["GalleryFigure", "build_gallery", "figure", "registered_figures"],
    "torchgeo_cg.viz.curves": [],
    "torchgeo_cg.viz.estimation": ["plot_report_fits"],
    "torchgeo_cg.viz.gallery": [
        "build_gallery", "check_output_folder", "check_sections", "load_figure_modules"
    ],
    "torchgeo_cg.viz.glyph_fit": [
        "GlyphFit", "GlyphPieces", "fit_glyph", "glyph_pieces", "glyph_polygon",
        "plot_glyph_fit"
    ],
    "torchgeo_cg.viz.icp": ["plot_icp"],
    "torchgeo_cg.viz.marching_cubes": ["mri_phantom"],
    "torchgeo_cg.viz.registration": ["plot_registration", "plot_robust_fit"],
    "torchgeo_cg.viz.registry": ["GalleryFigure", "figure", "registered_figures"],
    "torchgeo_cg.viz.scans": ["ScanPairs", "rabbit_scan_pairs", "rabbit_surface"],
    "torchgeo_cg.viz.sdf": [],
    "torchgeo_cg.viz.style": ["closed", "plt", "save"],
    "torchgeo_cg.viz.subdivision": [],
    "torchgeo_cg.viz.subdivision_tags": [],
    "torchgeo_cg.viz.torus_fit": [
        "START_RADII", "TRUE_RADII", "TorusFit", "extract_torus", "fit_torus_radii",
        "plot_torus_fit", "sample_torus_surface", "soft_chamfer", "torus_grid_sdf"
    ],
    "torchgeo_cg.viz.transforms": [],
}


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
    """``surface`` as the body of :data:`INVENTORY` (one module per line or block)."""
    import textwrap

    lines = []
    for module, names in surface.items():
        body = ", ".join(f'"{n}"' for n in names)
        one_line = f'    "{module}": [{body}],'
        if len(one_line) <= 96:
            lines.append(one_line)
            continue
        lines.append(f'    "{module}": [')
        lines += [f"        {chunk}" for chunk in textwrap.wrap(body, 88)]
        lines.append("    ],")
    return "\n".join(lines)


if __name__ == "__main__":
    print("INVENTORY: dict[str, list[str]] = {")
    print(format_inventory(current_surface()))
    print("}")
