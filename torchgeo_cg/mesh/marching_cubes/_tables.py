"""The 256-case marching-cubes triangulation table, generated in code (report section 1.4).

Nothing here is pasted in: :func:`generate_tables` derives every case by tracing,
on each of the cube's six faces, the segments that the face's four corners imply,
chaining the segments into closed loops, and triangulating each loop.

Numbering (corner ``c`` sits at offset ``(dx, dy, dz)`` from the cell's lower
corner, with ``c = 4*dx + 2*dy + dz``; bit ``c`` of the case index is set when
corner ``c`` is *inside*, i.e. its sample is ``< iso``)::

            3 ----------- 7              z
           /|            /|              |   y
          / |           / |              |  /
         1 ----------- 5  |              | /
         |  |          |  |              |/
         |  2 ---------|- 6              +------- x
         | /           | /
         |/            |/                corner c = 4*dx + 2*dy + dz
         0 ----------- 4                 edge   e = 4*d + m

    edges along x (d=0), m = 2*dy + dz:  e0 = 0-4, e1 = 1-5, e2 = 2-6, e3 = 3-7
    edges along y (d=1), m = 2*dx + dz:  e4 = 0-2, e5 = 1-3, e6 = 4-6, e7 = 5-7
    edges along z (d=2), m = 2*dx + dy:  e8 = 0-1, e9 = 2-3, e10 = 4-5, e11 = 6-7

Every edge runs from its lower corner to the corner one step along ``d``, so a
grid edge is keyed by (lower grid corner, direction) and welding is free.

The one rule for ambiguous faces (two diagonal inside corners, two diagonal
outside corners): **the inside corners are separated**, i.e. each inside corner
is cut off by its own segment. The rule reads only the face's four corners, so
the two cells sharing a face draw the same segments on it (with opposite
orientation), and the extracted surface is closed and edge-manifold by
construction. Loops are triangulated without any diagonal joining two vertices
on a common cube face (such a diagonal could be drawn by the neighbour cell as
well, making an edge with four triangles); among the admissible triangulations
the one maximising the worst triangle quality (on edge midpoints) is kept.

Winding: triangles are counter-clockwise seen from the outside, so the right-hand
normal ``(v1 - v0) x (v2 - v0)`` points towards increasing field values.

The report notes that the 256 cases reduce to 15 under the cube's symmetries; the
loop-tracing construction needs no case list at all, and :data:`AMBIGUOUS` marks
the cases whose topology is not fixed by their corners (the inside or the outside
corners are not connected along cube edges), where tools disagree.
"""

from __future__ import annotations

from functools import cache
from typing import NamedTuple

import torch

__all__ = [
    "CORNER_OFFSETS",
    "EDGE_CORNERS",
    "EDGE_DIRECTION",
    "CUBE_FACES",
    "face_segments",
    "generate_tables",
    "TRIANGLES",
    "AMBIGUOUS",
    "MAX_TRIANGLES",
    "table_tensors",
    "corner_tables",
    "configuration_loops",
    "MAX_TUBES",
    "CENTRE",
    "ambiguous_faces",
    "corner_patches",
    "tube_candidates",
    "configuration_triangles",
    "tube_witness",
    "ConfigurationTables",
    "configuration_tensors",
]

#: (8, 3) offsets (dx, dy, dz) of corner c = 4*dx + 2*dy + dz.
CORNER_OFFSETS: tuple[tuple[int, int, int], ...] = tuple(
    ((c >> 2) & 1, (c >> 1) & 1, c & 1) for c in range(8)
)


def _make_edges() -> tuple[tuple[tuple[int, int], ...], tuple[int, ...]]:
    corners, dirs = [], []
    for d in range(3):
        others = [a for a in range(3) if a != d]
        for m in range(4):
            off = [0, 0, 0]
            off[others[0]], off[others[1]] = (m >> 1) & 1, m & 1
            lo = 4 * off[0] + 2 * off[1] + off[2]
            corners.append((lo, lo | (1 << (2 - d))))
            dirs.append(d)
    return tuple(corners), tuple(dirs)


