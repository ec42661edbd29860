"""Exact limit patches around isolated smooth extraordinary vertices (Stam's evaluation).

Convention:
    A face of a refined level is an *EV face* when exactly one corner is a smooth interior
    vertex (no sharp or boundary edge, untagged, a closed fan) of valence ``N`` other than
    the regular one (Catmark 4, Loop 6), and its other corners are smooth regular
    interior vertices with no sharp edge. Rotated so that the extraordinary vertex (EV)
    is corner 0 (the rotations are the child maps of the corners, halved), its limit
    depends on ``K`` *slots* (Catmark ``2N + 8``, Loop ``N + 6``): the EV; per face of
    its fan, turning from this face across the in-edges, the edge neighbour along the
    face's out-edge (Catmark: then the diagonal); then the rest of the face's regular
    control grid (Catmark 7 points, Loop 5). One level of subdivision maps the slots to
    those of the child at the EV by a fixed ``(K, K)`` matrix ``A``; the other children
    are regular patches whose control points are fixed ``P_p = (16 or 12, K)`` matrices
    of the slots. A point ``n`` levels deep in the EV's children (``2**n max(s, t)``,
    Loop ``2**n (s + t)``, in ``[1/2, 1)``) in child ``p`` of that level has the weights
    ``b(s', t') P_p A^n`` (Stam 1998: the B-spline or box-spline basis at the point's
    coordinates in the child). Instead of ``A``'s eigenvectors, ``A^n = 1 l^T + lam^n
    Q^n`` (``n >= 1``) with ``l`` the EV's limit mask, ``lam`` the subdominant
    eigenvalue and ``Q = (A - 1 l^T) / lam`` (spectral radius 1, powers by squaring),
    so the derivatives, which grow or shrink like ``(2 lam)^n``, keep their relative
    accuracy at any depth. At the EV itself the derivatives are unbounded (``lam >
    1/2``) or zero (``lam < 1/2``: Catmark's valence 3, Loop's 3 to 5); there ``du``,
    ``dv`` are the limits of the derivatives at ``(2^-n, 0)`` and ``(0, 2^-n)`` (the
    child corners on the two edges) divided by ``(2 lam)^n``: tangent to the two edges,
    so ``du x dv`` is the exact limit normal. ``A``, ``P_p``, ``l`` and ``lam`` are
    computed once per scheme and valence, in float64, by subdividing a template ring
    with the scheme's own operator.
"""

from __future__ import annotations

import functools

import torch

from torchgeo_cg.mesh.subdivision._limit_masks import catmark_limit_stencils, loop_limit_stencils
from torchgeo_cg.mesh.subdivision._loop_patches import box_spline_weights, triangle_slots
from torchgeo_cg.mesh.subdivision._patches import (
    bspline_basis,
    patch_grids,
    quad_twins,
    sharp_edge_counts,
)
from torchgeo_cg.mesh.subdivision._topology import mesh_topology
from torchgeo_cg.mesh.subdivision.catmark import catmull_clark_operator
from torchgeo_cg.mesh.subdivision.loop import loop_operator

# child quad p of a quad: its local (s', t') = A_p (s, t) + b_p (corner p's child has its
# corner 0 at corner p, turned so that its u runs along the parent's edge p -> p + 1)
CHILD_A = ((2, 0, 0, 2), (0, 2, -2, 0), (-2, 0, 0, -2), (0, -2, 2, 0))
CHILD_B = ((0, 0), (0, 2), (2, 2), (2, 0))
# child triangle p of a triangle (Loop's child order: corners 0, 1, 2, then the middle)
TRI_A = ((2, 0, 0, 2), (0, 2, -2, -2), (-2, -2, 2, 0), (2, 2, -2, 0))
TRI_B = ((0, 0), (0, 2), (2, 0), (-1, 1))
# grid slots (j * 4 + k) of the 7 points of a Catmark face's grid outside the EV's fan, for
# the EV at corner 0 of the face (patch_grids' layout); corner r turns them by r sides
_GRID_SIDES = (((0, 1), (1, 3), (3, 2), (2, 0)), ((0, 2), (2, 3), (3, 1), (1, 0)),
               ((0, 0), (0, 3), (3, 3), (3, 0)))  # adjacent start, adjacent end, diagonal


def _outer_catmark(r: int) -> list[int]:
    start, end, diag = _GRID_SIDES
    picks = [start[(r + 1) % 4], end[(r + 1) % 4], start[(r + 2) % 4], end[(r + 2) % 4],
             diag[(r + 1) % 4], diag[(r + 2) % 4], diag[(r + 3) % 4]]
    return [4 * j + k for j, k in picks]


