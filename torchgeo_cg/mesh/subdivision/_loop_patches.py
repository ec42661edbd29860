"""Regular Loop patches of a triangle mesh level: which triangles are regular, their 12
box-spline control points, the quartic box-spline basis, and boundary (phantom) points.

Convention (OpenSubdiv's ``Far::PatchBuilder`` for Loop with ``useInfSharpPatch``):
    A triangle ``(a, b, c)`` is regular when it is not a hole and each corner is a smooth
    vertex of valence 6, or a crease vertex (two infinitely sharp or boundary edges, the
    vertex untagged) whose side of the crease has 3 faces (valence 4 on a boundary, or a
    straight interior crease), with no semi-sharp edge at its corners. Its limit is the
    quartic three-direction box spline of the 12 points of the triangular lattice around
    it. In lattice coordinates (which are ptex ``(u, v)``: ``a = (0, 0)``, ``b = (1, 0)``,
    ``c = (0, 1)``) the slots are ``a, b, c``, then per corner ``X1, X2, X3`` of its fan
    turning clockwise from its out-edge: ``a``: ``(1, -1), (0, -1), (-1, 0)``; ``b``:
    ``(1, 1), (2, 0), (2, -1)``; ``c``: ``(-1, 1), (-1, 2), (0, 2)``. A slot beyond a
    crease or boundary is a phantom: the point reflection ``B1 + B2 - I`` of a lattice
    triangle ``(B1, B2, I)`` of real slots through the midpoint of its crease edge
    ``B1 B2`` (or ``2 B - I`` through a crease vertex where no such edge is next to it),
    which makes the patch's boundary the crease rule's cubic B-spline; the phantoms are
    folded into the patch's map from slots to vertices.
"""

from __future__ import annotations

import torch

from torchgeo_cg.mesh.subdivision._patches import sharp_edge_counts

SLOTS = ((0, 0), (1, 0), (0, 1), (1, -1), (0, -1), (-1, 0), (1, 1), (2, 0), (2, -1),
         (-1, 1), (-1, 2), (0, 2))
# monomials u^i v^j of degree <= 4, and 12 x the basis coefficients of each slot (derived
# from the limit of Loop subdivision on the regular lattice: exact integers)
_MONOMIALS = tuple((a, d - a) for d in range(5) for a in range(d, -1, -1))
_BOX = (
    (6, 0, 0, -12, -12, -12, 8, 12, 12, 8, -1, -2, 0, -2, -1),
    (1, 4, 2, 6, 6, 0, -4, -6, -12, -4, -1, -2, 0, 4, 2),
    (1, 2, 4, 0, 6, 6, -4, -12, -6, -4, 2, 4, 0, -2, -1),
    (1, 2, -2, 0, -6, 0, -4, 0, 6, 2, 2, 4, 0, -2, -1),
    (1, -2, -4, 0, 6, 6, 2, 0, -6, -4, -1, -2, 0, 2, 1),
    (1, -4, -2, 6, 6, 0, -4, -6, 0, 2, 1, 2, 0, -2, -1),
    (0, 0, 0, 0, 0, 0, 2, 6, 6, 2, -1, -2, 0, -2, -1),
    (0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 2, 0, 0, 0),
    (0, 0, 0, 0, 0, 0, 2, 0, 0, 0, -1, -2, 0, 0, 0),
    (1, -2, 2, 0, -6, 0, 2, 6, 0, -4, -1, -2, 0, 4, 2),
    (0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, -2, -1),
    (0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 1),
)
_STEPS = ((1, 0), (0, 1), (-1, 1), (-1, 0), (0, -1), (1, -1))  # lattice neighbours


def _phantom_candidates() -> tuple[tuple[int, int, int], ...]:
    """Per slot, the reflections that may replace it, best first: ``(B1, B2, I)`` slot
    triples (edge midpoints first, then vertices with ``B1 == B2``); a constant table
    built once over the 12 slots."""
    index = {p: k for k, p in enumerate(SLOTS)}
    table = []
    for q in SLOTS:  # the 12 slots of the patch, not elements
        near = [(q[0] + di, q[1] + dj) for di, dj in _STEPS]
        rows = []
        for x in range(6):
            b1, b2 = near[x], near[(x + 1) % 6]  # adjacent neighbours: a lattice edge
            i = (b1[0] + b2[0] - q[0], b1[1] + b2[1] - q[1])
            if b1 in index and b2 in index and i in index:
                rows.append((index[b1], index[b2], index[i]))
        for b in near:
            i = (2 * b[0] - q[0], 2 * b[1] - q[1])
            if b in index and i in index:
                rows.append((index[b], index[b], index[i]))
        table.append(rows)
    width = max(len(r) for r in table)
    return tuple(tuple(r + [(-1, -1, -1)] * (width - len(r))) for r in table)


_CANDIDATES = _phantom_candidates()


def box_spline_weights(u: torch.Tensor, v: torch.Tensor):
    """The 12 basis weights and their ``u``, ``v`` derivatives at ``(u, v) (n,)``:
    three ``(n, 12)``."""
    coef = torch.tensor(_BOX, dtype=u.dtype, device=u.device) / 12.0  # (12, 15)
    exps = torch.tensor(_MONOMIALS, device=u.device)
    i, j = exps[:, 0], exps[:, 1]

    def mono(a, b):
        powers = u[:, None] ** a.clamp(min=0) * v[:, None] ** b.clamp(min=0)
        return torch.where((a >= 0) & (b >= 0), powers, 0.0)

    m = mono(i, j)
    mu = mono(i - 1, j) * i
    mv = mono(i, j - 1) * j
    return m @ coef.T, mu @ coef.T, mv @ coef.T