#: (12, 2) corners (lower, upper) of edge e; EDGE_DIRECTION[e] is its axis d.
EDGE_CORNERS, EDGE_DIRECTION = _make_edges()


def _make_faces() -> tuple[tuple[int, int, tuple[int, int, int, int]], ...]:
    """(axis, side, 4 corners in cyclic order) for the six cube faces."""
    faces = []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for side in (0, 1):
            ring = []
            for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                off = [0, 0, 0]
                off[axis], off[u], off[v] = side, du, dv
                ring.append(4 * off[0] + 2 * off[1] + off[2])
            faces.append((axis, side, tuple(ring)))
    return tuple(faces)


#: The six cube faces as (axis, side, cyclic ring of 4 corners).
CUBE_FACES = _make_faces()

_EDGE_OF_PAIR = {frozenset(p): e for e, p in enumerate(EDGE_CORNERS)}


def _midpoint(e: int) -> tuple[float, ...]:
    a, b = EDGE_CORNERS[e]
    return tuple((pa + pb) / 2 for pa, pb in zip(CORNER_OFFSETS[a], CORNER_OFFSETS[b]))


def _sub(p, q):
    return tuple(a - b for a, b in zip(p, q))


def _cross(p, q):
    return (p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0])


def _dot(p, q):
    return sum(a * b for a, b in zip(p, q))


def face_segments(case: int, face: int, join: bool = False) -> list[tuple[int, int]]:
    """Oriented segments ``(edge_from, edge_to)`` that ``case`` draws on cube ``face``.

    Orientation: with ``n`` the face's outward normal, ``n x (to - from)`` points
    away from the inside corners, which makes the loops (and so the triangles)
    counter-clockwise seen from the outside. An ambiguous face separates the inside
    corners (each is cut off by its own segment), or with ``join`` joins them (each
    *outside* corner is cut off); ``join`` is ignored on other faces.

    Example:
        >>> face_segments(0b00000001, 0)  # corner 0 inside, face x = 0
        [(4, 8)]
        >>> face_segments(0b00001001, 0)  # corners 0 and 3 inside: two segments
        [(4, 8), (5, 9)]
        >>> face_segments(0b00001001, 0, join=True)  # ... joined: corners 1, 2 cut off
        [(4, 9), (5, 8)]
    """
    axis, side, ring = CUBE_FACES[face]
    inside = [(case >> c) & 1 for c in ring]
    normal = [0, 0, 0]
    normal[axis] = 1 if side else -1
    ring_edges = [_EDGE_OF_PAIR[frozenset((ring[i], ring[(i + 1) % 4]))] for i in range(4)]
    crossing = [i for i in range(4) if inside[i] != inside[(i + 1) % 4]]
    pairs: list[tuple[int, int, tuple[float, ...]]] = []  # (edge, edge, inside reference point)
    if len(crossing) == 2:
        ins = [CORNER_OFFSETS[ring[i]] for i in range(4) if inside[i]]
        ref = tuple(sum(p[k] for p in ins) / len(ins) for k in range(3))
        pairs.append((ring_edges[crossing[0]], ring_edges[crossing[1]], ref))
    elif len(crossing) == 4 and not join:  # ambiguous: cut off each inside corner
        for i in range(4):
            if inside[i]:
                pairs.append((ring_edges[(i - 1) % 4], ring_edges[i], CORNER_OFFSETS[ring[i]]))
    elif len(crossing) == 4:  # ambiguous, joined: cut off each outside corner
        centre = tuple(sum(CORNER_OFFSETS[c][k] for c in ring) / 4 for k in range(3))
        for i in range(4):
            if not inside[i]:
                pairs.append((ring_edges[(i - 1) % 4], ring_edges[i], centre))
    out = []
    for ea, eb, ref in pairs:
        pa, pb = _midpoint(ea), _midpoint(eb)
        side_of_inside = _dot(_cross(normal, _sub(pb, pa)), _sub(ref, pa))
        out.append((ea, eb) if side_of_inside < 0 else (eb, ea))
    return sorted(out)


