"""Generate ``rabbit.obj``: the low-poly, all-quad, rabbit-like control mesh we ship.

Run ``python -m torchgeo_cg.mesh.data._make_rabbit`` to rewrite the file. The mesh
is made from scratch (no scanned data): a cube-sphere body, a head extruded from a
2x2 patch, two ears extruded from the head, a tail and four feet. It is closed,
manifold, consistently wound (outward), and made of quads only, so Catmull-Clark
turns it into a smooth rabbit-like blob, as in report section 1.5.

This is an offline data script: plain Python loops over a few hundred faces are
fine here (the library code stays vectorized).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__: list[str] = []

HERE = Path(__file__).resolve().parent


def cube_sphere(n: int) -> tuple[np.ndarray, list[list[int]]]:
    """Quad cube with ``n x n`` cells per side projected onto the unit sphere, outward."""
    index: dict[tuple[int, int, int], int] = {}
    points: list[tuple[int, int, int]] = []

    def vid(p: tuple[int, int, int]) -> int:
        if p not in index:
            index[p] = len(points)
            points.append(p)
        return index[p]

    faces = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3  # (u, v, axis) right-handed
        for side in (0, n):
            for i in range(n):
                for j in range(n):
                    quad = []
                    for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = [0, 0, 0]
                        p[axis], p[u], p[v] = side, i + di, j + dj
                        quad.append(vid(tuple(p)))
                    faces.append(quad if side == n else quad[::-1])
    verts = np.asarray(points, dtype=np.float64) - n / 2.0
    verts /= np.linalg.norm(verts, axis=1, keepdims=True)
    return verts, faces


def extrude(verts, faces, patch, move):
    """Extrude the faces ``patch`` (indices into ``faces``) as one region.

    ``move(points) -> points`` places the copied patch vertices. Returns the new
    vertex array; ``faces`` is edited in place (patch faces re-pointed to the
    copies, side quads appended). Returns also the patch face indices.
    """
    patch_verts = sorted({v for f in patch for v in faces[f]})
    copy = {v: len(verts) + k for k, v in enumerate(patch_verts)}
    verts = np.vstack([verts, move(verts[patch_verts])])
    directed = [(f_v[k], f_v[(k + 1) % len(f_v)]) for f_v in (faces[f] for f in patch)
                for k in range(len(f_v))]
    boundary = [(a, b) for a, b in directed if (b, a) not in set(directed)]
    for f in patch:
        faces[f] = [copy[v] for v in faces[f]]
    for a, b in boundary:
        faces.append([a, b, copy[b], copy[a]])
    return verts


def _around(verts, faces, direction, count):
    """Indices of the ``count`` faces whose centroids point most along ``direction``."""
    direction = np.asarray(direction, dtype=np.float64)
    direction /= np.linalg.norm(direction)
    centroids = np.array([verts[f].mean(0) for f in faces])
    centroids /= np.linalg.norm(centroids, axis=1, keepdims=True)
    return list(np.argsort(-(centroids @ direction))[:count])


def _shift_scale(offset, scale):
    def move(p):
        centre = p.mean(0)
        return centre + np.asarray(offset) + (p - centre) * scale

    return move


def make_rabbit() -> tuple[np.ndarray, list[list[int]]]:
    """Build the rabbit control mesh: ``(verts (V,3) float64, faces list of quads)``."""
    verts, faces = cube_sphere(6)
    verts = verts * np.array([1.3, 0.8, 0.85])  # body: x forward, z up
    # head: a 2x2 patch at the front-top, extruded twice (neck, then skull)
    head = _around(verts, faces, (0.75, 0.0, 0.65), 4)
    verts = extrude(verts, faces, head, _shift_scale((0.3, 0.0, 0.35), 1.5))
    verts = extrude(verts, faces, head, _shift_scale((0.3, 0.0, 0.25), 1.5))
    verts = extrude(verts, faces, head, _shift_scale((0.3, 0.0, -0.05), 0.75))
    # ears: the two upper faces of the head's front patch, three segments each
    centroids = np.array([verts[faces[f]].mean(0) for f in head])
    upper = [head[k] for k in np.argsort(-centroids[:, 2])[:2]]
    for f in upper:
        side = np.sign(verts[faces[f]].mean(0)[1]) or 1.0
        for step in range(3):
            verts = extrude(
                verts, faces, [f],
                _shift_scale((-0.12, 0.08 * side, 0.42 - 0.05 * step), 0.85),
            )
    # tail: one face at the back, two short segments
    tail = _around(verts, faces, (-1.0, 0.0, 0.25), 1)
    verts = extrude(verts, faces, tail, _shift_scale((-0.18, 0.0, 0.06), 0.8))
    verts = extrude(verts, faces, tail, _shift_scale((-0.08, 0.0, 0.0), 0.5))
    # feet: four faces at the bottom
    for x, y in ((0.7, 0.45), (0.7, -0.45), (-0.7, 0.45), (-0.7, -0.45)):
        foot = _around(verts, faces, (x, y, -1.0), 1)
        verts = extrude(verts, faces, foot, _shift_scale((0.12, 0.0, -0.22), 0.9))
    # drop the vertices left inside extruded patches, keeping the order of the rest
    used = sorted({v for f in faces for v in f})
    new_index = {old: new for new, old in enumerate(used)}
    return verts[used], [[new_index[v] for v in f] for f in faces]


def main(path: Path = HERE / "rabbit.obj") -> None:
    """Write :func:`make_rabbit` to ``path`` as a Wavefront OBJ (the shipped ``rabbit.obj``)."""
    verts, faces = make_rabbit()
    with open(path, "w") as fh:
        fh.write("# torchgeo_cg low-poly rabbit control mesh (quads), made by _make_rabbit.py\n")
        fh.write("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in verts))
        fh.write("".join("f " + " ".join(str(v + 1) for v in f) + "\n" for f in faces))
    print(f"wrote {path}: {len(verts)} vertices, {len(faces)} quads")


if __name__ == "__main__":
    main()
