"""Contract entries of marching cubes, mesh files, mesh regularizers.

``ENTRIES`` join ``table.TABLE``; ``EXEMPT`` names have no geometry (result types,
exceptions, validators).

Laws:

- ``marching_cubes``: vertex positions are ``origin + spacing * index`` (law
  ``"length"`` on ``origin``/``spacing``, normals and weights unitless, faces and
  counts ``"index"``); scaling the field, ``iso`` and ``temperature`` by any ``s > 0``
  gives the same mesh (the ``[field]`` / ``[soft]`` variants, field law ``"length"``).
- Files and trimesh: every format writes enough digits (OBJ/OFF/ASCII PLY: 17 for
  float64, 9 otherwise) or the raw binary, so a save/load round trip is exact and
  the vertices come back scaled (law ``"length"``, ``rtol`` untouched).
- Regularizers (module docstring of ``regularizers.py``): the Laplacian vectors and
  the smoothing loss (a mean norm) scale as ``s``, the normal consistency (a mean
  ``1 - cos``) is invariant, the edge-length loss (a mean squared length deviation,
  ``target`` scaled too) scales as ``s^2``.
"""

from __future__ import annotations

import os
import tempfile

import torch

import torchgeo_cg.mesh as M
from tests.contract.spec import Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]

# ----------------------------------------------------------------------------- inputs