def _share_face(e1: int, e2: int) -> bool:
    c = set(EDGE_CORNERS[e1]) | set(EDGE_CORNERS[e2])
    return any(c <= set(ring) for _, _, ring in CUBE_FACES)


_SHARE_FACE = [[_share_face(a, b) for b in range(12)] for a in range(12)]


_LOW_CHORD = 1000


def _chord_cost(e1: int, e2: int) -> int:
    """Cost of a chord between the vertices of edges ``e1`` and ``e2``: 0 across the cell,
    1 on a face at the cell's high side (``side == 1``), 1000 on a low-side face.

    The neighbour across a face sees it from the other side, so when only high-side
    chords are drawn, at most one of the two cells draws a given chord on their common
    face and no edge gets four triangles. 12 disk configurations (nine-edge loops) and
    130 tube configurations cannot avoid a low-side chord (Lewiner et al. add a vertex at
    the cell centre there); their risk is measured by the closure tests.
    """
    c = set(EDGE_CORNERS[e1]) | set(EDGE_CORNERS[e2])
    sides = [side for _, side, ring in CUBE_FACES if c <= set(ring)]
    if not sides:
        return 0
    return 1 if sides[0] == 1 else _LOW_CHORD


_CHORD_COST = [[_chord_cost(a, b) for b in range(12)] for a in range(12)]
#: Edge id of the cell-centre vertex in the asymptotic configuration tables.
CENTRE = 12


@cache
def _quality(a: int, b: int, c: int) -> float:
    pa, pb, pc = _midpoint(a), _midpoint(b), _midpoint(c)
    n = _cross(_sub(pb, pa), _sub(pc, pa))
    area2 = _dot(n, n) ** 0.5
    return area2 / (_dot(_sub(pb, pa), _sub(pb, pa)) + _dot(_sub(pc, pb), _sub(pc, pb))
                    + _dot(_sub(pa, pc), _sub(pa, pc)))


@cache
def _triangulate_loop(loop: tuple[int, ...]) -> tuple[int, list[tuple[int, int, int]]]:
    """``(cost, triangles)``: the triangulation of a loop with the least chord cost
    (:func:`_chord_cost`), then the best worst triangle quality (on edge midpoints)."""
    n = len(loop)

    def chord_cost(i: int, j: int) -> int:
        return 0 if (j - i) % n in (1, n - 1) else _CHORD_COST[loop[i]][loop[j]]

    @cache
    def best(i: int, j: int):  # polygon loop[i..j], chord (i, j) already present
        if j - i < 2:
            return (0, -float("inf"), ())
        result = None
        for k in range(i + 1, j):
            left, right = best(i, k), best(k, j)
            cost = left[0] + right[0] + chord_cost(i, k) + chord_cost(k, j)
            neg_q = max(-_quality(loop[i], loop[k], loop[j]), left[1], right[1])
            if result is None or (cost, neg_q) < result[:2]:
                result = (cost, neg_q, left[2] + ((loop[i], loop[k], loop[j]),) + right[2])
        return result

    found = best(0, n - 1)
    return found[0], list(found[2])


def _triangulate(loop: tuple[int, ...]) -> list[tuple[int, int, int]]:
    """Triangles of a loop (see :func:`_triangulate_loop`); the 256 cases of
    ``ambiguity="separate"`` need no chord between edges on a common face."""
    return _triangulate_loop(loop)[1]


def _connected(corners: list[int]) -> bool:
    if not corners:
        return True
    seen, todo = {corners[0]}, [corners[0]]
    while todo:
        c = todo.pop()
        for d in range(3):
            nb = c ^ (1 << d)
            if nb in corners and nb not in seen:
                seen.add(nb)
                todo.append(nb)
    return len(seen) == len(corners)


