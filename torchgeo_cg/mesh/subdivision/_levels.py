"""The shared machinery of the subdivision modules: one cached operator per level."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import torch
from torch import nn

from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.mesh.faces import check_faces
from torchgeo_cg.mesh.subdivision._stencil_build import StencilMatrix, check_out
from torchgeo_cg.mesh.subdivision._topology import check_verts
from torchgeo_cg.mesh.subdivision.operator import SubdivisionOperator
from torchgeo_cg.mesh.subdivision.options import SchemeOptions
from torchgeo_cg.mesh.subdivision.stencils import apply_stencils
from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags


def children_options(options: SchemeOptions) -> SchemeOptions:
    """The options of the levels after the first: OpenSubdiv applies boundary ``"none"``
    (boundary faces become holes) at the base level only; their children stay holes."""
    return replace(options, boundary="edge_only") if options.boundary == "none" else options


class SubdivisionModule(nn.Module):
    """Shared machinery: one cached operator per level, applied by sparse matmuls."""

    scheme = ""  # the subclass's scheme name

    @staticmethod
    def _build_operator(faces, num_vertices, dtype=None, tags=None, edge_tags=None, *,
                        options=SchemeOptions()) -> SubdivisionOperator:
        raise NotImplementedError

    def __init__(
        self,
        faces: torch.Tensor | Sequence[Sequence[int]],
        num_vertices: int,
        levels: int = 1,
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
        tags: SubdivisionTags | None = None,
        *,
        options: SchemeOptions = SchemeOptions(),
    ) -> None:
        super().__init__()
        if isinstance(levels, bool) or not isinstance(levels, int) or levels < 0:
            raise ValueError(f"levels: expected an int >= 0, got {levels!r}")
        self.levels, self.options = levels, SchemeOptions.check(options)
        self.num_vertices_in = num_vertices
        faces_fk = check_faces(faces, num_vertices, allow_duplicates=True, allow_degenerate=True)
        if device is not None:
            faces_fk = faces_fk.to(device)
        self.register_buffer("faces_0", faces_fk, persistent=False)
        count = num_vertices
        self.sizes: list[tuple[int, int, int, int]] = []  # (V_in, V_out, F_in, E_in)
        self._child_tag_levels: list[bool] = []
        level_options, edge_tags = options, None
        for level in range(levels):  # loop over levels only
            op = self._build_operator(faces_fk, count, dtype=dtype, tags=tags,
                                      edge_tags=edge_tags, options=level_options)
            for field, tensor in zip(StencilMatrix._fields, op.stencils):
                self.register_buffer(f"{field}_{level}", tensor, persistent=False)
            self.register_buffer(f"faces_{level + 1}", op.faces, persistent=False)
            self.register_buffer(f"child_faces_{level + 1}", op.child_faces, persistent=False)
            self.register_buffer(f"child_edge_tags_{level + 1}", op.child_edge_tags,
                                 persistent=False)
            self._child_tag_levels.append(op.child_tags is not None)
            if op.child_tags is not None:
                for field, tensor in zip(SubdivisionTags._fields, op.child_tags):
                    self.register_buffer(f"tags_{field}_{level + 1}", tensor, persistent=False)
            self.sizes.append(
                (op.num_vertices_in, op.num_vertices_out, op.num_faces_in, op.num_edges_in)
            )
            faces_fk, count, tags = op.child_faces, op.num_vertices_out, op.child_tags
            edge_tags = op.child_edge_tags
            # OpenSubdiv applies boundary "none" (boundary faces become holes) at the base
            # level only; the children of those holes are holes of the next levels
            level_options = children_options(options)
        self.num_vertices_out = count

    @property
    def faces(self) -> torch.Tensor:
        """``(F_L, 4)`` (Loop: ``(F_L, 3)``) long faces of the last level (input faces,
        padded, when ``levels = 0``)."""
        return getattr(self, f"faces_{self.levels}")

    def operator(self, level: int) -> SubdivisionOperator:
        """The cached :class:`SubdivisionOperator` of step ``level`` (0-based)."""
        if not 0 <= level < self.levels:
            raise IndexError(f"level: expected 0 <= level < {self.levels}, got {level}")
        v_in, v_out, f_in, e_in = self.sizes[level]
        tags = None
        if self._child_tag_levels[level]:
            tags = SubdivisionTags(
                *(getattr(self, f"tags_{f}_{level + 1}") for f in SubdivisionTags._fields)
            )
        options = children_options(self.options) if level else self.options
        return SubdivisionOperator(
            self._stencils(level), getattr(self, f"faces_{level + 1}"),
            v_in, v_out, f_in, e_in, options.boundary, self.scheme,
            getattr(self, f"child_faces_{level + 1}"), tags,
            getattr(self, f"child_edge_tags_{level + 1}"),
        )

    def _stencils(self, level: int) -> StencilMatrix:
        return StencilMatrix(*(getattr(self, f"{f}_{level}") for f in StencilMatrix._fields))

    def forward(self, verts: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
        """Refine ``(*, V, D)`` -> ``(*, V_L, D)``; ``out`` (optional, ``(*, V_L, D)``) takes
        the last level's result as in
        :func:`~torchgeo_cg.mesh.subdivision.apply_operator` (outside autograd)."""
        check_module_dtype(self, verts, "verts", exclude=("tags_",))  # tags built the operators
        check_verts(verts, self.num_vertices_in)
        if out is not None and self.levels == 0:
            check_out(out, tuple(verts.shape), verts)
            return out.copy_(verts)
        for level in range(self.levels):
            last = level == self.levels - 1
            verts = apply_stencils(self._stencils(level), verts, out=out if last else None)
        return verts

    def extra_repr(self) -> str:
        return (
            f"levels={self.levels}, options={self.options!r}, "
            f"num_vertices={self.num_vertices_in} -> {self.num_vertices_out}"
        )
