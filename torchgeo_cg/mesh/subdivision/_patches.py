"""Regular Catmark patches of an all-quad mesh level: which faces are regular, their 4 x 4
B-spline control grids, their phantom rows, and the cubic B-spline basis.

Convention (OpenSubdiv's ``Far::PatchBuilder`` with ``useInfSharpPatch``):
    A quad is regular when it is not a hole and each of its corners is one of: a smooth
    vertex of valence 4; a crease vertex (two infinitely sharp edges, vertex untagged)
    of valence 3 on a boundary, or of valence 4 with the crease running straight
    through (each of its four faces has exactly one crease edge); a corner (infinitely
    sharp vertex) of valence 2 with one face. No semi-sharp edge or vertex may touch
    the quad's corners. Infinitely sharp edges of the quad are the patch's boundary: the
    row of points beyond is the phantom ``2 P_edge - P_inner`` (the crease rule's cubic
    B-spline), folded into the patch's map from grid slots to vertices.

    Grid ``G[j][k]`` has ``k`` along ``u`` and ``j`` along ``v``; the quad's corners
    0-3 sit at ``G[1][1], G[1][2], G[2][2], G[2][1]`` ((0,0), (1,0), (1,1), (0,1)).
"""

from __future__ import annotations

import torch

from torchgeo_cg.mesh.subdivision.tags import INFINITELY_SHARP

# grid slots (j, k) of: the corners; the outer point next to corner i across edge i; the
# outer point next to corner i + 1 across edge i; the diagonal point at corner i
_CORNER = ((1, 1), (1, 2), (2, 2), (2, 1))
_ADJ_START = ((0, 1), (1, 3), (3, 2), (2, 0))
_ADJ_END = ((0, 2), (2, 3), (3, 1), (1, 0))
_DIAGONAL = ((0, 0), (0, 3), (3, 3), (3, 0))


def _next(c: torch.Tensor) -> torch.Tensor:
    return c - c % 4 + (c + 1) % 4


def _prev(c: torch.Tensor) -> torch.Tensor:
    return c - c % 4 + (c + 3) % 4


def quad_twins(topo) -> torch.Tensor:
    """``(C,)`` long: the opposite corner (half-edge) across each corner's out-edge, ``-1``
    where the edge does not have exactly two consistently wound faces."""
    edge_c, vert_c = topo.edge_c, topo.vert_c
    C = edge_c.numel()
    order = torch.sort(edge_c, stable=True).indices
    count_e = torch.bincount(edge_c, minlength=topo.edge_lo_e.numel())
    twin = torch.full((C,), -1, dtype=torch.long, device=edge_c.device)
    if C == 0:
        return twin
    first = torch.ones(C, dtype=torch.bool, device=edge_c.device)
    first[1:] = edge_c[order[1:]] != edge_c[order[:-1]]
    pair = first & (count_e[edge_c[order]] == 2)
    a = order[pair]
    b = order[torch.nonzero(pair).flatten() + 1]
    consistent = vert_c[a] != vert_c[b]
    a, b = a[consistent], b[consistent]
    twin[a], twin[b] = b, a
    return twin