@cache
def configuration_loops(case: int, face_bits: int) -> list[list[int]]:
    """The closed loops of crossing edges that ``case`` cuts from the cube's faces.

    Args:
        case: corner bits (bit ``c`` set: corner ``c`` inside).
        face_bits: bit ``f`` set: ambiguous face ``f`` of :data:`CUBE_FACES` joins its
            inside corners (ignored on faces that are not ambiguous).

    Returns:
        Loops as lists of edge ids, each starting at its smallest edge, in order.

    Example:
        >>> configuration_loops(0b00001001, 0), configuration_loops(0b00001001, 1)
        ([[0, 4, 8], [3, 5, 9]], [[0, 4, 9, 3, 5, 8]])
    """
    nxt: dict[int, int] = {}
    for face in range(6):
        for ea, eb in face_segments(case, face, bool((face_bits >> face) & 1)):
            if ea in nxt:  # pragma: no cover - guarded by the construction
                raise RuntimeError(f"case {case}: edge {ea} leaves twice")
            nxt[ea] = eb
    loops, seen = [], set()
    for start in sorted(nxt):
        if start in seen:
            continue
        loop, e = [], start
        while e not in seen:
            seen.add(e)
            loop.append(e)
            e = nxt[e]
        loops.append(loop)
    return loops


def generate_tables() -> tuple[list[list[tuple[int, int, int]]], list[bool]]:
    """Generate, for all 256 cases, the triangles (as edge triples) and the ambiguity flag.

    Returns:
        ``(triangles, ambiguous)``: ``triangles[case]`` is a list of ``(e0, e1, e2)``
        edge-index triples wound outward; ``ambiguous[case]`` is True when the
        inside or the outside corners of ``case`` are not connected along edges.

    Example:
        >>> triangles, ambiguous = generate_tables()
        >>> triangles[0], triangles[255], triangles[1]
        ([], [], [(0, 4, 8)])
        >>> sum(ambiguous), max(len(t) for t in triangles)
        (128, 5)
    """
    triangles, ambiguous = [], []
    for case in range(256):
        tris: list[tuple[int, int, int]] = []
        for loop in configuration_loops(case, 0):
            tris += _triangulate(tuple(loop))
        triangles.append(tris)
        inside = [c for c in range(8) if (case >> c) & 1]
        outside = [c for c in range(8) if not (case >> c) & 1]
        ambiguous.append(not (_connected(inside) and _connected(outside)))
    return triangles, ambiguous


_TRIANGLES, _AMBIGUOUS = generate_tables()

#: ``TRIANGLES[case]``: list of outward-wound (e0, e1, e2) edge triples.
TRIANGLES: tuple[tuple[tuple[int, int, int], ...], ...] = tuple(tuple(t) for t in _TRIANGLES)
#: ``AMBIGUOUS[case]``: the case's topology is a choice (tools may differ there).
AMBIGUOUS: tuple[bool, ...] = tuple(_AMBIGUOUS)
#: The largest number of triangles of one case.
MAX_TRIANGLES: int = max(len(t) for t in TRIANGLES)


_TENSOR_CACHE: dict[torch.device, tuple[torch.Tensor, ...]] = {}


def table_tensors(device: torch.device | str | None = None) -> tuple[torch.Tensor, ...]:
    """The tables as long tensors on ``device`` (cached per device).

    Returns:
        ``(tri_edges (256, MAX_TRIANGLES, 3), num_tris (256,), edge_dir (12,),
        edge_offset (12, 3), corner_offset (8, 3))``; unused rows of
        ``tri_edges`` hold -1.

    Example:
        >>> tri_edges, num_tris, edge_dir, edge_offset, corner_offset = table_tensors()
        >>> tri_edges.shape, num_tris[1].item(), edge_dir[4].item(), edge_offset[5].tolist()
        (torch.Size([256, 5, 3]), 1, 1, [0, 0, 1])
    """
    device = torch.device("cpu" if device is None else device)
    if device not in _TENSOR_CACHE:
        tri = torch.full((256, MAX_TRIANGLES, 3), -1, dtype=torch.long)
        for case, tris in enumerate(TRIANGLES):
            if tris:
                tri[case, : len(tris)] = torch.tensor(tris, dtype=torch.long)
        num = torch.tensor([len(t) for t in TRIANGLES], dtype=torch.long)
        edge_dir = torch.tensor(EDGE_DIRECTION, dtype=torch.long)
        edge_off = torch.tensor([CORNER_OFFSETS[a] for a, _ in EDGE_CORNERS], dtype=torch.long)
        corner_off = torch.tensor(CORNER_OFFSETS, dtype=torch.long)
        _TENSOR_CACHE[device] = tuple(
            t.to(device) for t in (tri, num, edge_dir, edge_off, corner_off)
        )
    return _TENSOR_CACHE[device]



