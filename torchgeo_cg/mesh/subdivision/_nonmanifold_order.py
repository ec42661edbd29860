"""OpenSubdiv's order of the edges and faces around refined vertices of non-manifold parts.

OpenSubdiv's limit tangent masks (``Sdc::Scheme::assign*LimitTangentMasks``) weight a
vertex's incident edges and faces by their position in its vertex-edge and vertex-face
lists. ``Vtr::Level`` sorts those lists counter-clockwise only around manifold vertices
of the base mesh; a non-manifold vertex keeps the order they were built in, and one
level of refinement derives the children's lists from the parents' lists. This module
rebuilds those lists, as ranked ``(vertex, rank, neighbour)`` rows, for the refined
vertices whose order is not a counter-clockwise fan.

Convention:
    The operator's input mesh is OpenSubdiv's base mesh. Its edges are numbered in the
    order their first side appears (faces in order, sides in face order), a side that
    repeats a pair its face already used, and a degenerate side, starting an edge of its
    own. A base vertex is non-manifold when it ends a non-manifold edge (three or more
    faces, two faces traversing it the same way, a face using it twice, degenerate) or
    its faces form more than one fan. After one level:

    - the child of a non-manifold vertex ``v``: edges to the edge points of ``v``'s edges
      by edge number (a degenerate edge twice); faces the children at ``v``'s corners,
      corners in face-major order;
    - the child of a non-manifold edge whose sides ``s_0 < s_1 < ..`` (face-major) run
      ``a_i -> b_i``: Catmark, edges to ``b_0``, the face point of ``s_0``, ``a_0``,
      then the face points of ``s_1, s_2, ..``; faces the children at ``b_i`` then at
      ``a_i`` for each side. Loop, edges to ``b_0``, the edge points of the sides after
      and before ``s_0`` in its face, ``a_0``, then those two edge points of each later
      side.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.mesh.subdivision._creasing import component_labels

__all__: list[str] = []


class Neighbourhoods(NamedTuple):
    """Ranked neighbours of the refined vertices in ``vertex_mask`` (all 1-D)."""

    vertex_mask: torch.Tensor  # (V1,) bool: refined vertices listed here
    vert_e: torch.Tensor  # (N,) refined vertex of each edge row
    rank_e: torch.Tensor  # (N,) position of the edge in the vertex's edge list
    other_e: torch.Tensor  # (N,) the edge's other end
    sharp_e: torch.Tensor  # (N,) bool: the edge is sharp
    vert_f: torch.Tensor  # (M,) refined vertex of each face row (Catmark only)
    rank_f: torch.Tensor  # (M,) position of the face in the vertex's face list
    diag_f: torch.Tensor  # (M,) the face's vertex opposite the refined vertex


class _Corners(NamedTuple):
    vert: torch.Tensor  # (C0,) base vertex of each base corner (face-major)
    edge: torch.Tensor  # (C0,) base edge of the side leaving the corner
    face: torch.Tensor  # (C0,) base face
    nxt: torch.Tensor  # (C0,) next corner of the face
    prv: torch.Tensor  # (C0,) previous corner of the face
    child: torch.Tensor  # (C0,) row of the corner's child face in ``child_faces``
    pos: torch.Tensor  # (C0,) position in the face


def _base_corners(operator) -> _Corners:
    """The base mesh's corners, read back from the child faces (each corner's child
    face starts at the corner's vertex point, then the edge point of its side)."""
    ch = operator.child_faces
    dev = ch.device
    V0 = operator.num_vertices_in
    if operator.scheme == "catmark":
        C0 = ch.shape[0]
        face = ch[:, 2] - V0
        size_f = torch.bincount(face, minlength=operator.num_faces_in)
        idx = torch.arange(C0, device=dev)
        pos = idx - (torch.cumsum(size_f, 0) - size_f)[face]
        size = size_f[face]
        child = idx
        edge = ch[:, 1] - (V0 + operator.num_faces_in)
    else:
        F0 = ch.shape[0] // 4
        idx = torch.arange(3 * F0, device=dev)
        face, pos = idx // 3, idx % 3
        size = torch.full_like(idx, 3)
        child = 4 * face + pos
        edge = ch[child, 1] - V0
    vert = ch[child, 0]
    nxt = idx - pos + (pos + 1) % size
    prv = idx - pos + (pos - 1) % size
    return _Corners(vert, edge, face, nxt, prv, child, pos)


