"""The docstrings of torchgeo_cg.sdf: every public function gives an example, its returns
and (where geometric) its convention."""

from __future__ import annotations

import inspect

import torchgeo_cg.sdf as sdf


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
