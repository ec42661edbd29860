"""The scheme-neutral subdivision operator: one level as a sparse matrix, and its application.

A scheme's builder (:func:`~torchgeo_cg.mesh.subdivision.catmull_clark_operator`,
:func:`~torchgeo_cg.mesh.subdivision.loop_operator`,
:func:`~torchgeo_cg.mesh.subdivision.bilinear_operator`) turns the topology into a
:class:`SubdivisionOperator` once; :func:`apply_operator` refines any per-vertex data
with one sparse matmul, ``V1 = S @ V0``, and backward multiplies by the cached ``S^T``.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.mesh.subdivision._stencil_build import StencilMatrix
from torchgeo_cg.mesh.subdivision._topology import check_verts
from torchgeo_cg.mesh.subdivision.stencils import apply_stencils
from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags

__all__ = ["SubdivisionOperator", "apply_operator"]


class SubdivisionOperator(NamedTuple):
    """One level of subdivision, built once from the topology.

    Attributes:
        stencils: the ``(V1, V0)`` stencil matrix ``S`` (``V1 = S @ V0``) and its
            transpose as plain CSR tensors
            (:class:`~torchgeo_cg.mesh.subdivision.stencils.StencilMatrix`).
        faces: ``(F1, 4)`` long output quads (Loop: ``(F1, 3)`` triangles).
        num_vertices_in: ``V0``.
        num_vertices_out: ``V1 = V0 + F0 + E0`` (Loop: ``V0 + E0``).
        num_faces_in: ``F0`` (Catmark face points start at row ``V0``).
        num_edges_in: ``E0`` (edge points start at row ``V0 + F0``; Loop: ``V0``).
        boundary: the boundary rule this level was built with
            (``SchemeOptions.boundary``; ``"none"`` acts
            at the base level only, later levels record ``"edge_only"``).
        scheme: ``"catmark"`` or ``"loop"``, the rules that built it.
        child_faces: every child face, holes' children included (what the next level
            is built from); ``faces`` is this without the holes' children.
        child_tags: :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` of the refined
            mesh (child creases with their decayed sharpness, corners, holes as rows
            of ``child_faces``), or ``None`` for an untagged mesh without holes.
        child_edge_tags: ``(C1,)`` long per corner of ``child_faces`` (face-major): sides
            between the same two vertices that are distinct edges (the halves of a
            degenerate edge, the inner edges of back-to-back triangles) carry different
            tags; the sides of the children of a non-manifold edge with two or more
            faces carry ``-1`` (OpenSubdiv keeps them non-manifold, infinitely sharp);
            ``None`` where there are none. The next level's builder takes them as
            ``edge_tags``.

    The properties ``matrix`` and ``matrix_t`` give ``S`` and ``S^T`` as
    ``torch.sparse_csr`` tensors (built on use; they share the stencils' memory).

    Example:
        >>> from torchgeo_cg.mesh.subdivision import catmull_clark_operator
        >>> op = catmull_clark_operator([[0, 1, 2]], 3)  # rows: 3 vertex, 1 face, 3 edge points
        >>> op.matrix.shape, op.faces.tolist(), op.scheme
        (torch.Size([7, 3]), [[0, 4, 3, 5], [1, 6, 3, 4], [2, 5, 3, 6]], 'catmark')
    """

    stencils: StencilMatrix
    faces: torch.Tensor
    num_vertices_in: int
    num_vertices_out: int
    num_faces_in: int
    num_edges_in: int
    boundary: str
    scheme: str = "catmark"
    child_faces: torch.Tensor | None = None
    child_tags: SubdivisionTags | None = None
    child_edge_tags: torch.Tensor | None = None

    @property
    def matrix(self) -> torch.Tensor:
        """``(V1, V0)`` sparse CSR stencil matrix."""
        return self.stencils.sparse()

    @property
    def matrix_t(self) -> torch.Tensor:
        """``(V0, V1)`` sparse CSR transpose (what backward applies)."""
        return self.stencils.sparse_t()


def apply_operator(operator: SubdivisionOperator, verts: torch.Tensor, *,
                   out: torch.Tensor | None = None) -> torch.Tensor:
    """Refine per-vertex data with one operator: ``(*, V0, D) -> (*, V1, D)``.

    Convention:
        Rows are vertices (``verts[..., i, :]`` is vertex ``i``); ``D`` is any
        width, so positions, UVs and features refine alike. Differentiable in
        ``verts``; backward applies ``S^T`` from ``operator.stencils``. The
        weights are cast to ``verts``' dtype and device when they differ. Works
        under ``torch.compile(fullgraph=True)``, ``torch.func.vmap`` and ``jacrev``.
        ``out`` writes the result into a caller's buffer (no output allocation, which
        for large batches is mostly page faults); like torch's ``out=`` it is outside
        autograd (an error where grad mode is on and ``verts`` or ``out`` requires
        grad) and eager only (see
        :func:`~torchgeo_cg.mesh.subdivision.stencils.apply_stencils`).

    Args:
        operator: from :func:`catmull_clark_operator`.
        verts: ``(*, V0, D)`` float.
        out: optional ``(*, V1, D)`` buffer of ``verts``' dtype and device.

    Returns:
        ``(*, V1, D)`` (``out`` itself when given).

    Raises:
        ShapeError: ``verts`` is not ``(*, V0, D)``, or ``out`` not ``(*, V1, D)``.
        TypeError: ``verts`` is not floating, or ``out`` has another dtype.
        ValueError: ``out`` on another device, needing autograd, or under a transform.

    Example:
        >>> from torchgeo_cg.mesh.subdivision import catmull_clark_operator
        >>> op = catmull_clark_operator([[0, 1, 2]], 3)
        >>> apply_operator(op, torch.tensor([[0., 0.], [3., 0.], [0., 3.]]))[3:5]
        tensor([[1.0000, 1.0000],
                [1.5000, 0.0000]])
        >>> buffer = torch.empty(7, 2)
        >>> apply_operator(op, torch.tensor([[0., 0.], [3., 0.], [0., 3.]]), out=buffer)[3]
        tensor([1., 1.])
    """
    check_verts(verts, operator.num_vertices_in)
    return apply_stencils(operator.stencils, verts, out=out)