def corner_tables(device: torch.device | str | None = None) -> tuple[torch.Tensor, ...]:
    """``(edge_dir (12,), edge_offset (12, 3), corner_offset (8, 3))`` long tensors on ``device``.

    Example:
        >>> edge_dir, edge_offset, corner_offset = corner_tables()
        >>> edge_dir[4].item(), edge_offset[5].tolist(), corner_offset[3].tolist()
        (1, [0, 0, 1], [0, 1, 1])
    """
    return table_tensors(device)[2:]


# --------------------------------------------------------------------------------------
# ambiguity="asymptotic": configurations (case, face decisions, interior decision)
#
# A configuration is the case plus one decision bit per ambiguous face (bit f set:
# face f joins its inside corners, the asymptotic decider's verdict) plus an interior
# decision: which pair of loops, if any, a tube joins through the cell (the interior
# test of Marching Cubes 33, Chernyaev 1995; Lewiner et al. 2003).
#
# The faces' loops fix the surface on the cell's boundary. The boundary of the cube
# minus the loops falls into patches of one sign each (corners joined along edges of
# one sign, or across a face whose decision joins them). By default each loop bounds
# its own disk. A tube between loops L1 and L2 is possible when both border the same
# patch M and their other sides A != C have the same sign s: the tube then joins A and
# C through the interior (an annulus bounded by L1 and L2 replaces their two disks).
# Every other decision of the interior is fixed by the boundary.
# --------------------------------------------------------------------------------------

#: The number of interior decisions a configuration can take (0: no tube; k: the k-th
#: candidate tube of :func:`tube_candidates`, at most 6 of them).
MAX_TUBES = 8


def ambiguous_faces(case: int) -> int:
    """Bit mask of the faces of :data:`CUBE_FACES` whose corners alternate in sign.

    Example:
        >>> ambiguous_faces(0b00001001), ambiguous_faces(0b01101001)
        (1, 63)
    """
    mask = 0
    for face, (_, _, ring) in enumerate(CUBE_FACES):
        bits = [(case >> c) & 1 for c in ring]
        if bits[0] == bits[2] != bits[1] == bits[3]:
            mask |= 1 << face
    return mask


@cache
def corner_patches(case: int, face_bits: int) -> tuple[int, ...]:
    """Patch label of each corner: corners on one connected boundary patch share it.

    Example:
        >>> corner_patches(0b00001001, 0), corner_patches(0b00001001, 1)
        ((0, 7, 7, 3, 7, 7, 7, 7), (3, 7, 7, 3, 7, 7, 7, 7))
    """
    parent = list(range(8))

    def find(a: int) -> int:
        while parent[a] != a:
            a = parent[a]
        return a

    for a, b in EDGE_CORNERS:
        if (case >> a) & 1 == (case >> b) & 1:
            parent[find(a)] = find(b)
    amb = ambiguous_faces(case)
    for face, (_, _, ring) in enumerate(CUBE_FACES):
        if (amb >> face) & 1:
            joined_sign = (face_bits >> face) & 1  # 1: inside corners joined
            first = 0 if (case >> ring[0]) & 1 == joined_sign else 1
            parent[find(ring[first])] = find(ring[first + 2])
    return tuple(find(c) for c in range(8))


