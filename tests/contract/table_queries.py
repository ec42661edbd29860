"""Contract entries of mesh distance queries, SDF sampler, point clouds.

``ENTRIES`` join ``table.TABLE``; ``EXEMPT`` names have no geometry (result types,
exceptions, validators).

The mesh is a fixed octahedron topology (``OCTA``, captured as a constant); its
vertices are the float input (``args[0]``), jittered per seed so that no two faces
are symmetric and every query has one closest face.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np
import torch

import torchgeo_cg.points as P
import torchgeo_cg.sdf as S
from tests.contract.spec import Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]

#: Octahedron on the axes (0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z), faces counter-clockwise
#: seen from outside (one per octant).
OCTA = torch.tensor([[0, 2, 4], [1, 4, 2], [0, 4, 3], [1, 3, 4],
                     [0, 5, 2], [1, 2, 5], [0, 3, 5], [1, 5, 3]])
_AXES = torch.tensor([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                     dtype=torch.float64)


def _octahedron(shape, g, dtype):
    """``(*, 6, 3)`` octahedra: radii in [0.8, 1.2] per vertex, a small jitter, an offset."""
    radius = 0.8 + 0.4 * torch.rand(*shape[:-1], 1, generator=g, dtype=torch.float64)
    jitter = 0.05 * torch.randn(shape, generator=g, dtype=torch.float64)
    offset = 0.05 * torch.randn(*shape[:-2], 1, 3, generator=g, dtype=torch.float64)
    return _AXES * radius + jitter + offset


def _queries(shape, g, dtype):
    """Points around the octahedra, the first of each item near the centre (inside), so
    that winding numbers (0 outside up to rounding) have a scale to compare against."""
    p = 0.8 * torch.randn(shape, generator=g, dtype=torch.float64)
    p[..., 0, :] *= 0.1
    return p


VERTS = Arg("verts", (2, 6, 3), _octahedron)
QUERY = Arg("points", (2, 5, 3), _queries)
BAD_VERTS = ((2, 6, 2), (3,))


# Face ids are not compared: when the closest point lies on an edge or a vertex, every
# face sharing it is a closest face, and which one wins depends on rounding (it changes
# with the scale and the backend); distances and closest points are the same either way.


def _mesh_sdf(backend: str, sign: str = "auto"):
    def call(vertices, points):
        r = S.mesh_sdf(vertices, OCTA, points, sign=sign, return_closest=True, backend=backend)
        return r.sdf, r.closest_points

    return call


def _mesh_sdf_points_first(points, vertices):
    r = S.mesh_sdf(vertices, OCTA, points, sign="winding", return_closest=True, backend="torch")
    return r.sdf, r.closest_points


def _module(points, vertices):
    r = S.MeshSDF(vertices, OCTA, backend="torch")(points, return_closest=True)
    return r.sdf, r.closest_points


def _sampler(vertices, sigma):
    """Seeded samples of a mesh; the variances are lengths squared, so they come from a
    length argument (``sigma``) and scale with the mesh."""
    sampler = S.SDFSampler((vertices, OCTA), variances=tuple((sigma * sigma).tolist()),
                           generator=torch.Generator().manual_seed(0), backend="torch")
    return tuple(sampler.sample(12))


def _balanced(vertices, sigma):
    """Balanced and clamped: ``clamp`` is a length too (from ``sigma``)."""
    sampler = S.SDFSampler((vertices, OCTA), variances=tuple((sigma * sigma).tolist()),
                           balanced=True, clamp=float(3 * sigma[0]), backend="torch",
                           generator=torch.Generator().manual_seed(1))
    return tuple(sampler.sample(12))


def _surface(vertices):
    return S.sample_mesh_surface(vertices, OCTA, 5, torch.Generator().manual_seed(0))


def _save_load(points, sdf):
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "samples.npz")
        S.save_samples(path, S.SDFSamples(points, sdf))
        return tuple(S.load_samples(path, dtype=points.dtype))


def _numpy(x: torch.Tensor) -> np.ndarray:
    """numpy has no bfloat16: such a file would hold float32."""
    return (x.float() if x.dtype == torch.bfloat16 else x).numpy()


def _load(pos, neg):
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "deepsdf.npz")
        np.savez(path, pos=_numpy(pos), neg=_numpy(neg))
        dtype = pos.dtype if pos.dtype == torch.bfloat16 else None
        return tuple(S.load_samples(path, dtype=dtype))


A = Arg("a", (2, 6, 3))
B = Arg("b", (2, 7, 3))

ENTRIES: list[Entry] = [
    # --- mesh distance
    Entry("sdf.closest_point_on_triangle", S.closest_point_on_triangle,
          (QUERY, Arg("v0", (2, 1, 3)), Arg("v1", (2, 1, 3)), Arg("v2", (2, 1, 3))),
          out=("length", "index"), bad=((2, 5, 2), (3, 2))),
    # the mesh follows the dtype of the points (documented: a parameter of the query)
    Entry("sdf.winding_number",
          lambda v, p: S.winding_number(v, OCTA, p, backend="torch"), (VERTS, QUERY),
          out="unitless", empty=(1, -2), bad=BAD_VERTS, mixed=("follow", 1)),
    # vertices must be finite (documented ValueError): NaN points are the [winding] variant
    Entry("sdf.mesh_sdf", _mesh_sdf("torch"), (VERTS, QUERY), out=("length", "length"),
          empty=(1, -2), bad=BAD_VERTS, nan="raise", mixed=("follow", 1)),
    # "auto": the fastest installed engine (Warp's float32 BVH when the extra is installed)
    Entry("sdf.mesh_sdf[auto]", _mesh_sdf("auto"), (VERTS, QUERY),
          out=("length", "length"), empty=(1, -2), bad=BAD_VERTS, nan="raise",
          mixed=("follow", 1)),
    Entry("sdf.mesh_sdf[winding]", _mesh_sdf_points_first, (QUERY, VERTS),
          out=("length", "length"), bad=((2, 5, 2), (3,)), mixed=("follow", 0)),
    Entry("sdf.MeshSDF", _module, (QUERY, VERTS), out=("length", "length"),
          bad=((2, 5, 2), (3,)), mixed=("follow", 0)),
    # --- samples
    # vertices must be finite (documented ValueError); the empty input is an empty batch
    Entry("sdf.SDFSampler", _sampler, (VERTS, Arg("sigma", (2,), "small_positive")),
          out=("length", "length"), empty=(0, 0), bad=BAD_VERTS, nan="raise",
          mixed=None,  # sigma becomes Python floats (the variances)
          cross="sigma becomes Python floats (the variances)"),
    Entry("sdf.SDFSampler[balanced]", _balanced, (VERTS, Arg("sigma", (2,), "small_positive")),
          out=("length", "length"), empty=(0, 0), bad=BAD_VERTS, nan="raise",
          mixed=None,  # sigma becomes Python floats (the variances, the clamp)
          cross="sigma becomes Python floats (the variances, the clamp)"),
    # vertices must be finite (documented ValueError: the area CDF is undefined)
    Entry("sdf.sample_mesh_surface", _surface, (VERTS,), empty=(0, 0), bad=BAD_VERTS,
          nan="raise"),
    Entry("sdf.save_samples", _save_load, (Arg("points", (6, 3)), Arg("sdf", (6,))),
          out=("length", "length"), empty=((0, 0), (1, 0)), bad=((6, 2), (6,))),
    Entry("sdf.load_samples", _load, (Arg("pos", (3, 4)), Arg("neg", (4, 4))),
          out=("length", "length"), empty=((0, 0), (1, 0)), bad=((3, 5), (4,)),
          mixed="promote"),  # numpy's concatenation of pos and neg (documented)
    # --- point clouds
    Entry("points.knn", P.knn, (Arg("query", (2, 6, 3)), Arg("reference", (2, 7, 3))),
          out=("area", "index"), bad=((2, 7, 5), (3,)), bad_arg=1),
    Entry("points.knn[k3]", lambda q, r: P.knn(q, r, 3),
          (Arg("query", (2, 6, 2)), Arg("reference", (2, 7, 2))),
          out=("area", "index"), bad=((2, 7, 3), (2,)), bad_arg=1),
    # above BRUTE_FORCE_PAIRS (2 x 370 x 370 pairs): the grid search on the CPU
    Entry("points.knn[grid]", P.knn, (Arg("query", (2, 370, 3)), Arg("reference", (2, 370, 3))),
          out=("area", "index"), bad=((2, 370, 2), (3,)), bad_arg=1),
    # ragged: the lengths are constants sized for the batch of 2, so nothing to empty
    Entry("points.knn[ragged]",
          lambda q, r: P.knn(q, r, 3, torch.tensor([6, 2]), torch.tensor([7, 2])),
          (Arg("query", (2, 6, 3)), Arg("reference", (2, 7, 3))),
          out=("area", "index"), empty=None, bad=((2, 7, 5), (3,)), bad_arg=1),
    Entry("points.chamfer_distance[ragged]",
          lambda a, b: P.chamfer_distance(a, b, torch.tensor([6, 3]), torch.tensor([2, 7])),
          (A, B), out=("area",) * 3, empty=None, bad=((2, 7, 2), (3,)), bad_arg=1),
    Entry("points.chamfer_distance", P.chamfer_distance, (A, B), out=("area",) * 3,
          bad=((2, 7, 2), (3,)), bad_arg=1),
    Entry("points.chamfer_distance[unsquared]",
          lambda a, b: P.chamfer_distance(a, b, squared=False), (A, B), out=("length",) * 3,
          bad=((2, 7, 2), (3,)), bad_arg=1),
    Entry("points.chamfer_distance[none]",
          lambda a, b: P.chamfer_distance(a, b, reduction="none"), (A, B), out=("area",) * 3,
          bad=((2, 7, 2), (3,)), bad_arg=1),
    Entry("points.chamfer_distance[sum]",
          lambda a, b: P.chamfer_distance(a, b, reduction="sum"), (A, B), out=("area",) * 3,
          bad=((2, 7, 2), (3,)), bad_arg=1),
    Entry("points.ChamferDistance", lambda a, b: P.ChamferDistance(squared=False)(a, b),
          (A, B), out=("length",) * 3, bad=((2, 7, 2), (3,)), bad_arg=1),
]

EXEMPT: dict[str, str] = {
    "sdf.MeshSDFResult": "NamedTuple result type",
    "sdf.TriangleClosestPoint": "NamedTuple result type",
    "sdf.SDFSamples": "NamedTuple result type",
    "points.KNNResult": "NamedTuple result type",
    "points.ChamferResult": "NamedTuple result type",
    "sdf.is_watertight": "topology predicate on integer faces, no float input "
                         "(tests/sdf/test_mesh_distance.py)",
    "sdf.available_engines": "lists the installed engines, no tensor input "
                             "(tests/sdf/test_mesh_distance.py)",
}
