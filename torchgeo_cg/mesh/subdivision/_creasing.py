"""OpenSubdiv's creasing rules, vectorized: sharpness, vertex rules, transitions, child tags.

This module turns a mesh's topology and its :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags`
into the per-vertex and per-edge coefficients that the Catmark and Loop builders
(:mod:`torchgeo_cg.mesh.subdivision`, :mod:`torchgeo_cg.mesh.subdivision.loop`) weight their masks
with, and into the tags of the refined mesh. Everything is sort/scatter on flat tensors.

Convention (OpenSubdiv 3, ``Sdc::Crease``, ``Far::TopologyRefinerFactory``):
    - Effective edge sharpness: the crease tag, raised to infinity (``10``) on boundary
      edges (one face) and non-manifold edges (three or more faces, or two faces that
      traverse the edge in the same direction: inconsistent winding).
    - Effective vertex sharpness: the corner tag, raised to infinity on non-manifold
      vertices (faces forming more than one fan, or touching a non-manifold edge) unless
      the vertex lies on an interior non-manifold crease (exactly two non-manifold
      edges, no boundary edge, more faces than edges), and on topological corners (one
      face, two edges) with ``boundary="edge_and_corner"``.
    - Refined levels inherit the non-manifold sharpness (``Vtr::Refinement`` propagates
      the tags): the children of a non-manifold edge stay non-manifold even where their
      faces look manifold (a 2-gon's edge), the child of a vertex sharpened as
      non-manifold stays an infinitely sharp corner, and an edge's or a face's child
      vertex is not sharpened. The operators carry this in ``child_edge_tags`` (``-1``)
      and ``child_tags`` (corners); a level whose edge tags hold ``-1`` is a refined one
      and derives no vertex sharpness from non-manifoldness.
    - Rule of a vertex: corner if its sharpness is positive, else by its number of
      sharp edges: 0 or 1 smooth (a dart is smooth), 2 crease, more corner.
    - Child sharpness: ``"uniform"`` decrements by 1 (values in ``(0, 1]`` become 0,
      infinity stays); ``"chaikin"`` gives the child of edge ``e`` at vertex ``v``
      ``3/4 s_e + 1/4 mean(s of v's other semi-sharp edges) - 1`` when ``v`` has two
      or more semi-sharp edges (vertices decrement uniformly).
    - Edge points blend crease and smooth masks with weight ``min(s, 1)`` (``1`` when
      both child edges stay sharp under Chaikin). When a vertex's rule changes from
      parent to child, its mask is ``w * parent + (1 - w) * child`` with ``w`` the mean
      of the sharpness values that decay to 0 (``ComputeFractionalWeightAtVertex``).
    - Holes: tagged faces, plus (``boundary="none"``) every face touching a vertex that
      has a boundary edge not tagged infinitely sharp; hole faces have no children but
      take part in every rule.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.mesh.subdivision.tags import INFINITELY_SHARP, SubdivisionTags, check_tags

__all__: list[str] = []

SMOOTH, CREASE, CORNER = 0, 1, 2


class SubdivisionRules(NamedTuple):
    """Mask coefficients of one refinement step (all float in the weights' dtype).

    Attributes:
        smooth_v: ``(V,)`` weight of the smooth vertex mask.
        crease_v: ``(V,)`` weight of the crease vertex mask ``3/4 V + 1/8 (a + b)``.
        corner_v: ``(V,)`` weight of the corner mask (the vertex itself).
        crease_end_lo_e: ``(E,)`` weight of ``hi`` in row ``lo``'s crease part (``1/8`` each).
        crease_end_hi_e: ``(E,)`` weight of ``lo`` in row ``hi``'s crease part.
        crease_e: ``(E,)`` weight of the crease edge mask ``(a + b) / 2``; the smooth edge
            mask gets ``1 - crease_e``.
        child_sharp_lo_e: ``(E,)`` sharpness of the child edge at ``lo``.
        child_sharp_hi_e: ``(E,)`` sharpness of the child edge at ``hi``.
        tagged_e: ``(E,)`` bool, the edge carries a crease tag (its children do too).
        child_corner_v: ``(V,)`` decremented corner-tag sharpness.
        hole_f: ``(F,)`` bool, faces without children.
        rule_v: ``(V,)`` long parent rule (0 smooth, 1 crease, 2 corner).
        inherit_e: ``(E,)`` bool, non-manifold edges whose children stay non-manifold
            (the builders mark their children's sides in ``child_edge_tags``).
        inherit_v: ``(V,)`` bool, vertices made infinitely sharp by non-manifoldness
            (their children are infinitely sharp corners of ``child_tags``).
    """

    smooth_v: torch.Tensor
    crease_v: torch.Tensor
    corner_v: torch.Tensor
    crease_end_lo_e: torch.Tensor
    crease_end_hi_e: torch.Tensor
    crease_e: torch.Tensor
    child_sharp_lo_e: torch.Tensor
    child_sharp_hi_e: torch.Tensor
    tagged_e: torch.Tensor
    child_corner_v: torch.Tensor
    hole_f: torch.Tensor
    rule_v: torch.Tensor
    inherit_e: torch.Tensor
    inherit_v: torch.Tensor


def decrement_sharpness(sharpness: torch.Tensor) -> torch.Tensor:
    """OpenSubdiv's uniform decrement: ``s - 1`` above 1, ``0`` at or below 1, infinity kept.

    Example:
        >>> decrement_sharpness(torch.tensor([0.0, 0.5, 1.0, 2.3, 10.0]))
        tensor([ 0.0000,  0.0000,  0.0000,  1.3000, 10.0000])
    """
    return torch.where(
        sharpness >= INFINITELY_SHARP, sharpness,
        torch.where(sharpness > 1.0, sharpness - 1.0, torch.zeros_like(sharpness)),
    )


def vertex_rule(vertex_sharpness: torch.Tensor, sharp_edge_count: torch.Tensor) -> torch.Tensor:
    """``(V,)`` rule: 2 corner if sharp or more than 2 sharp edges, 1 crease if 2, else 0.

    Example:
        >>> vertex_rule(torch.tensor([0.0, 0.0, 0.0, 1.5]), torch.tensor([1, 2, 3, 0]))
        tensor([0, 1, 2, 2])
    """
    rule = torch.where(sharp_edge_count == 2, CREASE, SMOOTH)
    rule = torch.where(sharp_edge_count > 2, CORNER, rule)
    return torch.where(vertex_sharpness > 0, CORNER, rule)



def component_labels(num_nodes: int, src: torch.Tensor, dst: torch.Tensor) -> torch.Tensor:
    """``(num_nodes,)`` connected-component label of each node of the undirected graph with
    edges ``src[i] -- dst[i]``: the smallest node id of its component.

    Min-label propagation with pointer jumping: a loop over rounds (about the log of the
    component diameter), not over nodes or edges.

    Example:
        >>> component_labels(5, torch.tensor([0, 3]), torch.tensor([2, 4]))
        tensor([0, 1, 0, 3, 3])
    """
    label = torch.arange(num_nodes, device=src.device)
    while True:  # loop over propagation rounds
        m = torch.minimum(label[src], label[dst])
        new = label.scatter_reduce(0, src, m, "amin").scatter_reduce(0, dst, m, "amin")
        new = new[new]
        if torch.equal(new, label):
            return label
        label = new

def _fan_count(topo, num_vertices: int, manifold_e: torch.Tensor) -> torch.Tensor:
    """``(V,)`` number of face fans around each vertex (connected corners through
    manifold, consistently wound edges), by min-label propagation with pointer jumping
    (a loop over iterations, not elements)."""
    C = topo.vert_c.numel()
    dev = topo.vert_c.device
    next_corner_c = torch.arange(C, device=dev) - topo.pos_c + (topo.pos_c + 1) % topo.size_c
    order = torch.argsort(topo.edge_c, stable=True)
    counts = torch.bincount(topo.edge_c, minlength=manifold_e.numel())
    starts = torch.cumsum(counts, 0) - counts
    keep = manifold_e
    h1 = order[starts[keep]]
    h2 = order[starts[keep] + 1]
    src = torch.cat([h1, next_corner_c[h1]])
    dst = torch.cat([next_corner_c[h2], h2])
    label = component_labels(C, src, dst)
    roots = label == torch.arange(C, device=dev)
    return torch.bincount(topo.vert_c[roots], minlength=num_vertices)


class _Sharpness(NamedTuple):
    tag_e: torch.Tensor  # (E,) tagged sharpness
    tag_v: torch.Tensor  # (V,)
    sharp_e: torch.Tensor  # (E,) effective sharpness
    sharp_v: torch.Tensor  # (V,)
    hole_f: torch.Tensor  # (F,) bool
    inherit_e: torch.Tensor  # (E,) bool: non-manifold edges with two or more faces
    inherit_v: torch.Tensor  # (V,) bool: vertices made infinitely sharp by non-manifoldness


def _effective_sharpness(topo, tags, num_vertices, num_faces, boundary, dtype) -> _Sharpness:
    """Tagged and effective sharpness of edges and vertices, the hole mask, and what the
    children inherit (OpenSubdiv derives non-manifold sharpness at the base level only:
    the children of a non-manifold edge stay non-manifold and the child of a sharpened
    vertex stays sharp, while an edge's or a face's child vertex starts smooth)."""
    V, E = num_vertices, topo.edge_lo_e.numel()
    dev = topo.edge_lo_e.device
    count_e = torch.bincount(topo.edge_c, minlength=E)
    forward_e = torch.bincount(topo.edge_c, weights=(topo.vert_c == topo.edge_lo_e[topo.edge_c])
                               .to(torch.float64), minlength=E)
    inconsistent_e = (count_e == 2) & (forward_e != 1)
    boundary_e = count_e == 1
    nonmanifold_e = (count_e > 2) | inconsistent_e
    if topo.repeat_e is not None:  # a face using one pair twice (a 2-gon, [a, a, b])
        nonmanifold_e = nonmanifold_e | topo.repeat_e
    if topo.inherited_e is not None:  # a child of a non-manifold edge
        nonmanifold_e = nonmanifold_e | topo.inherited_e
    tag_e = torch.zeros(E, dtype=dtype, device=dev)
    tag_v = torch.zeros(V, dtype=dtype, device=dev)
    hole_f = torch.zeros(num_faces, dtype=torch.bool, device=dev)
    if tags is not None:
        tag_e, tag_v, hole_f = _scatter_tags(topo, tags, V, num_faces, dtype)
    ends = torch.cat([topo.edge_lo_e, topo.edge_hi_e])
    per_end = lambda mask: torch.bincount(ends[torch.cat([mask, mask])], minlength=V)  # noqa: E731
    if boundary == "none":
        open_v = per_end(boundary_e & (tag_e < INFINITELY_SHARP)) > 0
        hole_f = hole_f | _faces_touching(topo, open_v, num_faces)
    inf = torch.full_like(tag_e, INFINITELY_SHARP)
    sharp_e = torch.where(boundary_e | nonmanifold_e, torch.maximum(tag_e, inf), tag_e)
    valence_v, faces_v = topo.valence_v, topo.num_faces_v
    carry_v = torch.zeros(V, dtype=torch.bool, device=dev)
    if topo.inherited_e is None:  # a refined level's vertices inherit (the tags carry them)
        nm_edges_v, boundary_edges_v = per_end(nonmanifold_e), per_end(boundary_e)
        fans_v = _fan_count(topo, V, (count_e == 2) & ~inconsistent_e)
        nonmanifold_v = (fans_v > 1) | (nm_edges_v > 0)
        interior_crease_v = (nm_edges_v == 2) & (boundary_edges_v == 0) & (faces_v > valence_v)
        carry_v = nonmanifold_v & ~interior_crease_v
    sharpen_v = carry_v
    if boundary == "edge_and_corner":
        sharpen_v = sharpen_v | ((faces_v == 1) & (valence_v == 2))
    sharp_v = torch.where(sharpen_v, torch.full_like(tag_v, INFINITELY_SHARP), tag_v)
    sharp_v = torch.where(valence_v == 0, torch.full_like(tag_v, INFINITELY_SHARP), sharp_v)
    return _Sharpness(tag_e, tag_v, sharp_e, sharp_v, hole_f, nonmanifold_e & ~boundary_e,
                      carry_v)


def effective_sharpness(topo, tags, num_vertices, num_faces, boundary, dtype):
    """``(sharp_e (E,), sharp_v (V,), hole_f (F,) bool)``: the effective sharpness of every
    edge and vertex (boundary and non-manifold raised to infinity) and the holes.

    Example:
        >>> from torchgeo_cg.mesh.subdivision._topology import mesh_topology
        >>> quad = torch.tensor([[0, 1, 2, 3]])
        >>> effective_sharpness(mesh_topology(quad, 4), None, 4, 1, "edge_only", torch.float64)[0]
        tensor([10., 10., 10., 10.], dtype=torch.float64)
    """
    found = _effective_sharpness(topo, tags, num_vertices, num_faces, boundary, dtype)
    return found.sharp_e, found.sharp_v, found.hole_f


def _faces_touching(topo, mask_v: torch.Tensor, num_faces: int) -> torch.Tensor:
    hit_c = mask_v[topo.vert_c]
    return torch.bincount(topo.face_c[hit_c], minlength=num_faces) > 0


def _scatter_tags(topo, tags: SubdivisionTags, V: int, F: int, dtype):
    """Tag values on the topology's edges, vertices and faces, with clear errors."""
    E = topo.edge_lo_e.numel()
    dev = topo.edge_lo_e.device
    check_tags(tags)
    creases = tags.creases.to(dev).long().reshape(-1, 2)
    crease_s = tags.crease_sharpness.to(device=dev, dtype=dtype).reshape(-1)
    corners = tags.corners.to(dev).long().reshape(-1)
    corner_s = tags.corner_sharpness.to(device=dev, dtype=dtype).reshape(-1)
    holes = tags.holes.to(dev).long().reshape(-1)
    if crease_s.numel() != creases.shape[0] or corner_s.numel() != corners.numel():
        raise ValueError(
            f"tags: expected one sharpness per crease and per corner, got "
            f"{creases.shape[0]} creases / {crease_s.numel()} values and "
            f"{corners.numel()} corners / {corner_s.numel()} values"
        )
    for name, values in (("crease_sharpness", crease_s), ("corner_sharpness", corner_s)):
        bad = ~(values >= 0)  # negative or NaN
        if bool(bad.any()):
            i = int(torch.nonzero(bad)[0])
            raise ValueError(f"tags.{name}[{i}]: expected a sharpness >= 0, got {float(values[i])}")
    for name, ids, n in (("creases", creases.reshape(-1), V), ("corners", corners, V),
                         ("holes", holes, F)):
        bad = (ids < 0) | (ids >= n)
        if bool(bad.any()):
            i = int(torch.nonzero(bad)[0])
            raise ValueError(f"tags.{name}: index {int(ids[i])} out of range [0, {n})")
    lo, hi = creases.min(1).values, creases.max(1).values
    key_e = topo.edge_lo_e * max(V, 1) + topo.edge_hi_e  # sorted (torch.unique)
    key = lo * max(V, 1) + hi
    pos = torch.searchsorted(key_e, key).clamp(max=max(E - 1, 0))
    found = (key_e[pos] == key) if E else torch.zeros_like(key, dtype=torch.bool)
    if bool((~found).any()):
        i = int(torch.nonzero(~found)[0])
        raise ValueError(
            f"tags.creases[{i}] = ({int(creases[i, 0])}, {int(creases[i, 1])}) is not an "
            f"edge of the mesh"
        )
    tag_e = torch.zeros(E, dtype=dtype, device=dev).scatter_reduce(0, pos, crease_s, "amax")
    tag_v = torch.zeros(V, dtype=dtype, device=dev).scatter_reduce(0, corners, corner_s, "amax")
    hole_f = torch.zeros(F, dtype=torch.bool, device=dev)
    hole_f[holes] = True
    return tag_e, tag_v, hole_f


def _child_edge_sharpness(sharp_e, lo_e, hi_e, V, method):
    """Sharpness of the two children of each edge (at ``lo`` and at ``hi``)."""
    if method == "uniform":
        child = decrement_sharpness(sharp_e)
        return child, child
    semi_e = (sharp_e > 0) & (sharp_e < INFINITELY_SHARP)
    ends = torch.cat([lo_e, hi_e])
    semi2 = torch.cat([semi_e, semi_e])
    s2 = torch.cat([sharp_e, sharp_e])
    count_v = torch.bincount(ends[semi2], minlength=V)
    sum_v = torch.zeros(V, dtype=sharp_e.dtype, device=sharp_e.device).index_add_(
        0, ends[semi2], s2[semi2]
    )

    def at(v_e):
        n = count_v[v_e]
        others = (sum_v[v_e] - sharp_e) / (n - 1).clamp(min=1).to(sharp_e.dtype)
        chaikin = (0.75 * sharp_e + 0.25 * others - 1.0).clamp(min=0.0)
        return torch.where(semi_e & (n > 1), chaikin, decrement_sharpness(sharp_e))

    return at(lo_e), at(hi_e)


def subdivision_rules(
    topo,
    num_vertices: int,
    num_faces: int,
    tags: SubdivisionTags | None,
    boundary: str,
    crease_method: str,
    dtype: torch.dtype,
) -> SubdivisionRules:
    """Resolve sharpness and rules for one refinement step (module docstring).

    Args:
        topo: the corner/edge tables of :mod:`torchgeo_cg.mesh.subdivision`.
        num_vertices: ``V``.
        num_faces: ``F``.
        tags: :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` or ``None``.
        boundary: ``"edge_only"``, ``"edge_and_corner"`` or ``"none"``.
        crease_method: ``"uniform"`` or ``"chaikin"``.
        dtype: float dtype of the coefficients.

    Returns:
        :class:`SubdivisionRules`.

    Example:
        >>> from torchgeo_cg.mesh.subdivision._topology import mesh_topology
        >>> quad = torch.tensor([[0, 1, 2, 3]])
        >>> rules = subdivision_rules(mesh_topology(quad, 4), 4, 1, None, "edge_only",
        ...                           "uniform", torch.float64)
        >>> rules.crease_v.tolist(), rules.crease_e.tolist()  # all boundary: creases
        ([1.0, 1.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0])
    """
    V = num_vertices
    lo_e, hi_e = topo.edge_lo_e, topo.edge_hi_e
    found = _effective_sharpness(topo, tags, V, num_faces, boundary, dtype)
    tag_e, tag_v, sharp_e, sharp_v, hole_f = found[:5]
    ends = torch.cat([lo_e, hi_e])
    count = lambda mask_lo, mask_hi: torch.bincount(  # noqa: E731
        ends[torch.cat([mask_lo, mask_hi])], minlength=V
    )
    parent = vertex_rule(sharp_v, count(sharp_e > 0, sharp_e > 0))
    child_lo, child_hi = _child_edge_sharpness(sharp_e, lo_e, hi_e, V, crease_method)
    child_v = decrement_sharpness(sharp_v)
    child = vertex_rule(child_v, count(child_lo > 0, child_hi > 0))
    # fractional weight: mean of the sharpness values that decay to 0 (capped at 1)
    if crease_method == "uniform":
        decays_lo = decays_hi = (sharp_e > 0) & (sharp_e <= 1.0)
    else:
        decays_lo, decays_hi = (sharp_e > 0) & (child_lo <= 0), (sharp_e > 0) & (child_hi <= 0)
    vertex_decays = (sharp_v > 0) & (child_v <= 0)
    n_v = count(decays_lo, decays_hi) + vertex_decays.long()
    s_v = torch.zeros(V, dtype=dtype, device=lo_e.device).index_add_(
        0, ends, torch.cat([sharp_e * decays_lo, sharp_e * decays_hi])
    ) + torch.where(vertex_decays, sharp_v, 0.0)
    frac_v = (s_v / n_v.clamp(min=1).to(dtype)).clamp(max=1.0)
    p_w = torch.where(child == parent, 1.0, frac_v).to(dtype)
    changed = child != parent
    smooth_v = torch.where(parent == SMOOTH, 1.0, torch.where(child == SMOOTH, 1 - p_w, 0.0))
    crease_p = torch.where(parent == CREASE, p_w, 0.0)
    crease_c = torch.where((child == CREASE) & changed, 1 - p_w, 0.0)
    corner_v = torch.where(parent == CORNER, p_w, 0.0) + torch.where(
        (child == CORNER) & changed, 1 - p_w, 0.0
    )
    crease_end_lo = 0.125 * (crease_p[lo_e] * (sharp_e > 0) + crease_c[lo_e] * (child_lo > 0))
    crease_end_hi = 0.125 * (crease_p[hi_e] * (sharp_e > 0) + crease_c[hi_e] * (child_hi > 0))
    crease_e = torch.where(sharp_e >= 1.0, 1.0, sharp_e.clamp(min=0.0))
    if crease_method == "chaikin":
        crease_e = torch.where((child_lo > 0) & (child_hi > 0), 1.0, crease_e)
    return SubdivisionRules(
        smooth_v.to(dtype), (crease_p + crease_c).to(dtype), corner_v.to(dtype),
        crease_end_lo.to(dtype), crease_end_hi.to(dtype), crease_e.to(dtype),
        child_lo, child_hi, tag_e > 0, decrement_sharpness(tag_v), hole_f, parent,
        found.inherit_e, found.inherit_v,
    )


def child_tags(
    rules: SubdivisionRules,
    lo_e: torch.Tensor,
    hi_e: torch.Tensor,
    edge_point_e: torch.Tensor,
    hole_child: torch.Tensor,
    like: SubdivisionTags | None,
) -> SubdivisionTags | None:
    """Tags of the refined mesh: child creases (at each end of a tagged edge, where the
    child sharpness stays positive), decremented corners, infinitely sharp corners at the
    children of vertices sharpened by non-manifoldness, and the children of holes.
    ``None`` when the parent has no tags, no hole and no such vertex."""
    inherit_v = rules.inherit_v
    if like is None and not bool(hole_child.any()) and not bool(inherit_v.any()):
        return None
    keep_lo = rules.tagged_e & (rules.child_sharp_lo_e > 0)
    keep_hi = rules.tagged_e & (rules.child_sharp_hi_e > 0)
    creases = torch.cat([
        torch.stack([lo_e[keep_lo], edge_point_e[keep_lo]], 1),
        torch.stack([edge_point_e[keep_hi], hi_e[keep_hi]], 1),
    ])
    sharpness = torch.cat([rules.child_sharp_lo_e[keep_lo], rules.child_sharp_hi_e[keep_hi]])
    corner_s = torch.where(inherit_v, INFINITELY_SHARP, rules.child_corner_v)
    corners = torch.nonzero(corner_s > 0).flatten()
    real = sharpness.dtype if like is None else like.crease_sharpness.dtype
    return SubdivisionTags(
        creases, sharpness.to(real), corners, corner_s[corners].to(real),
        torch.nonzero(hole_child).flatten(),
    )


def limit_rules(topo, num_vertices, num_faces, tags, boundary, dtype):
    """``(rule_v (V,) long, sharp_e (E,) bool)`` for limit masks of an already refined mesh.

    Raises:
        ValueError: a semi-sharp crease or corner remains (its limit is not given by a
            mask at this level: refine until the sharpness has decayed).

    Example:
        >>> from torchgeo_cg.mesh.subdivision._topology import mesh_topology
        >>> quad = torch.tensor([[0, 1, 2, 3]])
        >>> limit_rules(mesh_topology(quad, 4), 4, 1, None, "edge_and_corner", torch.float64)[0]
        tensor([2, 2, 2, 2])
    """
    if boundary == "none":
        boundary = "edge_only"
    found = _effective_sharpness(topo, tags, num_vertices, num_faces, boundary, dtype)
    sharp_e, sharp_v = found.sharp_e, found.sharp_v
    semi = ((sharp_e > 0) & (sharp_e < INFINITELY_SHARP)).any() | (
        (sharp_v > 0) & (sharp_v < INFINITELY_SHARP)).any()
    if bool(semi):
        raise ValueError(
            "operator: limit positions need infinitely sharp or smooth tags, but semi-sharp "
            "creases or corners remain after this level; subdivide until they decay "
            "(ceil of the largest finite sharpness levels)"
        )
    ends = torch.cat([topo.edge_lo_e, topo.edge_hi_e])
    sharp2 = torch.cat([sharp_e > 0, sharp_e > 0])
    rule_v = vertex_rule(sharp_v, torch.bincount(ends[sharp2], minlength=num_vertices))
    return rule_v, sharp_e > 0