def _nonmanifold(cs: _Corners, V0: int, E0: int):
    """``(nm_v (V0,), nm_e (E0,), first_e (E0,))``: OpenSubdiv's non-manifold base
    vertices and edges, and the first side of each edge."""
    dev = cs.vert.device
    C0 = cs.vert.numel()
    idx = torch.arange(C0, device=dev)
    count_e = torch.bincount(cs.edge, minlength=E0)
    first_e = torch.full((E0,), C0, dtype=torch.long, device=dev).scatter_reduce(
        0, cs.edge, idx, "amin")
    head = cs.vert[cs.nxt]
    same_way = torch.bincount(cs.edge, weights=(cs.vert == cs.vert[first_e[cs.edge]]).double(),
                              minlength=E0)
    lo, hi = torch.minimum(cs.vert, head), torch.maximum(cs.vert, head)
    pair = torch.unique(lo * V0 + hi, return_inverse=True)[1]
    _, inv, uses = torch.unique(cs.face * C0 + pair, return_inverse=True, return_counts=True)
    nm_c = (uses[inv] > 1) | (cs.vert == head)  # a face using a pair twice; degenerate
    nm_e = (count_e > 2) | ((count_e == 2) & (same_way == 2))
    nm_e[cs.edge[nm_c]] = True
    # fans: corners joined across manifold edges
    manifold = (count_e == 2) & ~nm_e
    h1 = first_e[manifold]
    order = torch.argsort(cs.edge * C0 + idx)
    starts = torch.cumsum(count_e, 0) - count_e
    h2 = order[starts[manifold] + 1]
    label = component_labels(C0, torch.cat([h1, h2]), torch.cat([cs.nxt[h2], cs.nxt[h1]]))
    fans_v = torch.bincount(cs.vert[label == idx], minlength=V0)
    nm_v = fans_v > 1
    nm_v[cs.vert[nm_e[cs.edge]]] = True
    nm_v[head[nm_e[cs.edge]]] = True
    return nm_v, nm_e, first_e


def _ranks(vert: torch.Tensor, key: torch.Tensor) -> torch.Tensor:
    """Position of each row among the rows of its vertex, ordered by ``key``."""
    order = torch.argsort(key)
    order = order[torch.sort(vert[order], stable=True).indices]
    sorted_v = vert[order]
    count = torch.bincount(sorted_v)
    start = (torch.cumsum(count, 0) - count)[sorted_v]
    rank = torch.empty_like(vert)
    rank[order] = torch.arange(vert.numel(), device=vert.device) - start
    return rank


def nonmanifold_neighbourhoods(operator, edge1_c: torch.Tensor, sharp1_e: torch.Tensor
                               ) -> Neighbourhoods:
    """OpenSubdiv's edge and face lists of the children of the non-manifold base vertices
    and edges of ``operator`` (see the module docstring). ``edge1_c`` is the edge of each
    corner of ``operator.child_faces`` and ``sharp1_e`` the refined edges' sharpness."""
    cs = _base_corners(operator)
    V0, E0, V1 = operator.num_vertices_in, operator.num_edges_in, operator.num_vertices_out
    catmark = operator.scheme == "catmark"
    row_edge = V1 - E0
    nm_v, nm_e, first_e = _nonmanifold(cs, V0, E0)
    sharp_at = lambda corner1: sharp1_e[edge1_c[corner1]]  # noqa: E731
    side = torch.nonzero(nm_e[cs.edge]).flatten()  # sides of non-manifold edges
    i_s = _ranks(cs.edge[side], side)  # the side's position among its edge's sides
    edge_rows = _edge_child_rows_catmark if catmark else _edge_child_rows_loop
    rows = [_vertex_child_rows(cs, nm_v, first_e, row_edge, 4 if catmark else 3, sharp_at),
            *edge_rows(cs, side, i_s, V0, row_edge, sharp_at)]
    vert_e, key_e, other_e, sharp_e = (torch.cat(part) for part in zip(*rows))
    mask = torch.zeros(V1, dtype=torch.bool, device=cs.vert.device)
    mask[:V0] = nm_v
    mask[row_edge:] = nm_e
    vert_f = rank_f = diag_f = torch.zeros(0, dtype=torch.long, device=cs.vert.device)
    if catmark:
        vert_f, rank_f, diag_f = _child_faces_catmark(cs, nm_v, side, i_s, V0, row_edge)
    return Neighbourhoods(mask, vert_e, _ranks(vert_e, key_e), other_e, sharp_e,
                          vert_f, rank_f, diag_f)


