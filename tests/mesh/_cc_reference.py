"""An independent, loop-based dense reference of the Catmull-Clark rules, for tests only.

Written from the rules (OpenSubdiv Catmark; see torchgeo_cg.mesh.subdivision),
with dicts and Python loops, sharing no code with the library.
"""

from __future__ import annotations

import numpy as np


def reference_catmull_clark(verts, faces, boundary="edge_only"):
    """One level. ``verts`` (V, D) array, ``faces`` list of lists -> (verts (V1, D), faces)."""
    verts = np.asarray(verts, dtype=np.float64)
    V0, F0 = len(verts), len(faces)
    edge_faces: dict[tuple[int, int], list[int]] = {}
    for fi, face in enumerate(faces):
        for k, a in enumerate(face):
            b = face[(k + 1) % len(face)]
            edge_faces.setdefault((min(a, b), max(a, b)), []).append(fi)
    edges = sorted(edge_faces)
    edge_row = {e: V0 + F0 + i for i, e in enumerate(edges)}
    face_pts = np.array([verts[face].mean(axis=0) for face in faces])

    edge_pts = []
    for a, b in edges:
        fs = edge_faces[(a, b)]
        if len(fs) == 2:
            edge_pts.append((verts[a] + verts[b] + face_pts[fs[0]] + face_pts[fs[1]]) / 4)
        else:
            edge_pts.append((verts[a] + verts[b]) / 2)

    vert_edges: dict[int, list[tuple[int, int]]] = {v: [] for v in range(V0)}
    for e in edges:
        vert_edges[e[0]].append(e)
        vert_edges[e[1]].append(e)
    vert_faces: dict[int, list[int]] = {v: [] for v in range(V0)}
    for fi, face in enumerate(faces):
        for v in face:
            vert_faces[v].append(fi)

    vert_pts = []
    for v in range(V0):
        inc = vert_edges[v]
        sharp = [e for e in inc if len(edge_faces[e]) != 2]
        other = lambda e, v=v: e[1] if e[0] == v else e[0]  # noqa: E731
        if not inc or len(sharp) > 2:
            vert_pts.append(verts[v])
        elif len(sharp) == 2:
            if boundary == "edge_and_corner" and len(inc) == 2:
                vert_pts.append(verts[v])
            else:
                a, b = (other(e) for e in sharp)
                vert_pts.append(0.75 * verts[v] + 0.125 * (verts[a] + verts[b]))
        else:
            n = len(inc)
            mean_e = np.mean([verts[other(e)] for e in inc], axis=0)
            mean_f = np.mean([face_pts[f] for f in vert_faces[v]], axis=0)
            vert_pts.append(((n - 2) * verts[v] + mean_e + mean_f) / n)

    new_faces = []
    for fi, face in enumerate(faces):
        n = len(face)
        for k in range(n):
            a, b, p = face[k], face[(k + 1) % n], face[k - 1]
            new_faces.append(
                [a, edge_row[(min(a, b), max(a, b))], V0 + fi, edge_row[(min(a, p), max(a, p))]]
            )
    new_verts = np.concatenate(
        [np.array(vert_pts).reshape(V0, -1), face_pts.reshape(F0, -1),
         np.array(edge_pts).reshape(len(edges), -1)]
    )
    return new_verts, new_faces


def reference_levels(verts, faces, levels, boundary="edge_only"):
    for _ in range(levels):
        verts, faces = reference_catmull_clark(verts, faces, boundary)
    return verts, faces
