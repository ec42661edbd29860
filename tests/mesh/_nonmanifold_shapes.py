"""Meshes of the kinds of OpenSubdiv's eight non-manifold regression shapes, built here:
each kind is one mesh of several separate parts (as the regression shapes are), in the
xy plane with some relief in z so that no refined point is an average by accident.

``KINDS[name] = (verts, faces, scheme)``; the names are those of the regression shapes
whose kind they rebuild (``catmark_nonman_edges``, ``catmark_nonman_quadpole8/64/360``,
``catmark_val2_back2back``, ``catmark_val2_nonman``, ``loop_nonman_edges``,
``loop_val2_interior``).
"""

from __future__ import annotations

import math


class _Parts:
    """Parts appended one after the other: each gets its own vertices, shifted apart."""

    def __init__(self):
        self.verts: list[list[float]] = []
        self.faces: list[list[int]] = []
        self.count = 0

    def add(self, verts, faces):
        shift, self.count = 3.0 * self.count, self.count + 1
        o = len(self.verts)
        self.verts += [[x + shift, y, z] for x, y, z in verts]
        self.faces += [[o + i for i in f] for f in faces]
        return self


def _relief(i, j):
    return 0.05 * ((3 * i + 5 * j) % 4) + 0.02 * i * j


def _grid(n, m=None):
    """``(n + 1) x (m + 1)`` vertices, ``n x m`` quads, vertex ``j * (n + 1) + i``."""
    m = n if m is None else m
    verts = [[i / n, j / m, _relief(i, j)] for j in range(m + 1) for i in range(n + 1)]
    faces = [[j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1,
              (j + 1) * (n + 1) + i] for j in range(m) for i in range(n)]
    return verts, faces


def _triangulated(faces):
    return [t for a, b, c, d in faces for t in ([a, b, c], [a, c, d])]


def _polygon(n, radius=0.8, z=0.0):
    return [[radius * math.cos(2 * math.pi * k / n), radius * math.sin(2 * math.pi * k / n),
             z + 0.05 * (k % 3)] for k in range(n)]


def _merged(faces, merge):
    return [[merge.get(i, i) for i in f] for f in faces]


