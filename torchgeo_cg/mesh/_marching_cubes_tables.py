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


def face_segments(case: int, face: int) -> list[tuple[int, int]]:
    """Oriented segments ``(edge_from, edge_to)`` that ``case`` draws on cube ``face``.

    Orientation: with ``n`` the face's outward normal, ``n x (to - from)`` points
    away from the inside corners, which makes the loops (and so the triangles)
    counter-clockwise seen from the outside. Ambiguous faces separate the inside
    corners.

    Example:
        >>> face_segments(0b00000001, 0)  # corner 0 inside, face x = 0
        [(4, 8)]
        >>> face_segments(0b00001001, 0)  # corners 0 and 3 inside: two segments
        [(4, 8), (5, 9)]
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
    elif len(crossing) == 4:  # ambiguous: cut off each inside corner on its own
        for i in range(4):
            if inside[i]:
                pairs.append((ring_edges[(i - 1) % 4], ring_edges[i], CORNER_OFFSETS[ring[i]]))
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


@cache
def _quality(a: int, b: int, c: int) -> float:
    pa, pb, pc = _midpoint(a), _midpoint(b), _midpoint(c)
    n = _cross(_sub(pb, pa), _sub(pc, pa))
    area2 = _dot(n, n) ** 0.5
    return area2 / (_dot(_sub(pb, pa), _sub(pb, pa)) + _dot(_sub(pc, pb), _sub(pc, pb))
                    + _dot(_sub(pa, pc), _sub(pa, pc)))


def _triangulate(loop: list[int]) -> list[tuple[int, int, int]]:
    """Max-min-quality triangulation of a loop, avoiding chords between same-face edges."""
    n = len(loop)

    def chord_ok(i: int, j: int) -> bool:
        return (j - i) % n in (1, n - 1) or not _SHARE_FACE[loop[i]][loop[j]]

    @cache
    def best(i: int, j: int):  # polygon loop[i..j], chord (i, j) already present
        if j - i < 2:
            return (float("inf"), ())
        result = (-1.0, None)
        for k in range(i + 1, j):
            if not (chord_ok(i, k) and chord_ok(k, j)):
                continue
            left, right = best(i, k), best(k, j)
            if left[1] is None or right[1] is None:
                continue
            q = min(_quality(loop[i], loop[k], loop[j]), left[0], right[0])
            if q > result[0]:
                result = (q, left[1] + ((loop[i], loop[k], loop[j]),) + right[1])
        return result

    quality, tris = best(0, n - 1)
    if tris is None:  # pragma: no cover - never happens for the cube (checked in tests)
        raise RuntimeError(f"marching cubes tables: loop {loop} cannot be triangulated")
    return list(tris)


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
        nxt: dict[int, int] = {}
        for face in range(6):
            for ea, eb in face_segments(case, face):
                if ea in nxt:  # pragma: no cover - guarded by the construction
                    raise RuntimeError(f"case {case}: edge {ea} leaves twice")
                nxt[ea] = eb
        tris: list[tuple[int, int, int]] = []
        todo = sorted(nxt)
        seen: set[int] = set()
        for start in todo:
            if start in seen:
                continue
            loop, e = [], start
            while e not in seen:
                seen.add(e)
                loop.append(e)
                e = nxt[e]
            tris += _triangulate(loop)
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
