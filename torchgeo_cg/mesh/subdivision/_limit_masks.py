"""Limit masks of the Catmark and Loop schemes as ``(V, V)`` stencil matrices, and Loop's beta.

Catmark (Halstead et al. 1993): smooth vertex of valence ``n``:
``(n^2 V + 4 sum e_i + sum d_i) / (n (n + 5))``. Loop: smooth vertex
``(1 - n chi) V + chi sum e_i``, ``chi = 1 / (n + 3 / (8 beta))``. Both: crease vertex
``(a + 4 V + b) / 6``, corners ``V``.
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.mesh.subdivision._creasing import limit_rules
from torchgeo_cg.mesh.subdivision._stencil_build import StencilMatrix, stencil_matrix
from torchgeo_cg.mesh.subdivision._topology import mesh_topology
from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags


def catmark_limit_stencils(
    faces_q4: torch.Tensor,
    num_vertices: int,
    boundary: str,
    dtype: torch.dtype,
    tags: SubdivisionTags | None = None,
    edge_tags: torch.Tensor | None = None,
) -> StencilMatrix:
    """``(V, V)`` Catmark limit masks of an all-quad mesh (see :func:`limit_positions`).

    Example:
        >>> catmark_limit_stencils(torch.tensor([[0, 1, 2, 3]]), 4, "edge_only",
        ...                        torch.float64).dense()[0] * 6
        tensor([4., 1., 0., 1.], dtype=torch.float64)
    """
    V1 = num_vertices
    with torch.no_grad():
        topo = mesh_topology(faces_q4, V1, boundary, edge_tags)
        dev, wdtype = faces_q4.device, dtype
        n_v = topo.valence_v.to(wdtype).clamp(min=1)
        m_v = topo.num_faces_v.to(wdtype).clamp(min=1)
        rule_v, sharp_e = limit_rules(topo, V1, faces_q4.shape[0], tags, boundary, wdtype)
        kind_v = rule_v + 1  # 1 smooth, 2 crease, 3 corner
        kind_v = torch.where((kind_v == 1) & (topo.num_faces_v == 2), 3, kind_v)  # OpenSubdiv:
        smooth_v, crease_v = kind_v == 1, kind_v == 2  # a smooth 2-face vertex takes V
        self_v = torch.where(smooth_v, n_v / (n_v + 5), 1.0 - crease_v.to(wdtype) / 3.0)
        v_side = torch.cat([topo.edge_lo_e, topo.edge_hi_e])
        nbr_side = torch.cat([topo.edge_hi_e, topo.edge_lo_e])
        sharp_side = torch.cat([sharp_e, sharp_e])
        kind_side = kind_v[v_side]
        w_side = torch.where(
            kind_side == 1,
            4.0 / (n_v[v_side] * (n_v[v_side] + 5)),
            ((kind_side == 2) & sharp_side).to(wdtype) / 6.0,
        )
        # opposite corner of each quad corner: two steps along the face
        diag_c = topo.vert_c[topo.prev_corner_c[topo.prev_corner_c]]
        v_c = topo.vert_c
        w_c = torch.where(smooth_v[v_c], 1.0 / (m_v[v_c] * (n_v[v_c] + 5)), 0.0)
        arange_v = torch.arange(V1, device=dev)
        limit = stencil_matrix(
            torch.cat([arange_v, v_side, v_c]),
            torch.cat([arange_v, nbr_side, diag_c]),
            torch.cat([self_v.to(wdtype), w_side.to(wdtype), w_c.to(wdtype)]),
            (V1, V1),
        )
    return limit


def loop_beta(valence: torch.Tensor) -> torch.Tensor:
    """Loop's neighbour weight ``beta = (5/8 - (3/8 + 1/4 cos(2 pi / n))^2) / n``.

    Args:
        valence: ``(*,)`` float vertex valences ``n >= 1``.

    Returns:
        ``(*,)`` float ``beta``.

    Example:
        >>> loop_beta(torch.tensor([3.0, 6.0]))  # 3/16 and 1/16
        tensor([0.1875, 0.0625])
    """
    cos_v = torch.cos(2.0 * math.pi / valence)
    return (0.625 - (0.375 + 0.25 * cos_v) ** 2) / valence


def loop_limit_stencils(
    faces_f3: torch.Tensor,
    num_vertices: int,
    boundary: str,
    dtype: torch.dtype,
    tags: SubdivisionTags | None = None,
    edge_tags: torch.Tensor | None = None,
) -> StencilMatrix:
    """``(V, V)`` Loop limit masks of a triangle mesh (OpenSubdiv's Loop limit masks).

    Smooth vertex of valence ``n``: ``(1 - n chi) V + chi sum(nbrs)`` with
    ``chi = 1 / (n + 3 / (8 beta))``; crease/boundary vertex ``(a + 4 V + b) / 6``
    (``a, b`` its sharp neighbours); corners and unreferenced vertices ``V``.

    Example:
        >>> ring = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [0, 5, 6], [0, 6, 1]]
        >>> loop_limit_stencils(torch.tensor(ring), 7, "edge_only", torch.float64).dense()[0] * 12
        tensor([6., 1., 1., 1., 1., 1., 1.], dtype=torch.float64)
    """
    V = num_vertices
    with torch.no_grad():
        topo = mesh_topology(faces_f3, V, boundary, edge_tags)
        n_v = topo.valence_v.to(dtype).clamp(min=1)
        chi_v = 1.0 / (n_v + 3.0 / (8.0 * loop_beta(n_v)))
        rule_v, sharp_e = limit_rules(topo, V, faces_f3.shape[0], tags, boundary, dtype)
        smooth_v, crease_v = rule_v == 0, rule_v == 1
        self_v = torch.where(smooth_v, 1.0 - n_v * chi_v, 1.0 - crease_v.to(dtype) / 3.0)
        v_side = torch.cat([topo.edge_lo_e, topo.edge_hi_e])
        nbr_side = torch.cat([topo.edge_hi_e, topo.edge_lo_e])
        sharp_side = torch.cat([sharp_e, sharp_e])
        rule_side = rule_v[v_side]
        w_side = torch.where(
            rule_side == 0, chi_v[v_side], ((rule_side == 1) & sharp_side).to(dtype) / 6.0
        )
        arange_v = torch.arange(V, device=faces_f3.device)
        return stencil_matrix(
            torch.cat([arange_v, v_side]), torch.cat([arange_v, nbr_side]),
            torch.cat([self_v, w_side]), (V, V),
        )