def _next3(c: torch.Tensor) -> torch.Tensor:
    return c - c % 3 + (c + 1) % 3


def _prev3(c: torch.Tensor) -> torch.Tensor:
    return c - c % 3 + (c + 2) % 3


def triangle_slots(topo, twin, cut_e, faces: torch.Tensor):
    """``(slots (n, 12) long, present (n, 12) bool, cw, ccw)`` of triangles ``faces``: the
    control vertex of each slot, found walking each corner's fan both ways and stopping
    at ``cut_e`` edges; whether it exists on this side of every crease; and the walks
    (``cw[k]``, ``ccw[k]``: ``(n, 3)`` corner ``k`` faces on, ``-1`` past a crease)."""
    h = 3 * faces[:, None] + torch.arange(3, device=faces.device)  # (n, 3) corners
    cross = torch.where(cut_e[topo.edge_c], -1, twin)  # the twin half-edge, uncut only

    def turn(c, t):  # the corner at the same vertex in the face across half-edge t
        return torch.where((c >= 0) & (t >= 0), t.clamp(min=0), -1)

    cw, ccw = [h], [h]
    for _ in range(4):  # four faces around each corner (fixed, not per element)
        t = turn(cw[-1], cross[cw[-1].clamp(min=0)])  # across the out-edge
        cw.append(torch.where(t >= 0, _next3(t.clamp(min=0)), -1))
        ccw.append(turn(ccw[-1], cross[_prev3(ccw[-1].clamp(min=0))]))  # across the in-edge
    vert = topo.vert_c
    slots, present = [vert[h]], [torch.ones_like(h, dtype=torch.bool)]
    for k in (1, 2, 3):  # X_k: clockwise step k, or counter-clockwise step 5 - k
        a, b = cw[k], ccw[5 - k]
        slots.append(torch.where(a >= 0, vert[_next3(a.clamp(min=0))],
                                 vert[_prev3(b.clamp(min=0))]))
        present.append((a >= 0) | (b >= 0))
    order = torch.tensor([0, 1, 2, 3, 6, 9, 4, 7, 10, 5, 8, 11], device=faces.device)
    slots = torch.stack(slots, 1).reshape(-1, 12)[:, order]  # (kind, corner) -> SLOTS
    present = torch.stack(present, 1).reshape(-1, 12)[:, order]
    return slots, present, cw, ccw


def phantom_rules(present: torch.Tensor):
    """``(rule (n, 12, 3) long, ok (n,) bool)``: for each missing slot, the first
    reflection whose three slots are present (a present slot keeps itself), and whether
    every missing slot found one."""
    cand = torch.tensor(_CANDIDATES, device=present.device)  # (12, K, 3)
    usable = (cand >= 0).all(-1)
    padded = torch.cat([present, torch.zeros_like(present[:, :1])], 1)  # index 12: absent
    idx = torch.where(cand >= 0, cand, 12)
    ok_k = padded[:, idx].all(-1) & usable  # (n, 12, K)
    first = torch.argmax(ok_k.to(torch.int8), dim=-1)  # (n, 12)
    rule = cand[torch.arange(12, device=present.device), first]  # (n, 12, 3)
    self_rule = torch.arange(12, device=present.device)[:, None].expand(12, 3)
    rule = torch.where(present[..., None], self_rule, rule)
    found = ok_k.any(-1) | present
    return rule, found.all(-1)


def phantom_fold_loop(present: torch.Tensor, rule: torch.Tensor, dtype) -> torch.Tensor:
    """``(m, 12, 12)``: each slot as a combination of slots, a missing one as its
    reflection ``B1 + B2 - I`` (``rule (m, 12, 3)``)."""
    m = present.shape[0]
    eye = torch.eye(12, dtype=dtype, device=present.device).expand(m, 12, 12)
    fold = torch.where(present[:, :, None], eye, 0.0)
    ghost = (~present).to(dtype)[:, :, None].expand(m, 12, 1)
    fold = fold.scatter_add(2, rule[..., 0:1], ghost).scatter_add(2, rule[..., 1:2], ghost)
    return fold.scatter_add(2, rule[..., 2:3], -ghost)


def regular_triangles(topo, faces_f3, sharp_e, sharp_v, hole_f, twin) -> torch.Tensor:
    """``(F,)`` bool: the triangles whose limit is one box-spline patch (module docstring)."""
    F = faces_f3.shape[0]
    if F == 0:
        return torch.zeros(0, dtype=torch.bool, device=faces_f3.device)
    inf_e, n_inf, n_semi = sharp_edge_counts(topo, sharp_e)
    val, nf = topo.valence_v, topo.num_faces_v
    free = (sharp_v == 0) & (n_semi == 0)
    smooth_v = free & (n_inf == 0) & (val == 6) & (nf == 6)
    crease_v = free & (n_inf == 2) & (((val == 4) & (nf == 3)) | ((val == 6) & (nf == 6)))
    all_f = torch.arange(F, device=faces_f3.device)
    _, present, cw, ccw = triangle_slots(topo, twin, inf_e, all_f)
    side = sum((c >= 0).long() for c in cw[1:3]) + sum((c >= 0).long() for c in ccw[1:3])
    corner_v = faces_f3  # (F, 3)
    ok_corner = smooth_v[corner_v] | (crease_v[corner_v] & (side == 2) &
                                      (cw[3] < 0) & (ccw[3] < 0))
    _, found = phantom_rules(present)
    return ok_corner.all(1) & found & ~hole_f
