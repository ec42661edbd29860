"""Bilinear subdivision (OpenSubdiv's ``SCHEME_BILINEAR``) as a sparse operator.

The topology splits exactly as Catmull-Clark's (every face into quads at its face
point), but the positions stay on the control polygons: face points are face centroids,
edge points edge midpoints, and vertex points the vertices themselves. Sharpness has no
effect; holes drop their children.

Convention:
    Same vertex order and face order as :func:`~torchgeo_cg.mesh.catmull_clark_operator`:
    ``[vertex points (V0) | face points (F0) | edge points
    (E0)]``, edges sorted by ``(min, max)``; output quads keep the parent's winding.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from torchgeo_cg.mesh.faces import check_faces
from torchgeo_cg.mesh.subdivision._stencil_build import stencil_matrix, weights_dtype
from torchgeo_cg.mesh.subdivision._topology import mesh_topology
from torchgeo_cg.mesh.subdivision.operator import SubdivisionOperator
from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags, check_tags

__all__ = ["bilinear_operator"]


def bilinear_operator(
    faces: torch.Tensor | Sequence[Sequence[int]],
    num_vertices: int,
    device: torch.device | str | None = None,
    dtype: torch.dtype | None = None,
    tags: SubdivisionTags | None = None,
) -> SubdivisionOperator:
    """Build one level of bilinear subdivision as a sparse ``(V1, V0)`` matrix.

    Convention:
        See the module docstring. ``limit_positions`` refuses bilinear operators (the
        limit surface is the control polygon itself).

    Args:
        faces: ``(F0, K)`` long padded with ``-1``, or a list of index lists.
        num_vertices: ``V0``.
        device: device of the operator (default: that of ``faces``).
        dtype: dtype of the weights (default: ``torch.get_default_dtype()``).
        tags: :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags`; only ``holes`` matter
            (their children are left out of ``faces`` and listed in ``child_tags``).

    Returns:
        :class:`~torchgeo_cg.mesh.subdivision.SubdivisionOperator` with scheme
        ``"bilinear"``, ``V1 = V0 + F0 + E0`` and quads ``faces``.

    Raises:
        ValueError: invalid faces or hole ids (the message names them).
        TypeError: a tags index field that is not an integer tensor.
        TypeError: ``dtype`` is not a floating-point dtype.

    Example:
        >>> op = bilinear_operator([[0, 1, 2, 3]], 4)
        >>> square = torch.tensor([[0., 0.], [2., 0.], [2., 2.], [0., 2.]])
        >>> (op.matrix @ square)[4:6], op.scheme
        (tensor([[1., 1.],
                [1., 0.]]), 'bilinear')
    """
    with torch.no_grad():
        faces_fk = check_faces(faces, num_vertices)
        if device is not None:
            faces_fk = faces_fk.to(device)
        wdtype = weights_dtype(dtype)
        V0, F0 = num_vertices, faces_fk.shape[0]
        topo = mesh_topology(faces_fk, V0)
        E0 = topo.edge_lo_e.numel()
        V1 = V0 + F0 + E0
        row_face, row_edge = V0, V0 + F0
        dev = faces_fk.device
        arange_v, arange_e = torch.arange(V0, device=dev), torch.arange(E0, device=dev)
        half = torch.full((E0,), 0.5, dtype=wdtype, device=dev)
        stencils = stencil_matrix(
            torch.cat([arange_v, row_face + topo.face_c, row_edge + arange_e,
                       row_edge + arange_e]),
            torch.cat([arange_v, topo.vert_c, topo.edge_lo_e, topo.edge_hi_e]),
            torch.cat([torch.ones(V0, dtype=wdtype, device=dev),
                       1.0 / topo.size_c.to(wdtype), half, half]),
            (V1, V0),
        )
        faces_q4 = torch.stack(
            [topo.vert_c, row_edge + topo.edge_c, row_face + topo.face_c,
             row_edge + topo.edge_c[topo.prev_corner_c]],
            dim=1,
        )
        child_tags, visible = None, faces_q4
        if tags is not None:
            holes = check_tags(tags).holes.to(dev).long().reshape(-1)
            bad = (holes < 0) | (holes >= F0)
            if bool(bad.any()):
                i = int(torch.nonzero(bad)[0])
                raise ValueError(f"tags.holes: index {int(holes[i])} out of range [0, {F0})")
            hole_f = torch.zeros(F0, dtype=torch.bool, device=dev)
            hole_f[holes] = True
            hole_child = hole_f[topo.face_c]
            real = tags.crease_sharpness.dtype
            child_tags = SubdivisionTags.empty(real, dev)._replace(
                holes=torch.nonzero(hole_child).flatten()
            )
            visible = faces_q4[~hole_child]
    return SubdivisionOperator(
        stencils, visible, V0, V1, F0, E0, "edge_only", "bilinear", faces_q4, child_tags
    )