def _loop_sides(case: int, loop: list[int], patches) -> tuple[int, int]:
    """``(inside patch, outside patch)`` of a loop, read at its first edge."""
    a, b = EDGE_CORNERS[loop[0]]
    inner, outer = (a, b) if (case >> a) & 1 else (b, a)
    return patches[inner], patches[outer]


@cache
def tube_candidates(case: int, face_bits: int) -> list[tuple[int, int, int, int, int]]:
    """The possible tubes: ``(loop_i, loop_j, sign, patch_a, patch_c)``, in a fixed order.

    ``sign`` is 1 when the tube joins inside patches ``patch_a`` and ``patch_c`` (the
    loops share their outside patch), 0 when it joins outside patches.

    Example:
        >>> tube_candidates(0b10000001, 0)  # corners 0 and 7: MC33 case 4
        [(0, 1, 1, 0, 7)]
    """
    loops = configuration_loops(case, face_bits)
    patches = corner_patches(case, face_bits)
    sides = [_loop_sides(case, loop, patches) for loop in loops]
    out = []
    for i in range(len(loops)):
        for j in range(i + 1, len(loops)):
            if sides[i][1] == sides[j][1]:
                out.append((i, j, 1, sides[i][0], sides[j][0]))
            if sides[i][0] == sides[j][0]:
                out.append((i, j, 0, sides[i][1], sides[j][1]))
    return out


@cache
def _triangulate_tube(first: tuple[int, ...], second: tuple[int, ...]):
    """Strip joining two loops into an annulus that keeps their orientation.

    The annulus keeps both loops as oriented boundaries, so it runs forward along
    ``first`` and backward along ``second``: a monotone path of chords
    ``(first[i], back[j])`` from ``(0, 0)`` to ``(n1, n2)`` (the same chord), one
    triangle per step. Every strip has a step along ``first`` followed by one along
    ``back``; rotating both loops (all rotations are tried) puts those two steps first.
    A chord is then visited twice only if the path reaches ``(1, n2)`` (the chord
    ``(1, 0)`` again), which is excluded.
    Among these strips, the one with the fewest chords between edges on a common cube
    face (a neighbour could draw such a chord too) and then the best worst triangle
    (on edge midpoints) is kept.
    """
    best_key, best = None, None
    for rot in range(len(first)):
        fwd = first[rot:] + first[:rot]
        for shift in range(len(second)):
            back = (second[::-1])[shift:] + (second[::-1])[:shift]
            found = _strip(fwd, back)
            if found is not None and (best_key is None or found[:2] < best_key):
                best_key, best = found[:2], list(found[2])
    return best_key[0], best


@cache
def _strip(fwd: tuple[int, ...], back: tuple[int, ...]):
    """``(same-face chords, -worst quality, triangles)`` of the best constrained strip."""
    n1, n2 = len(fwd), len(back)

    def allowed(i: int, j: int) -> bool:
        return (i, j) == (n1, n2) or j < n2 or i > 1

    def cost(i: int, j: int) -> int:
        if (i, j) == (n1, n2):
            return 0
        return _CHORD_COST[fwd[i % n1]][back[j % n2]]

    @cache
    def walk(i: int, j: int):
        if (i, j) == (n1, n2):
            return (0, -float("inf"), ())
        a, b = fwd[i % n1], back[j % n2]
        steps = [(i + 1, j, (a, fwd[(i + 1) % n1], b)), (i, j + 1, (a, back[(j + 1) % n2], b))]
        if (i, j) == (0, 0):
            steps = steps[:1]
        elif (i, j) == (1, 0):
            steps = steps[1:]
        result = None
        for ni, nj, tri in steps:
            if ni > n1 or nj > n2 or not allowed(ni, nj):
                continue
            rest = walk(ni, nj)
            if rest is None:
                continue
            key = (rest[0] + cost(ni, nj), max(rest[1], -_quality(*tri)))
            if result is None or key < result[:2]:
                result = (*key, (tri,) + rest[2])
        return result

    found = walk(0, 0)
    if found is None:
        return None
    return (found[0] + cost(0, 0), found[1], found[2])