def sharp_edge_counts(topo, sharp_e: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(inf_e, n_inf_v, n_semi_v)``: the infinitely sharp edges, and per vertex the number
    of its infinitely sharp and of its semi-sharp edges."""
    V = topo.valence_v.numel()
    inf_e = sharp_e >= INFINITELY_SHARP
    semi_e = (sharp_e > 0) & ~inf_e
    ends = torch.cat([topo.edge_lo_e, topo.edge_hi_e])

    def count(mask):
        return torch.bincount(ends[torch.cat([mask, mask])], minlength=V)

    return inf_e, count(inf_e), count(semi_e)


def regular_quads(topo, faces_q4, sharp_e, sharp_v, hole_f) -> torch.Tensor:
    """``(F,)`` bool: the quads whose limit is one bicubic B-spline patch (module docstring)."""
    V = topo.valence_v.numel()
    inf_e, n_inf, n_semi = sharp_edge_counts(topo, sharp_e)
    per_corner = inf_e[topo.edge_c].long() + inf_e[topo.edge_c[topo.prev_corner_c]].long()
    most = torch.zeros(V, dtype=torch.long, device=sharp_e.device).scatter_reduce(
        0, topo.vert_c, per_corner, "amax")
    val, nf = topo.valence_v, topo.num_faces_v
    free = sharp_v == 0
    smooth = free & (n_inf == 0) & (val == 4) & (nf == 4)
    straight = (val == 4) & (nf == 4) & (most == 1)
    crease = free & (n_inf == 2) & (((val == 3) & (nf == 2)) | straight)
    corner = (sharp_v >= INFINITELY_SHARP) & (val == 2) & (nf == 1)
    regular_v = (smooth | crease | corner) & (n_semi == 0)
    if faces_q4.shape[0] == 0:
        return torch.zeros(0, dtype=torch.bool, device=sharp_e.device)
    return regular_v[faces_q4].all(1) & ~hole_f


def patch_grids(topo, twin, sharp_e, faces: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(grid (n, 4, 4) long, phantom (n, 4) bool)`` for the regular quads ``faces``:
    the control vertex of each grid slot (any index where the slot is a phantom) and
    whether each edge of the quad is a patch boundary."""
    h = 4 * faces[:, None] + torch.arange(4, device=faces.device)  # (n, 4) corners
    vert = topo.vert_c
    t = twin[h].clamp(min=0)
    phantom = sharp_e[topo.edge_c[h]] >= INFINITELY_SHARP
    diag_he = twin[_next(t)].clamp(min=0)
    grid = torch.zeros(faces.numel(), 4, 4, dtype=torch.long, device=faces.device)
    for i in range(4):  # the four sides of one quad, not a loop over elements
        for (j, k), values in ((_CORNER[i], vert[h[:, i]]),
                               (_ADJ_START[i], vert[_next(_next(t[:, i]))]),
                               (_ADJ_END[i], vert[_prev(t[:, i])]),
                               (_DIAGONAL[i], vert[_prev(diag_he[:, i])])):
            grid[:, j, k] = values
    return grid, phantom


def bspline_basis(t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Uniform cubic B-spline basis and its derivative at ``t (n,)``: two ``(n, 4)``."""
    s = 1.0 - t
    t2, t3 = t * t, t * t * t
    basis = torch.stack([s * s * s, 3 * t3 - 6 * t2 + 4, -3 * t3 + 3 * t2 + 3 * t + 1, t3], -1)
    deriv = torch.stack([-3 * s * s, 9 * t2 - 12 * t, -9 * t2 + 6 * t + 3, 3 * t2], -1)
    return basis / 6.0, deriv / 6.0


def phantom_fold(phantom: torch.Tensor, dtype) -> torch.Tensor:
    """``(m, 16, 16)``: each grid slot as a combination of grid slots, with the phantom
    rows beyond infinitely sharp edges ``2 P_edge - P_inner`` (``phantom (m, 4)``: edges
    0-3 of the quad; edges 3 and 1 bound ``u`` below and above, 0 and 2 bound ``v``)."""
    m = phantom.shape[0]
    eye = torch.eye(4, dtype=dtype, device=phantom.device)
    low = torch.tensor([0.0, 2.0, -1.0, 0.0], dtype=dtype, device=phantom.device)

    def axis(lo, hi):  # (m, 4, 4): one axis's map
        f = eye.expand(m, 4, 4).clone()
        f[:, 0] = torch.where(lo[:, None], low, eye[0])
        f[:, 3] = torch.where(hi[:, None], low.flip(0), eye[3])
        return f

    fu, fv = axis(phantom[:, 3], phantom[:, 1]), axis(phantom[:, 0], phantom[:, 2])
    return torch.einsum("mjJ,mkK->mjkJK", fv, fu).reshape(m, 16, 16)
