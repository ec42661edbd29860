"""Edge tags of a refined level: the sides between the same two vertices that OpenSubdiv
keeps apart as distinct edges.

OpenSubdiv identifies the base mesh's edges by their two vertices (a degenerate side of a
face that repeats a vertex is an edge of its own), and every refined edge by its parent:
the two halves of an edge and the inner edges of a face. Two refined sides on the same
two vertices can therefore be distinct edges: the halves of a degenerate edge (both run
between its vertex and its midpoint), and the inner edges of faces that share all their
edges (back-to-back or repeated triangles, whose edge points coincide). The operators
give such sides of their child faces a nonzero tag per corner (``child_edge_tags``), which
:func:`~torchgeo_cg.mesh.subdivision._topology.mesh_topology` keeps apart; ``None`` when
there are none, the common case.

The same tags carry what OpenSubdiv's children inherit from a non-manifold edge with two
or more faces: its two children stay non-manifold (infinitely sharp) even where their
faces look manifold, as the children of an edge a 2-gon or a face ``[a, a, b]`` uses
twice do. Their sides get the tag ``-1``.
"""

from __future__ import annotations

import torch


def catmark_child_edge_tags(topo, inherit_e: torch.Tensor) -> torch.Tensor | None:
    """``(C1,)`` tags of the child quads' corners (child ``c`` is the quad at corner ``c``):
    the far half of a degenerate edge (corner 3 of the next child) gets 1, the halves of
    an ``inherit_e`` edge ``-1``. Inner edges end at the face point, unique to the face,
    so they need none."""
    degenerate_e = topo.edge_lo_e == topo.edge_hi_e
    if not (bool(degenerate_e.any()) or bool(inherit_e.any())):
        return None
    mark_e = degenerate_e.long() - inherit_e.long()  # a degenerate edge has one face
    tags = torch.zeros(topo.vert_c.numel(), 4, dtype=torch.long, device=topo.vert_c.device)
    tags[:, 0] = -inherit_e[topo.edge_c].long()
    tags[:, 3] = mark_e[topo.edge_c[topo.prev_corner_c]]
    return tags.flatten()


def _shares_vertices(faces_f3: torch.Tensor) -> torch.Tensor:
    """``(F,)`` bool: the triangles whose vertex set is another triangle's too."""
    key = torch.sort(faces_f3, dim=1).values
    V = int(key.max()) + 1 if key.numel() else 1
    if V ** 3 < 2 ** 62:  # one integer per set: a 1D unique, much faster than unique(dim=0)
        key = (key[:, 0] * V + key[:, 1]) * V + key[:, 2]
        _, inverse, counts = torch.unique(key, return_inverse=True, return_counts=True)
    else:
        _, inverse, counts = torch.unique(key, dim=0, return_inverse=True, return_counts=True)
    return counts[inverse] > 1


def loop_child_edge_tags(faces_f3: torch.Tensor, topo,
                         inherit_e: torch.Tensor) -> torch.Tensor | None:
    """``(12 F,)`` tags of the child triangles' corners (children ``4 f + k``: the corner
    triangles, then the middle one): the far half of a degenerate edge gets 1, the halves
    of an ``inherit_e`` edge ``-1``, and the inner edges of a face sharing its vertices
    with another face get ``2 + f``."""
    F = faces_f3.shape[0]
    degenerate_e = topo.edge_lo_e == topo.edge_hi_e
    shared_f = _shares_vertices(faces_f3)
    if not (bool(degenerate_e.any()) or bool(shared_f.any()) or bool(inherit_e.any())):
        return None
    dev = faces_f3.device
    tags = torch.zeros(F, 4, 3, dtype=torch.long, device=dev)
    edge_fk = topo.edge_c.reshape(F, 3)  # e01, e12, e20
    mark_e = degenerate_e.long() - inherit_e.long()  # a degenerate edge has one face
    tags[:, :3, 0] = -inherit_e[edge_fk].long()  # corner k's out-edge
    tags[:, :3, 2] = mark_e[edge_fk[:, [2, 0, 1]]]  # corner k's in-edge
    inner = torch.where(shared_f, 2 + torch.arange(F, device=dev), 0)
    tags[:, :3, 1] = inner[:, None]
    tags[:, 3, :] = inner[:, None]
    return tags.flatten()