def configuration_triangles(case: int, face_bits: int, tube: int):
    """Outward-wound triangles (edge triples) of one configuration, and its centre mask.

    A loop whose triangulation needs a chord on a low-side face (:func:`_chord_cost`;
    only nine-edge loops do) is fanned around a vertex :data:`CENTRE` (edge id 12) at
    the mean of the loop's vertices, as Lewiner et al. do. A tube that needs such a
    chord is not drawn (its loops get disks): 130 of the 424 tube configurations.

    Args:
        case: corner bits; face_bits: decisions of the ambiguous faces (see
            :func:`configuration_loops`); tube: 0 (every loop bounds a disk) or ``k``,
            the ``k``-th entry of :func:`tube_candidates` joins its two loops.

    Returns:
        ``(triangles, centre_mask)``: triangles as edge triples (``CENTRE`` for the
        centre vertex) and the bit mask of the edges the centre averages (0: none).

    Example:
        >>> len(configuration_triangles(0b10000001, 0, 0)[0])  # two corner triangles
        2
        >>> len(configuration_triangles(0b10000001, 0, 1)[0])  # a tube between them
        6
        >>> nine = (0, 8, 4, 2, 9, 5, 1, 10, 6)  # a nine-edge loop: fanned around the centre
        >>> configuration_triangles(22, 5, 0)[1] == sum(1 << e for e in nine)
        True
    """
    loops = configuration_loops(case, face_bits)
    tris: list[tuple[int, int, int]] = []
    joined: set[int] = set()
    if tube:
        i, j = tube_candidates(case, face_bits)[tube - 1][:2]
        cost, strip = _triangulate_tube(tuple(loops[i]), tuple(loops[j]))
        if cost < _LOW_CHORD:
            tris += strip
            joined = {i, j}
    centre_mask = 0
    for n, loop in enumerate(loops):
        if n in joined:
            continue
        cost, loop_tris = _triangulate_loop(tuple(loop))
        if cost >= _LOW_CHORD:
            loop_tris = [(loop[k], loop[(k + 1) % len(loop)], CENTRE) for k in range(len(loop))]
            centre_mask |= sum(1 << e for e in loop)
        tris += loop_tris
    return tris, centre_mask


def _face_ring_edges(axis: int) -> list[int]:
    """Corners ``r0..r3`` of the face (axis, side 0), whose edges along ``axis`` are the
    slice corners of the interior test."""
    return list(CUBE_FACES[2 * axis][2])


@cache
def tube_witness(case: int, face_bits: int) -> list[list[list[int]]]:
    """``[axis][diagonal][sign]`` -> tube id (0: none) that a slice witnesses.

    A slice perpendicular to ``axis`` whose bilinear saddle joins its diagonal
    ``(r0, r2)`` (``diagonal`` 0) or ``(r1, r3)`` (1) with sign ``sign`` (1 inside)
    proves that the patches of those two edges' ``sign`` ends are connected through
    the interior: the tube joining them, if it is a candidate.

    Example:
        >>> tube_witness(0b10000001, 0)[2]  # slices along z, corners 0 and 7 inside
        [[0, 1], [0, 0]]
    """
    patches = corner_patches(case, face_bits)
    cands = tube_candidates(case, face_bits)
    out = []
    for axis in range(3):
        ring = _face_ring_edges(axis)
        step = 4 >> axis
        per_diag = []
        for diag in range(2):
            per_sign = []
            for sign in range(2):
                ends = []
                for r in (ring[diag], ring[diag + 2]):
                    ok = [c for c in (r, r | step) if (case >> c) & 1 == sign]
                    ends.append(patches[ok[0]] if ok else None)
                tube = 0
                for k, (_, _, s, pa, pc) in enumerate(cands):
                    if s == sign and None not in ends and {pa, pc} == set(ends):
                        tube = k + 1
                per_sign.append(tube)
            per_diag.append(per_sign)
        out.append(per_diag)
    return out


