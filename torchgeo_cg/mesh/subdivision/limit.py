"""Limit positions and frames at the vertices: OpenSubdiv's limit masks as sparse operators.

Convention:
    Masks are OpenSubdiv's (``Sdc::Scheme::assign*LimitTangentMasks``), applied to the
    refined mesh of an operator exactly as :func:`~torchgeo_cg.mesh.limit_positions`
    applies the position masks. Edges and faces around a vertex are
    ordered counter-clockwise (seen from outside, faces wound counter-clockwise) from
    the start OpenSubdiv's refiner gives them when the operator's input mesh is its
    base mesh: an open fan starts at its leading boundary edge; a closed fan of a
    vertex point or a face point at the out-edge of its corner in its lowest-numbered
    child face; a closed fan of an edge point at its out-edge towards the far end of
    the edge in the edge's lowest-numbered parent face. Around the children of the
    input mesh's non-manifold vertices and edges (a non-manifold edge, a degenerate
    side, a face using a pair twice, faces in more than one fan) OpenSubdiv keeps the
    order it built the lists in, and the masks take edges and faces by position in
    them: the child of such a vertex lists the edge points of its edges by edge number
    (edges numbered by their first side, faces in order) and its child faces corner by
    corner; the child of such an edge lists, for its first side ``a -> b``, ``b``, the
    side's face point (Loop: the edge points of the sides after and before it), ``a``,
    then each later side's face point (Loop: its two edge points). A corner takes
    edges 0 and 1, a crease its first and last sharp edge and the edges and faces
    ranked between them. Loop's smooth masks hold down to two faces (Catmark takes the
    corner masks there). So ``(tangent_u, tangent_v)`` equal OpenSubdiv's ``(du, dv)``
    from ``Far::PrimvarRefiner::Limit`` after one level of refinement of the
    operator's input mesh, except where OpenSubdiv's mask buffers are too short (at
    an edge point of an edge with ``m >= 3`` faces, ``2 m`` above the level's maximum
    valence, its first tangent's last face weights overlap the second tangent's mask;
    not copied here). ``tangent_u`` follows edge 0 (along the crease for crease
    vertices), ``tangent_v`` is rotated counter-clockwise from it, and
    ``normals = normalize(tangent_u x tangent_v)`` points outward. Tangent magnitudes
    are OpenSubdiv's (not unit, not parametric derivatives).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.mesh.subdivision._creasing import component_labels, limit_rules
from torchgeo_cg.mesh.subdivision._limit_masks import catmark_limit_stencils, loop_limit_stencils
from torchgeo_cg.mesh.subdivision._nonmanifold_order import nonmanifold_neighbourhoods
from torchgeo_cg.mesh.subdivision._normals import power_of_two_scaled, unit_normals
from torchgeo_cg.mesh.subdivision._stencil_build import StencilMatrix, stencil_matrix
from torchgeo_cg.mesh.subdivision._topology import check_verts, mesh_topology
from torchgeo_cg.mesh.subdivision.operator import SubdivisionOperator, apply_operator
from torchgeo_cg.mesh.subdivision.stencils import apply_stencils

__all__ = ["limit_positions", "LimitFrames", "limit_frames"]


def limit_positions(operator: SubdivisionOperator, verts: torch.Tensor) -> torch.Tensor:
    """Exact limit-surface positions of the refined vertices: ``L @ S @ verts``.

    ``S`` is ``operator.stencils``; ``L`` applies the limit masks of the operator's
    scheme on the refined mesh ``operator.faces``. Catmark (Halstead et al. 1993):
    smooth vertex of valence ``n``: ``(n^2 V + 4 sum e_i + sum d_i) / (n (n + 5))``
    (``e_i`` edge neighbours, ``d_i`` the opposite corner of each incident quad).
    Loop: smooth vertex ``(1 - n chi) V + chi sum e_i``, ``chi = 1 / (n + 3 / (8 beta))``
    with Loop's ``beta`` (OpenSubdiv's ``assignSmoothLimitMask``). Both schemes:
    boundary/crease vertex ``(a + 4 V + b) / 6`` (the cubic B-spline limit of the
    crease rule), corners and unreferenced vertices ``V``.

    Convention:
        Same classification and ``boundary`` mode as the operator. Because the
        vertex points come first, ``out[..., :V0, :]`` are the limit positions of
        the original control vertices. Differentiable in ``verts``.

    Args:
        operator: from :func:`catmull_clark_operator` or
            :func:`~torchgeo_cg.mesh.subdivision.loop.loop_operator`.
        verts: ``(*, V0, D)`` float control data at the operator's input level.

    Returns:
        ``(*, V1, D)`` limit positions of the vertices of ``operator.faces``.

    Raises:
        ValueError: the operator's scheme has no limit masks here (only
            ``"catmark"`` and ``"loop"`` do).

    Example:
        >>> from torchgeo_cg.mesh.subdivision import SchemeOptions, catmull_clark_operator
        >>> square = torch.tensor([[0., 0.], [1., 0.], [1., 1.], [0., 1.]])
        >>> op = catmull_clark_operator([[0, 1, 2, 3]], 4, options=SchemeOptions("edge_and_corner"))
        >>> limit_positions(op, square)[4:6]  # centre, then the middle of the bottom edge
        tensor([[0.5000, 0.5000],
                [0.5000, 0.0000]])
    """
    check_verts(verts, operator.num_vertices_in)
    wdtype = operator.stencils.weights.dtype
    faces = operator.faces if operator.child_faces is None else operator.child_faces
    edge_tags = None if operator.child_faces is None else operator.child_edge_tags
    args = (faces, operator.num_vertices_out, operator.boundary, wdtype, operator.child_tags,
            edge_tags)
    if operator.scheme == "catmark":
        limit = catmark_limit_stencils(*args)
    elif operator.scheme == "loop":
        limit = loop_limit_stencils(*args)
    else:
        raise ValueError(
            f"operator: limit_positions has limit masks for the 'catmark' and 'loop' "
            f"schemes, got an operator of scheme {operator.scheme!r}"
        )
    return apply_stencils(limit, apply_stencils(operator.stencils, verts))


class LimitFrames(NamedTuple):
    """Limit positions and frames of the refined vertices.

    Attributes:
        positions: ``(*, V1, D)`` limit positions.
        tangent_u: ``(*, V1, D)`` first limit tangent.
        tangent_v: ``(*, V1, D)`` second limit tangent.
        normals: ``(*, V1, 3)`` unit normals (``None`` unless ``D == 3``).
    """

    positions: torch.Tensor
    tangent_u: torch.Tensor
    tangent_v: torch.Tensor
    normals: torch.Tensor | None


def _fan_order(topo, V, first_c=None):
    """Rank of each corner in its vertex's counter-clockwise fan, the fan's size, and
    the corner's out-/in-neighbour (list ranking by pointer jumping: loop over rounds).
    A closed fan starts at its corner flagged in ``first_c`` (``(C,)`` bool), else at
    its smallest corner."""
    C = topo.vert_c.numel()
    dev = topo.vert_c.device
    arange_c = torch.arange(C, device=dev)
    next_corner = arange_c - topo.pos_c + (topo.pos_c + 1) % topo.size_c
    E = topo.edge_lo_e.numel()
    count_e = torch.bincount(topo.edge_c, minlength=E)
    order = torch.argsort(topo.edge_c, stable=True)
    starts = torch.cumsum(count_e, 0) - count_e
    pair_e = count_e == 2
    h1, h2 = order[starts[pair_e]], order[starts[pair_e] + 1]
    consistent = topo.vert_c[h1] != topo.vert_c[h2]
    h1, h2 = h1[consistent], h2[consistent]
    twin = torch.full((C,), -1, dtype=torch.long, device=dev)
    twin[h1], twin[h2] = h2, h1
    pred = torch.where(twin >= 0, next_corner[twin.clamp(min=0)], -1)  # previous CCW corner
    nxt = twin[topo.prev_corner_c]  # next corner counter-clockwise, -1 past a boundary
    src, dst = arange_c[nxt >= 0], nxt[nxt >= 0]
    label = component_labels(C, src, dst)  # fan label: the smallest corner of the fan
    open_label = torch.zeros(C, dtype=torch.bool, device=dev)
    open_label[label[twin < 0]] = True
    lead_c = label == arange_c
    if first_c is not None:
        has_first = torch.zeros(C, dtype=torch.bool, device=dev)
        has_first[label[first_c]] = True
        lead_c = first_c | (~has_first[label] & lead_c)
    start = (twin < 0) | (~open_label[label] & lead_c)
    pred = torch.where(start, -1, pred)
    rank = (pred >= 0).long()
    p = pred
    while bool((p >= 0).any()):  # Wyllie list ranking, log2(valence) rounds
        rank = rank + torch.where(p >= 0, rank[p.clamp(min=0)], 0)
        p = torch.where(p >= 0, p[p.clamp(min=0)], -1)
    faces_v = torch.bincount(topo.vert_c, minlength=V)
    is_open = open_label[label]
    return rank, faces_v, is_open, topo.vert_c[next_corner], topo.vert_c[topo.prev_corner_c]


def limit_frames(operator: SubdivisionOperator, verts: torch.Tensor) -> LimitFrames:
    """Limit positions, tangents and normals of the refined vertices of ``operator``.

    Convention:
        See the module docstring. Catmark and Loop operators (others raise); the same
        tags and boundary handling as :func:`~torchgeo_cg.mesh.subdivision.limit_positions`.
        Differentiable in ``verts``.

    Args:
        operator: from ``catmull_clark_operator`` or ``loop_operator``.
        verts: ``(*, V0, D)`` float control data.

    Returns:
        :class:`LimitFrames` ``(positions, tangent_u, tangent_v (*, V1, D), normals
        (*, V1, 3) or None)``.

    Raises:
        ValueError: the scheme has no limit masks, or semi-sharp tags remain.

    Example:
        >>> from torchgeo_cg.mesh.subdivision import catmull_clark_operator
        >>> grid = [[r * 4 + c, r * 4 + c + 1, r * 4 + c + 5, r * 4 + c + 4]
        ...         for r in range(3) for c in range(3)]
        >>> xy = torch.tensor([[c, r, 0.0] for r in range(4) for c in range(4)])
        >>> frames = limit_frames(catmull_clark_operator(grid, 16), xy)
        >>> frames.normals[5], frames.tangent_u[5].round(decimals=4) + 0.0  # regular vertex
        (tensor([0., 0., 1.]), tensor([-6.,  0.,  0.]))
    """
    positions = limit_positions(operator, verts)  # checks verts and the scheme
    faces = operator.faces if operator.child_faces is None else operator.child_faces
    V1 = operator.num_vertices_out
    wdtype = operator.stencils.weights.dtype
    with torch.no_grad():
        tan_u, tan_v = _tangent_stencils(faces, V1, operator, wdtype)
    refined, scale = power_of_two_scaled(apply_operator(operator, verts))
    tu, tv = apply_stencils(tan_u, refined) * scale, apply_stencils(tan_v, refined) * scale
    normals = unit_normals(tu, tv) if verts.shape[-1] == 3 else None
    return LimitFrames(positions, tu, tv, normals)


def _tangent_stencils(faces, V, operator, dtype) -> tuple[StencilMatrix, StencilMatrix]:
    edge_tags = None if operator.child_faces is None else operator.child_edge_tags
    topo = mesh_topology(faces, V, operator.boundary, edge_tags)
    rule_v, sharp_e = limit_rules(topo, V, faces.shape[0], operator.child_tags,
                                  operator.boundary, dtype)
    rank, faces_v, is_open, out_nbr, in_nbr = _fan_order(topo, V, _first_corners(operator))
    v_c = topo.vert_c
    n_c = faces_v[v_c].to(dtype)
    i_c = rank.to(dtype)
    catmark = operator.scheme == "catmark"
    diag_c = v_c[topo.prev_corner_c[topo.prev_corner_c]] if catmark else v_c
    last_c = rank == faces_v[v_c] - 1
    rows, cols, wu, wv = [], [], [], []

    def add(r, c, a, b):
        rows.append(r), cols.append(c), wu.append(a.to(dtype)), wv.append(b.to(dtype))

    # smooth (interior) vertices; Catmark takes the corner masks at two faces, Loop not
    smooth_c = (rule_v[v_c] == 0) & ~is_open & (faces_v[v_c] > (2 if catmark else 1))
    theta = 2 * math.pi / n_c.clamp(min=1)
    if catmark:
        lam = 5 / 16 + (torch.cos(theta) + torch.cos(theta / 2)
                        * torch.sqrt(2 * (9 + torch.cos(theta)))) / 16
        s = 1.0 / (4 * lam - 1)
        cu, cv = torch.cos(i_c * theta), torch.cos((i_c - 1) * theta)
        cu1, cv1 = torch.cos((i_c + 1) * theta), torch.cos(i_c * theta)
        m = smooth_c
        add(v_c[m], out_nbr[m], 4 * cu[m], 4 * cv[m])
        add(v_c[m], diag_c[m], (s * (cu + cu1))[m], (s * (cv + cv1))[m])
    else:
        m = smooth_c
        add(v_c[m], out_nbr[m], torch.cos(i_c * theta)[m], torch.sin(i_c * theta)[m])
    _corner_entries(add, topo, rule_v, faces_v, rank, is_open, out_nbr, in_nbr, catmark,
                    smooth_c, dtype)
    _crease_entries(add, topo, rule_v, sharp_e, faces_v, rank, is_open, out_nbr, in_nbr,
                    diag_c, last_c, catmark, dtype)
    r, c, a, b = torch.cat(rows), torch.cat(cols), torch.cat(wu), torch.cat(wv)
    if operator.child_faces is not None:
        nb = nonmanifold_neighbourhoods(operator, topo.edge_c, sharp_e)
        ranked_v = nb.vertex_mask & (rule_v != 0)  # non-manifold children are never smooth
        if bool(ranked_v.any()):
            keep = ~ranked_v[r]
            rows, cols, wu, wv = [r[keep]], [c[keep]], [a[keep]], [b[keep]]
            _ranked_entries(add, nb, ranked_v, rule_v, catmark, dtype)
            r, c, a, b = torch.cat(rows), torch.cat(cols), torch.cat(wu), torch.cat(wv)
    return stencil_matrix(r, c, a, (V, V)), stencil_matrix(r, c, b, (V, V))


def _ranked_entries(add, nb, ranked_v, rule_v, catmark, dtype):
    """Corner and crease masks of the vertices in ``ranked_v`` from OpenSubdiv's ranked
    edge and face lists (:func:`nonmanifold_neighbourhoods`): a corner takes its edges
    0 and 1; a crease its first and last sharp edges and what lies between them by rank."""
    dev = rule_v.device
    V = rule_v.numel()
    m = ranked_v[nb.vert_e]
    v_e, rank, other, sharp = nb.vert_e[m], nb.rank_e[m], nb.other_e[m], nb.sharp_e[m]
    scale = 1.0 if catmark else 3.0
    corner = rule_v[v_e] == 2
    for i in (0, 1):
        sel = corner & (rank == i)
        one = torch.full((int(sel.sum()),), scale, dtype=dtype, device=dev)
        add(v_e[sel], other[sel], one if i == 0 else 0 * one, 0 * one if i == 0 else one)
    verts = torch.nonzero(ranked_v & (rule_v == 2)).flatten()
    minus = torch.full((verts.numel(),), -scale, dtype=dtype, device=dev)
    add(verts, verts, minus, minus)
    crease = (rule_v[v_e] == 1) & sharp
    big = torch.iinfo(torch.long).max
    c0_v = torch.full((V,), big, dtype=torch.long, device=dev).scatter_reduce(
        0, v_e[crease], rank[crease], "amin")
    c1_v = torch.full((V,), -1, dtype=torch.long, device=dev).scatter_reduce(
        0, v_e[crease], rank[crease], "amax")
    k_v = (c1_v - c0_v - 1).clamp(min=0)
    j = (rank - c0_v[v_e].clamp(max=V)).clamp(min=0)
    inside = (rule_v[v_e] == 1) & (rank >= c0_v[v_e]) & (rank <= c1_v[v_e])
    k = k_v[v_e].to(dtype)
    end1, end2, inner = _crease_edge_weights(j, k, catmark, dtype)
    last = rank == c1_v[v_e]
    a = torch.where(j == 0, end1, torch.where(last, -end1, 0.0))
    b = torch.where((j == 0) | last, end2, inner)
    add(v_e[inside], other[inside], a[inside], b[inside])
    if catmark:
        mf = ranked_v[nb.vert_f] & (rule_v[nb.vert_f] == 1)
        v_f, rank_f, diag = nb.vert_f[mf], nb.rank_f[mf], nb.diag_f[mf]
        jf = rank_f - c0_v[v_f]
        inside_f = (jf >= 0) & (jf <= k_v[v_f]) & (k_v[v_f] >= 1)
        fw = _crease_face_weights(jf.clamp(min=0), k_v[v_f].to(dtype), dtype)
        add(v_f[inside_f], diag[inside_f], 0 * fw[inside_f], fw[inside_f])
    verts = torch.nonzero(ranked_v & (rule_v == 1)).flatten()
    kk = k_v[verts].to(dtype)
    add(verts, verts, torch.zeros_like(kk), _crease_vertex_weight(kk, catmark))


def _first_corners(operator) -> torch.Tensor:
    """``(C,)`` bool: the corner where OpenSubdiv's refiner starts the fan of each edge
    point (``Vtr::QuadRefinement``/``TriRefinement`` order an edge point's faces from the
    child at the far end of the edge in its first face, the parent edge's lowest-numbered
    face): Catmark, the corner at position 3 of the lowest such child quad; Loop, at
    position 2 of a corner triangle. Vertex and face points keep the default start (their
    lowest-numbered face, which is the child of the parent's lowest one)."""
    faces = operator.child_faces
    F1, K = faces.shape
    pos = 3 if operator.scheme == "catmark" else 2
    edge_point = operator.num_vertices_out - operator.num_edges_in
    vert = faces[:, pos]
    ok = vert >= edge_point
    if operator.scheme == "loop":
        ok &= torch.arange(F1, device=faces.device) % 4 != 3
    big = torch.iinfo(torch.long).max
    face_ids = torch.arange(F1, device=faces.device)
    lowest = torch.full((operator.num_vertices_out,), big, dtype=torch.long,
                        device=faces.device).scatter_reduce(0, vert[ok], face_ids[ok], "amin")
    first = torch.zeros(F1, K, dtype=torch.bool, device=faces.device)
    first[:, pos] = ok & (lowest[vert] == face_ids)
    return first.flatten()


def _corner_entries(add, topo, rule_v, faces_v, rank, is_open, out_nbr, in_nbr, catmark,
                    smooth_c, dtype):
    """Corner masks (and smooth vertices with two faces): ``e0 - V`` and ``e1 - V``
    (Loop: times 3)."""
    v_c = topo.vert_c
    corner_v = rule_v == 2
    corner_v[v_c[(rule_v[v_c] == 0) & ~smooth_c]] = True  # valence-2 smooth / open smooth
    scale = 1.0 if catmark else 3.0
    V = rule_v.numel()
    first = corner_v[v_c] & (rank == 0)
    one = torch.ones(int(first.sum()), dtype=dtype, device=v_c.device)
    add(v_c[first], out_nbr[first], scale * one, 0 * one)  # edge 0
    # edge 1: out-edge of rank 1, or the in-edge of rank 0 when the fan has one face
    second = corner_v[v_c] & (rank == 1)
    one2 = torch.ones(int(second.sum()), dtype=dtype, device=v_c.device)
    add(v_c[second], out_nbr[second], 0 * one2, scale * one2)
    single = first & (faces_v[v_c] == 1)
    one3 = torch.ones(int(single.sum()), dtype=dtype, device=v_c.device)
    add(v_c[single], in_nbr[single], 0 * one3, scale * one3)
    has = torch.zeros(V, dtype=torch.bool, device=v_c.device)
    has[v_c[first]] = True
    verts = torch.nonzero(has).flatten()
    minus = torch.full((verts.numel(),), -scale, dtype=dtype, device=v_c.device)
    add(verts, verts, minus, minus)


def _crease_entries(add, topo, rule_v, sharp_e, faces_v, rank, is_open, out_nbr, in_nbr,
                    diag_c, last_c, catmark, dtype):
    """Crease tangents: along the crease (leading minus trailing end) and across it
    (OpenSubdiv's regular, irregular (Biermann et al.) and single-face masks)."""
    v_c = topo.vert_c
    dev = v_c.device
    V = rule_v.numel()
    crease_c = rule_v[v_c] == 1
    sharp_out_c = sharp_e[topo.edge_c]
    big = torch.iinfo(torch.long).max
    e0_v = torch.full((V,), big, dtype=torch.long, device=dev).scatter_reduce(
        0, v_c[crease_c & sharp_out_c], rank[crease_c & sharp_out_c], "amin")
    e1_v = torch.full((V,), -1, dtype=torch.long, device=dev).scatter_reduce(
        0, v_c[crease_c & sharp_out_c], rank[crease_c & sharp_out_c], "amax")
    open_v = torch.zeros(V, dtype=torch.bool, device=dev)
    open_v[v_c[is_open]] = True
    e0_v = torch.where(open_v, 0, e0_v)
    e1_v = torch.where(open_v, faces_v, e1_v)
    k_v = (e1_v - e0_v - 1).clamp(min=0)  # interior edges between the crease ends
    c = crease_c
    j = rank - e0_v[v_c]  # edge/face index relative to the leading crease edge
    k = k_v[v_c].to(dtype)
    ranks_in = (j >= 0) & (j <= k_v[v_c] + 1) & c
    w_end1, w_end2, w_int2 = _crease_edge_weights(j, k, catmark, dtype)
    # out-edges (edge index = rank); the trailing end of an open fan is the last in-edge
    is_e1 = rank == e1_v[v_c]
    wu = torch.where(j == 0, w_end1, torch.where(is_e1, -w_end1, 0.0))
    wv = torch.where((j == 0) | is_e1, w_end2, w_int2)
    add(v_c[ranks_in], out_nbr[ranks_in], wu[ranks_in], wv[ranks_in])
    trail = c & is_open & last_c
    add(v_c[trail], in_nbr[trail], -w_end1[trail], w_end2[trail])
    if catmark:
        fw = _crease_face_weights(j, k, dtype)
        faces_in = (j >= 0) & (j <= k_v[v_c]) & c & (k_v[v_c] >= 1)
        add(v_c[faces_in], diag_c[faces_in], 0 * fw[faces_in], fw[faces_in])
    verts = torch.nonzero(rule_v == 1).flatten()
    kk = k_v[verts].to(dtype)
    add(verts, verts, torch.zeros_like(kk), _crease_vertex_weight(kk, catmark))


def _crease_edge_weights(j, k, catmark, dtype):
    """(along-crease end weight, across end weight, across interior weight)."""
    jf = j.to(dtype)
    if catmark:
        kk = k + 1
        theta = math.pi / kk
        denom = 1.0 / (kk * (3 + torch.cos(theta)))
        r = (torch.cos(theta) + 1) / torch.sin(theta)
        end2 = torch.where(k == 1, -1 / 6, torch.where(k == 0, 3.0,
                           -r * (1 + 2 * torch.cos(theta)) * denom))
        inner = torch.where(k == 1, 4 / 6, 4 * torch.sin(jf * theta) * denom)
        return torch.full_like(jf, 0.5), end2, inner
    root3 = math.sqrt(3.0)
    theta = math.pi / (k + 1)
    end2 = torch.where(k == 2, -root3 / 2, torch.where(k > 2, -3 * torch.sin(theta),
                       torch.where(k == 1, 0.0, torch.full_like(k, 3.0))))
    inner = torch.where(k == 2, root3, torch.where(
        k > 2, -3 * (2 * torch.cos(theta) - 2) * torch.sin(jf * theta), 3.0))
    return torch.full_like(jf, 1.5), end2, inner


def _crease_face_weights(j, k, dtype):
    jf = j.to(dtype)
    kk = k + 1
    theta = math.pi / kk
    denom = 1.0 / (kk * (3 + torch.cos(theta)))
    irregular = (torch.sin(jf * theta) + torch.sin((jf + 1) * theta)) * denom
    return torch.where(k == 1, 1 / 6, irregular)


def _crease_vertex_weight(k, catmark):
    if catmark:
        kk = k + 1
        theta = math.pi / kk
        denom = 1.0 / (kk * (3 + torch.cos(theta)))
        r = (torch.cos(theta) + 1) / torch.sin(theta)
        irregular = 4 * r * (torch.cos(theta) - 1) * denom
        return torch.where(k == 1, -4 / 6, torch.where(k == 0, -6.0, irregular))
    low = torch.where(k == 1, -3.0, torch.full_like(k, -6.0))  # a tensor keeps k's dtype
    return torch.where(k == 2, -math.sqrt(3.0), torch.where(k > 2, 0.0, low))