def _outer_loop(r: int) -> list[int]:
    """The 5 of ``triangle_slots``' 12 outside the fan: ``X1..X3`` of corner ``r + 1`` and
    ``X2, X3`` of corner ``r + 2``."""
    b, c = 3 + 3 * ((r + 1) % 3), 3 + 3 * ((r + 2) % 3)
    return [b, b + 1, b + 2, c + 1, c + 2]


def _regular(scheme: str) -> int:
    return 4 if scheme == "catmark" else 6


def ev_face_corners(topo, twin, faces, sharp_e, sharp_v, scheme: str) -> torch.Tensor:
    """``(F,)`` long: the corner of each EV face holding its extraordinary vertex, ``-1``
    for other faces (module docstring)."""
    reg = _regular(scheme)
    if faces.shape[0] == 0:
        return torch.zeros(0, dtype=torch.long, device=faces.device)
    _, n_inf, n_semi = sharp_edge_counts(topo, sharp_e)
    val, nf = topo.valence_v, topo.num_faces_v
    smooth = (sharp_v == 0) & (n_inf == 0) & (n_semi == 0) & (val == nf)
    ev_v = smooth & (val != reg) & (val >= 3)
    reg_v = smooth & (val == reg)
    # every edge at the vertex has a consistently wound twin (the walks need them)
    twinned = torch.ones_like(smooth).scatter_reduce(0, topo.vert_c, twin >= 0, "amin")
    ev_c, reg_c = (ev_v & twinned)[faces], (reg_v & twinned)[faces]  # (F, k)
    one = (ev_c.sum(1) == 1) & ((ev_c | reg_c).all(1))
    corner = torch.argmax(ev_c.to(torch.int8), 1)
    return torch.where(one, corner, -1)


def _fan(topo, twin, h0: torch.Tensor, N: int, k: int, scheme: str) -> torch.Tensor:
    """``(n, 1 + N or 1 + 2N)`` slots of the EV and its fan, from the EV's corners ``h0``
    (a loop over the fan's faces, ``N`` fixed: one valence at a time)."""
    vert = topo.vert_c

    def step(c, j):  # corner j places after corner c in its face
        return c - c % k + (c + j) % k

    out, h = [vert[h0]], h0
    for _ in range(N):  # the N faces of the fan, not elements
        out.append(vert[step(h, 1)])
        if scheme == "catmark":
            out.append(vert[step(h, 2)])
        h = twin[step(h, k - 1)].clamp(min=0)  # across the in-edge: the next fan face
    return torch.stack(out, 1)


def ring_slots(topo, twin, faces_f, corner, N: int, scheme: str) -> torch.Tensor:
    """``(n, K)`` long: the slots of EV faces ``faces_f (n,)`` of valence ``N`` with their
    EV at ``corner (n,)`` (module docstring's order)."""
    k = 4 if scheme == "catmark" else 3
    h0 = k * faces_f + corner
    fan = _fan(topo, twin, h0, N, k, scheme)
    if scheme == "catmark":
        grid, _ = patch_grids(topo, twin, torch.zeros_like(topo.edge_lo_e, dtype=torch.float64),
                              faces_f)
        grid = grid.reshape(-1, 16)
    else:
        cut = torch.zeros_like(topo.edge_lo_e, dtype=torch.bool)
        grid, _, _, _ = triangle_slots(topo, twin, cut, faces_f)
    pick = _outer_catmark if scheme == "catmark" else _outer_loop
    table = torch.tensor([pick(r) for r in range(k)], device=faces_f.device)  # (k, 7 or 5)
    outer = torch.gather(grid, 1, table[corner])
    return torch.cat([fan, outer], 1)


def _template(N: int, scheme: str) -> tuple[list[list[int]], int]:
    """A ring of valence ``N`` around vertex 0 whose face 0 is an EV face (EV at corner 0)
    with the full neighbourhoods of its other corners."""
    if scheme == "catmark":
        e = [1 + i % N for i in range(N + 1)]  # e[i]: edge neighbour i (e[N] = e[0])
        d = [N + 1 + i % N for i in range(N + 1)]
        o = [2 * N + 1 + i for i in range(7)]  # (2,-1) (2,0) (2,1) (2,2) (1,2) (0,2) (-1,2)
        faces = [[0, e[i], d[i], e[i + 1]] for i in range(N)]
        faces += [[d[N - 1], o[0], o[1], e[0]], [e[0], o[1], o[2], d[0]],
                  [d[0], o[2], o[3], o[4]], [e[1], d[0], o[4], o[5]], [d[1], e[1], o[5], o[6]]]
        return faces, 2 * N + 8
    e = [1 + i % N for i in range(N + 1)]
    o = [N + 1 + i for i in range(5)]  # lattice (1,1) (2,0) (2,-1) (-1,2) (0,2)
    faces = [[0, e[i], e[i + 1]] for i in range(N)]
    faces += [[e[0], o[1], o[0]], [e[0], o[0], e[1]], [e[0], e[N - 1], o[2]],
              [e[0], o[2], o[1]], [e[1], o[0], o[4]], [e[1], o[4], o[3]], [e[1], o[3], e[2]]]
    return faces, N + 6