class ConfigurationTables(NamedTuple):
    """Tensors of the asymptotic configurations (see :func:`configuration_tensors`)."""

    row: torch.Tensor
    triangles: torch.Tensor
    num_triangles: torch.Tensor
    centre_mask: torch.Tensor
    face_mask: torch.Tensor
    needs_interior: torch.Tensor
    witness: torch.Tensor
    face_rings: torch.Tensor


def _all_configurations():
    """Distinct configurations and the dense (case, face bits, tube) -> row map."""
    rows: dict[tuple, int] = {}
    triangles: list[list[tuple[int, int, int]]] = []
    centres: list[int] = []
    dense = [0] * (256 * 64 * MAX_TUBES)
    needs, witness = [False] * (256 * 64), [[[[0, 0], [0, 0]]] * 3] * (256 * 64)
    for case in range(256):
        amb = ambiguous_faces(case)
        for bits in range(64):
            fb = bits & amb
            n_tubes = len(tube_candidates(case, fb))
            needs[case * 64 + bits] = n_tubes > 0
            if n_tubes:
                witness[case * 64 + bits] = tube_witness(case, fb)
            for tube in range(MAX_TUBES):
                key = (case, fb, tube if tube <= n_tubes else 0)
                if key not in rows:
                    rows[key] = len(triangles)
                    tris, centre_mask = configuration_triangles(*key)
                    triangles.append(tris)
                    centres.append(centre_mask)
                dense[(case * 64 + bits) * MAX_TUBES + tube] = rows[key]
    return dense, triangles, centres, needs, witness


_CONFIG_CACHE: dict[torch.device, ConfigurationTables] = {}


def configuration_tensors(device: torch.device | str | None = None) -> ConfigurationTables:
    """The asymptotic configuration tables on ``device`` (generated once, cached).

    Returns:
        :class:`ConfigurationTables`: ``row (256 * 64 * MAX_TUBES,)`` long, the row of
        ``(case, face_bits, tube)`` at ``(case * 64 + face_bits) * MAX_TUBES + tube``
        (face bits of unambiguous faces ignored); ``triangles (R, T, 3)`` long edge
        triples (edge :data:`CENTRE` is the cell-centre vertex), -1 padded, and
        ``num_triangles (R,)``; ``centre_mask (R,)`` the edges whose vertices the
        centre vertex averages (0: no centre); ``face_mask (256,)`` the
        ambiguous faces of each case; ``needs_interior (256 * 64,)`` bool, whether
        ``(case, face_bits)`` has a candidate tube; ``witness (256 * 64, 3, 2, 2)`` long
        (see :func:`tube_witness`); ``face_rings (6, 4)`` the corners of each face in
        cyclic order.

    Example:
        >>> tables = configuration_tensors()
        >>> tables.triangles.shape[1:], int(tables.needs_interior.sum())
        (torch.Size([12, 3]), 4512)
    """
    device = torch.device("cpu" if device is None else device)
    if device not in _CONFIG_CACHE:
        dense, triangles, centres, needs, witness = _all_configurations()
        width = max(len(t) for t in triangles)
        tri = torch.full((len(triangles), width, 3), -1, dtype=torch.long)
        for r, tris in enumerate(triangles):
            if tris:
                tri[r, : len(tris)] = torch.tensor(tris, dtype=torch.long)
        tables = ConfigurationTables(
            torch.tensor(dense, dtype=torch.long),
            tri,
            torch.tensor([len(t) for t in triangles], dtype=torch.long),
            torch.tensor(centres, dtype=torch.long),
            torch.tensor([ambiguous_faces(c) for c in range(256)], dtype=torch.long),
            torch.tensor(needs, dtype=torch.bool),
            torch.tensor(witness, dtype=torch.long),
            torch.tensor([ring for _, _, ring in CUBE_FACES], dtype=torch.long),
        )
        _CONFIG_CACHE[device] = ConfigurationTables(*(t.to(device) for t in tables))
    return _CONFIG_CACHE[device]