def catmark_nonman_edges():
    """Fins along a chain of edges; a fin face on an interior edge; the 3 x 3 grid with
    inner vertices merged (degenerate quads ``[a, a, b, c]``, ``[a, a, b, b]``,
    ``[a, a, a, b]``, ``[a, b, a, c]``, ``[a, a, a, a]``); the centre quad reversed;
    2-gons and ``[a, a, b]`` faces on an edge; a tube whose winding flips half way."""
    parts = _Parts()
    v, f = _grid(4, 2)  # two fins above and below the middle row of edges
    top = [[i / 4, 0.5, 0.4 + 0.03 * i] for i in range(5)]
    bottom = [[i / 4, 0.5, -0.4 - 0.02 * i] for i in range(5)]
    fins = [[5 + i, 6 + i, 16 + i, 15 + i] for i in range(4)]
    fins += [[6 + i, 5 + i, 20 + i, 21 + i] for i in range(4)]
    parts.add(v + top + bottom, f + fins)
    v, f = _grid(3)
    parts.add(v + [[0.5, 0.4, -0.5]], f + [[5, 6, 16]])  # a fin on an interior edge
    for merge in ({6: 5}, {6: 5, 9: 10}, {6: 5, 10: 5}, {10: 5}, {6: 5, 10: 5, 9: 5}):
        parts.add(v, _merged(f, merge))
    parts.add(v, f[:4] + [[9, 10, 6, 5]] + f[5:])  # the centre quad reversed
    v2, f2 = _grid(2)
    parts.add(v2, f2 + [[1, 0]])  # a 2-gon on a boundary edge, wound along it
    parts.add(v2, f2 + [[4, 1]])  # ... on an interior edge
    parts.add(v2, f2 + [[1, 0, 0]])  # [a, b, b] on a boundary edge
    parts.add(v2, f2 + [[5, 5, 4]])  # [a, a, b] on an interior edge
    parts.add(v2, f2 + [[0, 8]])  # a 2-gon across the grid
    n = 8
    ring = [[0.5 * math.cos(2 * math.pi * k / n), 0.5 * math.sin(2 * math.pi * k / n),
             z + 0.03 * k] for z in (0.0, 0.6) for k in range(n)]
    tube = [[k, (k + 1) % n, n + (k + 1) % n, n + k] for k in range(n // 2)]
    tube += [[(k + 1) % n, k, n + k, n + (k + 1) % n] for k in range(n // 2, n)]
    parts.add(ring, tube)
    return parts.verts, parts.faces, "catmark"


def catmark_nonman_quadpole(n):
    """A cylinder of ``n`` quads closed at both ends by ``n`` degenerate quads
    ``(r_k+1, r_k, P, P)`` around a pole ``P``."""
    ring = [[math.cos(2 * math.pi * k / n), math.sin(2 * math.pi * k / n),
             z + 0.1 * math.cos(6 * math.pi * k / n)] for z in (0.0, 1.0) for k in range(n)]
    verts = ring + [[0.05, 0, -0.5], [0, 0.05, 1.5]]
    bottom, top = 2 * n, 2 * n + 1
    faces = [[k, (k + 1) % n, n + (k + 1) % n, n + k] for k in range(n)]
    faces += [[(k + 1) % n, k, bottom, bottom] for k in range(n)]
    faces += [[n + k, n + (k + 1) % n, top, top] for k in range(n)]
    return verts, faces, "catmark"


def catmark_val2_back2back():
    """A triangle, a quad, a pentagon and a hexagon, each with its back face."""
    parts = _Parts()
    for k in (3, 4, 5, 6):
        parts.add(_polygon(k), [list(range(k)), list(range(k))[::-1]])
    return parts.verts, parts.faces, "catmark"


def catmark_val2_nonman():
    """Back-to-back quads and triangles with faces hanging on their edges and corners."""
    parts = _Parts()
    sq = [[0, 0, 0], [1, 0, 0.1], [1, 1, 0], [0, 1, 0.05]]
    hang = [[0, -0.3, 0.4], [1, -0.3, 0.45], [0, -0.35, -0.4], [1, -0.3, -0.35]]
    parts.add(sq + hang, [[0, 1, 2, 3], [3, 2, 1, 0], [0, 1, 5, 4], [1, 0, 6, 7]])
    tri = [[0, 0, 0], [1, 0, 0.1], [0.5, 1, 0]]
    parts.add(tri + hang, [[0, 1, 2], [2, 1, 0], [0, 1, 4, 3], [1, 0, 5, 6]])
    low = [[0, -0.4, -0.3], [1, -0.45, -0.3]]
    parts.add(sq + low, [[0, 1, 2, 3], [3, 2, 1, 0], [4, 5, 0]])
    parts.add(sq + low, [[0, 1, 2, 3], [3, 2, 1, 0], [4, 5, 0], [4, 5, 1]])
    return parts.verts, parts.faces, "catmark"


def _hex_patch():
    """A triangulated patch of 12 vertices with 3 raised inner vertices (4, 5, 8)."""
    rows = [(-1 / 3, 0, 1 / 3), (-1 / 2, -1 / 6, 1 / 6, 1 / 2), (-1 / 3, 0, 1 / 3), (-1 / 6, 1 / 6)]
    ys = (-0.43, -0.14, 0.14, 0.43)
    verts = [[x, y, 0.0] for xs, y in zip(rows, ys) for x in xs]
    for i in (4, 5, 8):
        verts[i][2] = -0.25
    faces = [[0, 1, 4], [1, 2, 5], [0, 4, 3], [1, 5, 4], [2, 6, 5], [3, 4, 7], [4, 5, 8],
             [5, 6, 9], [4, 8, 7], [5, 9, 8], [7, 8, 10], [8, 9, 11], [8, 11, 10]]
    return verts, faces


def loop_nonman_edges():
    """A third face on an interior edge; fins along a strip; eight faces on one edge;
    ``[a, a, b]`` along an edge, ``[a, b, b]`` and ``[a, a, a]`` inside; reversed faces;
    ``[a, b, b]`` on a boundary edge and ``[a, a, b]`` on an interior one."""
    parts = _Parts()
    hv, hf = _hex_patch()
    parts.add(hv + [[0, -0.15, -0.6]], hf + [[12, 4, 5]])
    v, f = _grid(4, 1)  # a strip with a fin above and below each of its middle edges
    tri = _triangulated(f)
    up = [[i / 4, 0.5, 0.3] for i in range(5)]
    down = [[i / 4 + 0.05, 0.5, -0.3] for i in range(5)]
    fins = [[5 + i, 6 + i, 10 + i] for i in range(4)]
    fins += [[6 + i, 5 + i, 15 + i] for i in range(4)]
    parts.add(v + [[i / 4, 1.5, 0.1 * i] for i in range(5)] + up + down, tri + fins)
    book = [[0, 0, 0.25], [0, 0, -0.25]]
    book += [[0.5 * math.cos(2 * math.pi * k / 8), 0.5 * math.sin(2 * math.pi * k / 8), 0.02 * k]
             for k in range(8)]
    parts.add(book, [[0, 1, 2 + k] if k < 4 else [1, 0, 2 + k] for k in range(8)])
    strip = [[0, 0, 0], [0.3, 0, -0.2], [0.6, 0, -0.2], [0.9, 0, 0], [0.15, 0.3, 0],
             [0.45, 0.3, -0.2], [0.75, 0.3, 0]]
    parts.add(strip, [[0, 1, 4], [1, 2, 5], [2, 3, 6], [1, 5, 4], [2, 6, 5], [2, 2, 5]])
    parts.add(hv, hf + [[4, 5, 5]])
    parts.add(hv, hf + [[4, 4, 4]])
    parts.add(hv, hf[:6] + [[8, 5, 4]] + hf[7:])  # one interior face reversed
    zig = [[0.25 * i, 0, -0.1 * (i % 2)] for i in range(5)]
    zig += [[0.125 + 0.25 * i, 0.2, -0.1 * (i % 2 == 0)] for i in range(4)]
    parts.add(zig, [[0, 1, 5], [1, 6, 5], [6, 2, 1], [6, 7, 2], [7, 3, 2], [3, 8, 7],
                    [3, 4, 8]])  # the three middle faces reversed
    v2, f2 = _grid(2)
    parts.add(v2, _triangulated(f2) + [[1, 0, 0]])  # [a, b, b] on a boundary edge
    parts.add(v2, _triangulated(f2) + [[4, 4, 1]])  # [a, a, b] on an interior edge
    return parts.verts, parts.faces, "loop"


def loop_val2_interior():
    """Two triangles on the same three vertices (a pillow), alone, with triangles at
    one corner and with triangles on one edge."""
    parts = _Parts()
    tri = [[0, 0, 0], [1, 0, 0.1], [0.5, 0.87, 0]]
    parts.add(tri, [[0, 1, 2], [1, 0, 2]])
    parts.add(tri + [[0, 1.5, 0.6], [1, 1.5, 0.6], [0, 1.6, -0.6], [1, 1.5, -0.6]],
              [[0, 1, 2], [1, 0, 2], [2, 3, 4], [2, 6, 5]])
    parts.add(tri + [[0.5, -0.5, 0.6], [0.5, -0.55, -0.6]],
              [[0, 1, 2], [1, 0, 2], [3, 1, 0], [4, 0, 1]])
    return parts.verts, parts.faces, "loop"


KINDS = {
    "catmark_nonman_edges": catmark_nonman_edges(),
    "catmark_nonman_quadpole8": catmark_nonman_quadpole(8),
    "catmark_nonman_quadpole64": catmark_nonman_quadpole(64),
    "catmark_nonman_quadpole360": catmark_nonman_quadpole(360),
    "catmark_val2_back2back": catmark_val2_back2back(),
    "catmark_val2_nonman": catmark_val2_nonman(),
    "loop_nonman_edges": loop_nonman_edges(),
    "loop_val2_interior": loop_val2_interior(),
}