@functools.cache
def _tables(N: int, scheme: str):
    """float64 CPU ``(P (3, S, K), l (K,), lam, Q powers (B, K, K), Pi (K, K))`` of valence
    ``N``: the children's patch maps, the limit mask, the subdominant eigenvalue, ``Q^(2^b)``
    and ``Pi = Q^inf`` (module docstring)."""
    f64 = torch.float64
    faces, V = _template(N, scheme)
    build = catmull_clark_operator if scheme == "catmark" else loop_operator
    op = build(faces, V, dtype=f64)
    S = op.stencils.dense()
    faces0 = torch.tensor(faces)
    zero = torch.zeros(1, dtype=torch.long)
    topo0 = mesh_topology(faces0, V, "edge_only", None)
    slots0 = ring_slots(topo0, quad_twins(topo0), zero, zero, N, scheme)[0]
    child = op.faces if op.child_faces is None else op.child_faces
    topo1 = mesh_topology(child, op.num_vertices_out, "edge_only", None)
    twin1 = quad_twins(topo1)
    slots1 = ring_slots(topo1, twin1, zero, zero, N, scheme)[0]  # child 0 of face 0
    kids = torch.tensor([1, 2, 3])
    if scheme == "catmark":
        grid = patch_grids(topo1, twin1, torch.zeros(topo1.edge_lo_e.numel(), dtype=f64),
                           kids)[0].reshape(3, 16)
        masks = catmark_limit_stencils
    else:
        grid = triangle_slots(topo1, twin1, torch.zeros(topo1.edge_lo_e.numel(),
                                                        dtype=torch.bool), kids)[0]
        masks = loop_limit_stencils
    A = S[slots1][:, slots0]
    P = S[grid][:, :, slots0]
    l_row = masks(faces0, V, "edge_only", f64).dense()[0][slots0]
    K = slots0.numel()
    values, vectors = torch.linalg.eig(A)
    lam = float(values.abs().sort(descending=True).values[1])
    Q = (A - torch.ones(K, 1, dtype=f64) * l_row) / lam
    powers = [Q]
    for _ in range(11):  # Q^(2^b): depths up to 4095 levels (float64 points reach 1075)
        powers.append(powers[-1] @ powers[-1])
    # Q^inf, the projector on the subdominant eigenvectors (from the eigenvectors: the
    # powers converge like (next eigenvalue / lam)^n, slowly at high valence)
    pair = torch.argsort((values - lam).abs())[:2]
    Pi = (vectors[:, pair] @ torch.linalg.inv(vectors)[pair, :]).real
    return P, l_row, lam, torch.stack(powers), Pi


def ev_tables(N: int, scheme: str, dtype, device):
    """:func:`_tables` in ``dtype`` on ``device``."""
    P, l_row, lam, powers, Pi = _tables(N, scheme)
    to = functools.partial(torch.Tensor.to, dtype=dtype, device=device)
    return to(P), to(l_row), lam, to(powers), to(Pi)


def rotate_to_corner(s, t, jac, corner, scheme: str):
    """The point's ``(s, t)`` and Jacobian in its face turned so that ``corner (n,)`` is
    corner 0."""
    table_a, table_b = (CHILD_A, CHILD_B) if scheme == "catmark" else (TRI_A, TRI_B)
    A = torch.tensor(table_a, dtype=s.dtype, device=s.device).reshape(-1, 2, 2)[corner] / 2
    b = torch.tensor(table_b, dtype=s.dtype, device=s.device)[corner] / 2
    st = torch.einsum("nij,nj->ni", A, torch.stack([s, t], -1)) + b
    return st[:, 0].clamp(0, 1), st[:, 1].clamp(0, 1), A @ jac


