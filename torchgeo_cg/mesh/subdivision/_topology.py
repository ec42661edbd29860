"""Corner, edge and vertex tables of a padded polygon mesh, and the checks the schemes share.

Every scheme's builder (Catmark, Loop, bilinear, face-varying) and the limit masks read
the same tables, built with sort/unique/bincount and no Python loop over elements.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.core.check import check_float, check_shape, check_tensor


class Topology(NamedTuple):
    """Corner/edge/vertex tables of a padded polygon mesh (all 1-D, long or bool)."""

    face_c: torch.Tensor  # (C,) face of each corner, corners in face-major order
    pos_c: torch.Tensor  # (C,) position of the corner in its face
    vert_c: torch.Tensor  # (C,) vertex at the corner
    next_c: torch.Tensor  # (C,) next vertex in the face (half-edge vert_c -> next_c)
    prev_corner_c: torch.Tensor  # (C,) index of the previous corner of the same face
    size_c: torch.Tensor  # (C,) size of the corner's face
    edge_c: torch.Tensor  # (C,) edge of the half-edge vert_c -> next_c
    edge_lo_e: torch.Tensor  # (E,) smaller endpoint
    edge_hi_e: torch.Tensor  # (E,) larger endpoint
    sharp_e: torch.Tensor  # (E,) bool: not exactly two faces
    valence_v: torch.Tensor  # (V,) number of edges
    num_faces_v: torch.Tensor  # (V,) number of incident faces
    kind_v: torch.Tensor  # (V,) 0 isolated, 1 smooth/dart, 2 crease, 3 corner
    repeat_e: torch.Tensor | None = None  # (E,) bool: a face uses its pair twice (None: none)
    inherited_e: torch.Tensor | None = None  # (E,) bool: non-manifold by the parent level


def check_verts(verts: torch.Tensor, num_vertices: int, name: str = "verts") -> None:
    check_tensor(verts, name)
    check_shape(verts, ["*", "V", "D"], name, {"V": num_vertices})
    check_float(verts, name)


def _edges(lo_c, hi_c, face_c, V, edge_tag_c, repeats: bool):
    """``(edge_c, edge_lo_e, edge_hi_e, repeat_e)``: sides grouped by vertex pair, then
    split by tag; a degenerate side, and (where a face ``repeats`` a vertex) a face's
    later sides on a pair it already used, get a tag of their own (their corner), and
    the edges of such a pair are non-manifold (``repeat_e``, OpenSubdiv's rule)."""
    C = lo_c.numel()
    pair, edge_c = torch.unique(lo_c * max(V, 1) + hi_c, return_inverse=True)
    own = lo_c == hi_c
    if repeats:  # rare: the first side of a face on a pair keeps the shared edge
        within = torch.unique(edge_c * (int(face_c.max()) + 1) + face_c, return_inverse=True)[1]
        order = torch.sort(within, stable=True).indices
        first = torch.ones(C, dtype=torch.bool, device=lo_c.device)
        first[order[1:]] = within[order[1:]] != within[order[:-1]]
        own = own | ~first
        twice_c = torch.zeros(C, dtype=torch.bool, device=lo_c.device)
        twice_c[order[1:]] = ~first[order[1:]]
        twice_c[order[:-1]] |= ~first[order[1:]]  # the first side of a repeated pair too
    if bool(own.any()) or (edge_tag_c is not None and bool((edge_tag_c != 0).any())):
        tag_c = torch.zeros_like(lo_c) if edge_tag_c is None else edge_tag_c.to(lo_c.device)
        offset = int(tag_c.max()) + 1 if C else 1
        tag_c = torch.where(own, offset + torch.arange(C, device=lo_c.device), tag_c)
        key, edge_c = torch.unique(edge_c * (offset + C) + tag_c, return_inverse=True)
        pair = pair[key // (offset + C)]
    repeat_e = None
    if repeats:
        repeat_e = torch.zeros(pair.numel(), dtype=torch.bool, device=lo_c.device)
        repeat_e[edge_c[twice_c]] = True
    return edge_c, pair // max(V, 1), pair % max(V, 1), repeat_e


def mesh_topology(faces_fk: torch.Tensor, num_vertices: int, boundary: str = "edge_only",
                  edge_tag_c: torch.Tensor | None = None) -> Topology:
    """Corner, edge and vertex tables of ``(F, K)`` padded faces (sort/unique/bincount).

    Edges are the faces' sides identified by their two vertices, as OpenSubdiv's
    ``Vtr`` identifies them, except a degenerate side (both ends the same vertex, from a
    face that repeats a vertex), which is an edge of its own, and sides whose corners
    carry different ``edge_tag_c`` (``(C,)`` long, ``0`` by default): a refined level's
    sides between the same two vertices that OpenSubdiv keeps apart (the two halves of
    a degenerate edge, the inner edges of back-to-back triangles). A negative tag marks
    a side of a child of a non-manifold edge: OpenSubdiv's children of a non-manifold
    edge stay non-manifold whatever their faces (``inherited_e``), and such a level is
    a refined one, whose vertices inherit their sharpness instead of deriving it from
    the topology (:mod:`~torchgeo_cg.mesh.subdivision._creasing`).

    Example:
        >>> topo = mesh_topology(torch.tensor([[0, 1, 2]]), 3)
        >>> topo.edge_lo_e.tolist(), topo.edge_hi_e.tolist(), topo.valence_v.tolist()
        ([0, 0, 1], [1, 2, 2], [2, 2, 2])
    """
    V = num_vertices
    valid_fk = faces_fk >= 0
    size_f = valid_fk.sum(1)
    F, K = faces_fk.shape
    if bool(valid_fk.all()):  # no padding (pure triangles or quads): skip nonzero
        face_c = torch.arange(F, device=faces_fk.device).repeat_interleave(K)
        pos_c = torch.arange(K, device=faces_fk.device).repeat(F)
    else:
        face_c, pos_c = torch.nonzero(valid_fk, as_tuple=True)  # face-major, then position
    size_c = size_f[face_c]
    start_c = (torch.cumsum(size_f, 0) - size_f)[face_c]
    vert_c = faces_fk[face_c, pos_c]
    next_c = faces_fk[face_c, (pos_c + 1) % size_c]
    prev_corner_c = start_c + (pos_c - 1) % size_c
    lo_c, hi_c = torch.minimum(vert_c, next_c), torch.maximum(vert_c, next_c)
    ordered = torch.sort(faces_fk, dim=1).values
    repeats = bool(((ordered[:, 1:] == ordered[:, :-1]) & (ordered[:, 1:] >= 0)).any()
                   | (size_f < 3).any())  # a 2-gon uses its pair twice
    inherit_c = None
    if edge_tag_c is not None and bool((edge_tag_c < 0).any()):
        inherit_c = edge_tag_c.to(faces_fk.device) < 0
        edge_tag_c = edge_tag_c.clamp(min=0)  # every side of such an edge is marked
    edge_c, edge_lo_e, edge_hi_e, repeat_e = _edges(lo_c, hi_c, face_c, V, edge_tag_c, repeats)
    E = edge_lo_e.numel()
    inherited_e = None
    if inherit_c is not None:
        inherited_e = torch.bincount(edge_c[inherit_c], minlength=E) > 0
    sharp_e = torch.bincount(edge_c, minlength=E) != 2
    ends = torch.cat([edge_lo_e, edge_hi_e])
    valence_v = torch.bincount(ends, minlength=V)
    sharp_v = torch.bincount(ends[torch.cat([sharp_e, sharp_e])], minlength=V)
    num_faces_v = torch.bincount(vert_c, minlength=V)
    kind_v = torch.ones(V, dtype=torch.long, device=faces_fk.device)
    kind_v[sharp_v == 2] = 2
    if boundary == "edge_and_corner":
        kind_v[(sharp_v == 2) & (valence_v == 2)] = 3
    kind_v[sharp_v > 2] = 3
    kind_v[valence_v == 0] = 0
    return Topology(
        face_c, pos_c, vert_c, next_c, prev_corner_c, size_c, edge_c, edge_lo_e, edge_hi_e,
        sharp_e, valence_v, num_faces_v, kind_v, repeat_e, inherited_e,
    )
