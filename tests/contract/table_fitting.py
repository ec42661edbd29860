"""Contract entries of scene graph, report shapes, Bezier fitting, marching squares.

``ENTRIES`` join ``table.TABLE``; ``PENDING`` names are not yet under contract;
``EXEMPT`` names have no geometry (result types, exceptions, validators).
"""

from __future__ import annotations

from tests.contract.spec import Entry

__all__ = ["ENTRIES", "PENDING", "EXEMPT"]

ENTRIES: list[Entry] = []

PENDING: dict[str, tuple[str, str]] = {
    "transforms.FixedTransform": ("i10", "not yet under contract"),
    "transforms.Orbit": ("i10", "not yet under contract"),
    "transforms.SceneGraph": ("i10", "not yet under contract"),
    "transforms.WorldTransforms": ("i10", "not yet under contract"),
    "transforms.solar_system": ("i10", "not yet under contract"),
    "transforms.ReportShapes": ("i10", "not yet under contract"),
    "transforms.ShapeFit": ("i10", "not yet under contract"),
    "transforms.fit_report_shapes": ("i10", "not yet under contract"),
    "transforms.report_shapes": ("i10", "not yet under contract"),
    "curves.BezierFit": ("i10", "not yet under contract"),
    "curves.fit_bezier": ("i10", "not yet under contract"),
    "curves.fit_parameters": ("i10", "not yet under contract"),
    "curves.MarchingSquaresResult": ("i10", "not yet under contract"),
    "curves.marching_squares": ("i10", "not yet under contract"),
}

EXEMPT: dict[str, str] = {}