def _vertex_child_rows(cs, nm_v, first_e, row_edge, K1, sharp_at):
    """``(vertex, key, other, sharp)`` edge rows of the children of non-manifold vertices:
    each base edge's two ends in edge-number order (its first side's corner, then end)."""
    c_e = first_e
    e_all = torch.arange(c_e.numel(), device=c_e.device)
    ends = torch.cat([cs.vert[c_e], cs.vert[cs.nxt[c_e]]])
    key = torch.cat([2 * c_e, 2 * c_e + 1])
    other = torch.cat([row_edge + e_all, row_edge + e_all])
    sharp = torch.cat([sharp_at(cs.child[c_e] * K1), sharp_at(cs.child[cs.nxt[c_e]] * K1
                                                               + K1 - 1)])
    keep = nm_v[ends]
    return ends[keep], key[keep], other[keep], sharp[keep]


def _edge_child_rows_catmark(cs, side, i_s, V0, row_edge, sharp_at):
    """Edge rows of Catmark edge points: ``b_0``, face point 0, ``a_0``, face points 1..
    (child quad of corner ``c``: vertex point, edge point, face point, edge point)."""
    ep, fp = row_edge + cs.edge[side], V0 + cs.face[side]
    first = i_s == 0
    f0, n0, later = side[first], cs.nxt[side[first]], side[~first]
    lead = torch.zeros_like(f0)
    return [(ep[first], lead, cs.vert[n0], sharp_at(cs.child[n0] * 4 + 3)),
            (ep[first], lead + 1, fp[first], sharp_at(cs.child[f0] * 4 + 1)),
            (ep[first], lead + 2, cs.vert[f0], sharp_at(cs.child[f0] * 4)),
            (ep[~first], i_s[~first] + 2, fp[~first], sharp_at(cs.child[later] * 4 + 1))]


def _edge_child_rows_loop(cs, side, i_s, V0, row_edge, sharp_at):
    """Edge rows of Loop edge points: ``b_0``, the edge points after and before side 0 in
    its face, ``a_0``, then those two of each later side (child triangles of a face: one
    per corner, vertex point first, then the middle one of its three edge points)."""
    ep = row_edge + cs.edge[side]
    first = i_s == 0
    f0, n0 = side[first], cs.nxt[side[first]]
    mid = (4 * cs.face[side] + 3) * 3  # the middle child's first corner
    lead = torch.zeros_like(f0)
    return [(ep[first], lead, cs.vert[n0], sharp_at(cs.child[n0] * 3 + 2)),
            (ep, torch.where(first, 1, 2 * i_s + 2), row_edge + cs.edge[cs.nxt[side]],
             sharp_at(mid + cs.pos[side])),
            (ep, torch.where(first, 2, 2 * i_s + 3), row_edge + cs.edge[cs.prv[side]],
             sharp_at(mid + cs.pos[cs.prv[side]])),
            (ep[first], lead + 3, cs.vert[f0], sharp_at(cs.child[f0] * 3))]


def _child_faces_catmark(cs, nm_v, side, i_s, V0, row_edge):
    """``(vertex, rank, opposite vertex)`` face rows: a non-manifold vertex's child at each
    of its corners (opposite: the face point); an edge point's children at the head, then
    the tail of each side (opposite: the edge point of the next, the previous side)."""
    corner = torch.nonzero(nm_v[cs.vert]).flatten()
    ep = row_edge + cs.edge[side]
    vert = torch.cat([cs.vert[corner], ep, ep])
    rank = torch.cat([_ranks(cs.vert[corner], corner), 2 * i_s, 2 * i_s + 1])
    diag = torch.cat([V0 + cs.face[corner], row_edge + cs.edge[cs.nxt[side]],
                      row_edge + cs.edge[cs.prv[side]]])
    return vert, rank, diag