#: an octahedron (6 vertices, 8 triangles, closed), wound outward for its rest shape
OCTA = torch.tensor([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                     [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
#: a triangular prism (6 vertices): two triangles and three quads, padded with -1
PRISM = torch.tensor([[0, 2, 1, -1], [3, 4, 5, -1], [0, 1, 4, 3], [1, 2, 5, 4],
                      [2, 0, 3, 5]])
#: a crease on the prism's edge (0, 1), for the Mesh container through OBJ
CREASE = torch.tensor([[0, 1]])
#: a 4x4x4 mask whose far-corner rule keeps 8 of the 27 cells
MASK = torch.zeros(4, 4, 4, dtype=torch.bool)
MASK[2:, 2:, 1:3] = True

MC_OUT = ("length", "index", "unitless", "unitless", "index", "index")
MC_SAME = ("unitless", "index", "unitless", "unitless", "index", "index")


def _field(shape, g, dtype):
    """A volume whose surface crosses sample (0, 0, 0)'s edges: a tilted plane plus noise,
    so the NaN test hits a crossing edge and ambiguous cells occur."""
    b, x, y, z = shape
    ijk = torch.stack(torch.meshgrid(*(torch.arange(n, dtype=torch.float64) for n in (x, y, z)),
                                     indexing="ij"))
    tilt = (ijk * torch.tensor([0.7, 0.5, 0.3], dtype=torch.float64)[:, None, None, None]).sum(0)
    return tilt - 1.2 + 0.8 * torch.randn(shape, generator=g, dtype=torch.float64)


VOL = Arg("volume", (2, 4, 4, 4), _field, "unitless")
VOL_S = Arg("volume", (2, 4, 4, 4), _field, "length")
ISO = Arg("iso", (2,), "t01", "unitless")
ISO_S = Arg("iso", (2,), "t01", "length")
ORIGIN = Arg("origin", (2, 3))
SPACING = Arg("spacing", (2, 3), "positive")
BAD_VOL = ((4, 4), (2, 1, 4, 4), (2, 2, 4, 4, 4))
EMPTY_MC = ((0, 0), (1, 0), (2, 0), (3, 0))  # a batch of 0 volumes (every per-mesh argument)


def _mc(**kw):
    def call(volume, iso, origin, spacing):
        return tuple(M.marching_cubes(volume, iso, origin, spacing, **kw))

    return call


def _mc_split(volume, iso, origin, spacing):
    parts = M.marching_cubes(volume, iso, origin, spacing).split()
    return tuple(x for part in parts for x in part)


def _mc_soft(volume, iso, temperature):
    return tuple(M.marching_cubes(volume, iso, temperature=temperature))


def _mc_module(volume, iso, origin, spacing):
    return tuple(M.MarchingCubes(iso, origin, spacing, ambiguity="separate")(volume))


def _round_trip(suffix: str, faces=PRISM, binary: bool = True):
    """Save ``verts`` with the fixed ``faces`` in a temp file and load them back."""

    def call(verts):
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "mesh" + suffix)
            M.save_mesh(path, verts, faces, binary=binary)
            mesh = M.load_mesh(path, dtype=verts.dtype)
        return mesh.verts, mesh.faces

    return call


def _mesh_obj(verts, uvs, sharpness):
    """A :class:`Mesh` container (UVs, crease tags) through OBJ and back."""
    tags = M.SubdivisionTags(CREASE, sharpness, torch.zeros(0, dtype=torch.long),
                             sharpness[:0], torch.zeros(0, dtype=torch.long))
    mesh = M.Mesh(verts, PRISM, uvs, PRISM, tags, {"boundary": "edge_only"})
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "mesh.obj")
        M.save_mesh(path, mesh)
        back = M.load_mesh(path, dtype=verts.dtype)
    return back.verts, back.uvs, back.tags.crease_sharpness, back.faces, back.uv_faces


def _to_trimesh(faces):
    def call(verts):
        tm = M.to_trimesh(verts, faces)
        return torch.from_numpy(tm.vertices).to(verts.dtype), torch.from_numpy(tm.faces)

    return call


def _from_trimesh(faces):
    def call(verts):
        import trimesh

        tm = trimesh.Trimesh(vertices=verts.double().numpy(), faces=faces.numpy(),
                             process=False)
        mesh = M.from_trimesh(tm, dtype=verts.dtype)
        return mesh.verts, mesh.faces

    return call


#: the fixed faces index 6 vertices, so 0 vertices is a ValueError (index out of range);
#: the ``[points]`` / ``[*_points]`` variants (no faces) check 0 vertices instead
FIXED_FACES = None
#: a NaN sample is neither inside nor outside: ``ValueError`` naming ``volume``
NAN_SAMPLE = "raise"

VERTS = Arg("verts", (6, 3))
BAD_VERTS = ((6, 2), (2, 6, 3))
BVERTS = Arg("verts", (2, 6, 3))
BAD_BVERTS = ((2, 6, 2), (3,))

# ----------------------------------------------------------------------------- the table

ENTRIES: list[Entry] = [
    # --- marching cubes: positions follow origin and spacing, the field's unit is free
    Entry("mesh.marching_cubes", _mc(), (VOL, ISO, ORIGIN, SPACING), out=MC_OUT,
          empty=EMPTY_MC, bad=BAD_VOL, mixed=("follow", 0), nan=NAN_SAMPLE),
    Entry("mesh.marching_cubes[separate]", _mc(ambiguity="separate"),
          (VOL, ISO, ORIGIN, SPACING), out=MC_OUT, empty=EMPTY_MC, bad=BAD_VOL,
          mixed=("follow", 0), nan=NAN_SAMPLE),
    Entry("mesh.marching_cubes[field]", _mc(), (VOL_S, ISO_S, Arg("origin", (3,), "normal",
                                                                  "unitless"),
                                                Arg("spacing", (3,), "positive", "unitless")),
          out=MC_SAME, empty=((0, 0), (1, 0)), bad=BAD_VOL, mixed=("follow", 0),
          nan=NAN_SAMPLE),
    Entry("mesh.marching_cubes[mask]", _mc(mask=MASK), (VOL, ISO, ORIGIN, SPACING), out=MC_OUT,
          empty=EMPTY_MC, bad=BAD_VOL, mixed=("follow", 0), nan=NAN_SAMPLE),
    Entry("mesh.marching_cubes[soft]", _mc_soft,
          (VOL_S, ISO_S, Arg("temperature", (2,), "positive", "length")), out=MC_SAME,
          empty=EMPTY_MC[:3], bad=BAD_VOL, mixed=("follow", 0), nan=NAN_SAMPLE),
    Entry("mesh.marching_cubes[split]", _mc_split, (VOL, ISO, ORIGIN, SPACING), out=MC_OUT * 2,
          empty=None,  # split() of an empty batch is an empty list: no tensor to check
          bad=BAD_VOL, mixed=("follow", 0), nan=NAN_SAMPLE),
    Entry("mesh.MarchingCubes", _mc_module, (VOL, ISO, ORIGIN, SPACING), out=MC_OUT,
          empty=EMPTY_MC, bad=BAD_VOL, mixed="raise", nan=NAN_SAMPLE),
    # --- files: save with fixed faces, load back (exact in every format)
    Entry("mesh.save_mesh[obj]", _round_trip(".obj"), (VERTS,), out=("length", "index"),
          empty=FIXED_FACES, bad=BAD_VERTS, mixed=None),
    Entry("mesh.save_mesh[points]", _round_trip(".obj", PRISM[:0, :3]), (VERTS,),
          out=("length", "index"), bad=BAD_VERTS, mixed=None),
    Entry("mesh.save_mesh[off]", _round_trip(".off"), (VERTS,), out=("length", "index"),
          empty=FIXED_FACES, bad=BAD_VERTS, mixed=None),
    Entry("mesh.load_mesh[ply]", _round_trip(".ply"), (VERTS,), out=("length", "index"),
          empty=FIXED_FACES, bad=BAD_VERTS, mixed=None),
    Entry("mesh.load_mesh[ply_ascii]", _round_trip(".ply", binary=False), (VERTS,),
          out=("length", "index"), empty=FIXED_FACES, bad=BAD_VERTS, mixed=None),
    Entry("mesh.load_mesh[off_points]", _round_trip(".off", PRISM[:0, :3]), (VERTS,),
          out=("length", "index"), bad=BAD_VERTS, mixed=None),
    Entry("mesh.Mesh", _mesh_obj, (VERTS, Arg("uvs", (6, 2), "t01", "unitless"),
                                   Arg("sharpness", (1,), "positive", "unitless")),
          out=("length", "unitless", "unitless", "index", "index"), empty=FIXED_FACES,
          bad=BAD_VERTS,
          mixed=("follow", 0)),  # a file holds numbers: load_mesh(dtype=verts.dtype) decides
    Entry("mesh.load_mesh[ply_points]", _round_trip(".ply", PRISM[:0, :3]), (VERTS,),
          out=("length", "index"), bad=BAD_VERTS, mixed=None),
    # --- trimesh (float64 inside: exact for every dtype we have)
    Entry("mesh.to_trimesh", _to_trimesh(PRISM), (VERTS,), out=("length", "index"),
          empty=FIXED_FACES, bad=BAD_VERTS, mixed=None),
    Entry("mesh.to_trimesh[points]", _to_trimesh(PRISM[:0, :3]), (VERTS,),
          out=("length", "index"), bad=BAD_VERTS, mixed=None),
    Entry("mesh.from_trimesh", _from_trimesh(OCTA), (VERTS,), out=("length", "index"),
          empty=FIXED_FACES, mixed=None),
    Entry("mesh.from_trimesh[points]", _from_trimesh(OCTA[:0]), (VERTS,),
          out=("length", "index"), mixed=None),
    # --- regularizers
    Entry("mesh.mesh_laplacian", lambda v: M.mesh_laplacian(v, OCTA), (BVERTS,), empty=(0, 0),
          bad=BAD_BVERTS, mixed=None),
    Entry("mesh.mesh_laplacian[cotangent]", lambda v: M.mesh_laplacian(v, OCTA, "cotangent"),
          (BVERTS,), empty=(0, 0), bad=BAD_BVERTS, mixed=None),
    Entry("mesh.mesh_laplacian[polygons]", lambda v: M.mesh_laplacian(v, PRISM, "cotangent"),
          (BVERTS,), empty=(0, 0), bad=BAD_BVERTS, mixed=None),
    Entry("mesh.laplacian_smoothing_loss", lambda v: M.laplacian_smoothing_loss(v, OCTA),
          (BVERTS,), empty=(0, 0), bad=BAD_BVERTS, mixed=None),
    Entry("mesh.laplacian_smoothing_loss[cotangent]",
          lambda v: M.laplacian_smoothing_loss(v, PRISM, "cotangent"), (BVERTS,), empty=(0, 0),
          bad=BAD_BVERTS, mixed=None),
    Entry("mesh.normal_consistency_loss", lambda v: M.normal_consistency_loss(v, OCTA),
          (BVERTS,), out="unitless", empty=(0, 0), bad=BAD_BVERTS, mixed=None),
    Entry("mesh.normal_consistency_loss[polygons]",
          lambda v: M.normal_consistency_loss(v, PRISM), (BVERTS,), out="unitless",
          empty=(0, 0), bad=BAD_BVERTS, mixed=None),
    Entry("mesh.edge_length_loss", lambda v: M.edge_length_loss(v, OCTA), (BVERTS,),
          out="area", empty=(0, 0), bad=BAD_BVERTS, mixed=None),
    Entry("mesh.edge_length_loss[target]", lambda v, t: M.edge_length_loss(v, PRISM, t),
          (BVERTS, Arg("target", (), "positive")), out="area", empty=(0, 0), bad=BAD_BVERTS),
]

EXEMPT: dict[str, str] = {
    "mesh.check_mesh": "validator of a mesh for the queries (tests/mesh/test_faces.py)",
    "mesh.MarchingCubesResult": "result type (NamedTuple); split() is under contract in "
    "mesh.marching_cubes[split]",
    "mesh.MeshEdges": "result type (NamedTuple) of mesh_edges",
    "mesh.mesh_edges": "topology only: integer faces in, integer edges out, no float input "
    "and nothing to scale (tests/mesh/test_regularizers.py)",
}