def _child_rows(s, t, P, scheme: str) -> torch.Tensor:
    """``(n, 3, K)``: position, ``d/ds`` and ``d/dt`` rows in the slots of the point's
    level, for ``(s, t) (n,)`` outside the EV's child (``max(s, t)``, Loop ``s + t``, at
    least 1/2)."""
    hi_s, hi_t = s >= 0.5, t >= 0.5
    if scheme == "catmark":
        p = torch.where(hi_t, torch.where(hi_s, 2, 3), 1)
        table_a, table_b = CHILD_A, CHILD_B
    else:
        p = torch.where(hi_s, 1, torch.where(hi_t, 2, 3))
        table_a, table_b = TRI_A, TRI_B
    A = torch.tensor(table_a, dtype=s.dtype, device=s.device).reshape(4, 2, 2)[p]
    b = torch.tensor(table_b, dtype=s.dtype, device=s.device)[p]
    st = torch.einsum("nij,nj->ni", A, torch.stack([s, t], -1)) + b
    cs, ct = st[:, 0].clamp(0, 1), st[:, 1].clamp(0, 1)
    if scheme == "catmark":
        bu, du = bspline_basis(cs)
        bv, dv = bspline_basis(ct)
        outer = lambda x, y: (x[:, :, None] * y[:, None, :]).reshape(-1, 16)  # noqa: E731
        w, w_s, w_t = outer(bv, bu), outer(bv, du), outer(dv, bu)
    else:
        w, w_s, w_t = box_spline_weights(cs, ct)
    a00, a01, a10, a11 = (A[:, i, j, None] for i, j in ((0, 0), (0, 1), (1, 0), (1, 1)))
    W = torch.stack([w, w_s * a00 + w_t * a10, w_s * a01 + w_t * a11], 1)  # (n, 3, S)
    rows = W.new_zeros(W.shape[0], 3, P.shape[-1])
    for child in (1, 2, 3):  # the three regular children, not elements
        m = p == child
        rows[m] = W[m] @ P[child - 1]
    return rows


def _times_power(rows: torch.Tensor, n: torch.Tensor, powers: torch.Tensor) -> torch.Tensor:
    """``rows (m, 3, K) @ Q^n`` per point, ``n (m,)``, by the bits of ``n`` (a loop over
    bits)."""
    top = int(n.max()).bit_length() if n.numel() else 0
    for b in range(top):
        bit = ((n >> b) & 1).bool()
        if bool(bit.any()):
            rows = torch.where(bit[:, None, None], rows @ powers[b], rows)
    return rows


def ev_weights(tables, scheme: str):
    """The weights callable of a block of points in EV faces of one valence (``tables``
    of :func:`ev_tables`): packed ``(s, t, jac)`` rows (the EV at corner 0) -> ``(m, 3,
    K)`` weights of the position and ``d/du``, ``d/dv``."""
    P, l_row, lam, powers, Pi = tables

    def weights(st: torch.Tensor) -> torch.Tensor:
        s, t = st[:, 0], st[:, 1]
        j = torch.maximum(s, t) if scheme == "catmark" else s + t
        at_ev = j == 0
        _, e = torch.frexp(torch.where(at_ev, torch.ones_like(j), j))
        n = (-e).clamp(min=0)  # levels inside the EV's children: 2^n j in [1/2, 1)
        half = (n // 2).to(st.dtype)
        up = torch.pow(2.0, half) * torch.pow(2.0, n.to(st.dtype) - half)  # exact powers of 2
        rows = _times_power(_child_rows(s * up, t * up, P, scheme), n, powers)
        nd = n.to(st.dtype)
        scale = torch.stack([torch.pow(lam, nd), torch.pow(2 * lam, nd), torch.pow(2 * lam, nd)],
                            1)
        rows = rows * scale[:, :, None]
        rows[:, 0] += (n > 0).to(st.dtype)[:, None] * l_row  # A^n = 1 l^T + lam^n Q^n, n >= 1
        if bool(at_ev.any()):  # the EV: its limit mask and the normalised edge tangents
            k = int(at_ev.sum())
            half_pt = torch.full((k,), 0.5, dtype=st.dtype, device=st.device)
            zero = torch.zeros_like(half_pt)
            d_s = _child_rows(half_pt, zero, P, scheme)[:, 1] @ Pi
            d_t = _child_rows(zero, half_pt, P, scheme)[:, 2] @ Pi
            rows[at_ev] = torch.stack([l_row.expand(k, -1), d_s, d_t], 1)
        a, c, b, d = (st[:, i, None] for i in range(2, 6))  # d(s, t)/d(u, v), row-major
        return torch.stack([rows[:, 0], rows[:, 1] * a + rows[:, 2] * b,
                            rows[:, 1] * c + rows[:, 2] * d], 1)

    return weights
