"""Contract entries of subdivision, faces, limit and face-varying.

``ENTRIES`` join ``table.TABLE``; ``EXEMPT`` names have no geometry (result types,
exceptions, validators).

Subdivision is linear in the control data, so every entry gives the vertex positions
(or UVs) as ``args[0]`` (law ``"length"``) with the topology (faces, tags' indices,
boundary mode) captured in the ``call`` as constants; crease and corner sharpness are
float inputs that do not scale (``"unitless"``). Operators are built inside the call
with the dtype of the data, as a user builds them once for their data.
"""

from __future__ import annotations

import torch

import torchgeo_cg.mesh as M
from tests.contract.spec import Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]

# ----------------------------------------------------------------------------- topologies

CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
GRID_F = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]]  # open 3 x 3 vertices
NGON_F = [[0, 1, 2, 3], [3, 2, 4], [1, 5, 6, 4, 2]]  # quad, triangle, pentagon (open)
OCTA_F = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5],
          [0, 3, 5]]
FAN_F = [[0, 1, 2], [0, 2, 3], [0, 3, 4]]  # open triangle fan
SEAM_F, SEAM_UV = [[0, 1, 4, 3], [1, 2, 5, 4]], [[0, 1, 2, 3], [4, 5, 6, 7]]  # a UV seam
TRI_SEAM_F, TRI_SEAM_UV = [[0, 1, 2], [0, 2, 3]], [[0, 1, 2], [3, 4, 5]]
CUBE_CREASES = torch.tensor([[0, 1], [1, 3], [3, 2]])  # a chain of three cube edges
OCTA_CREASES = torch.tensor([[0, 2], [2, 1]])


def _near(corners: list[list[float]]):
    """Generator of ``corners`` plus small noise: well-conditioned control meshes (limit
    normals of random points would be ill-conditioned, not a property of the library)."""
    base = torch.tensor(corners, dtype=torch.float64)

    def gen(shape, g, dtype):
        noise = 0.1 * torch.randn(shape, generator=g, dtype=torch.float64)
        return base[:, : shape[-1]] + noise

    return gen


CUBE_V = _near([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
GRID_V = _near([[x, y, 0.3 * (x * y)] for y in (-1.0, 0.0, 1.0) for x in (-1.0, 0.0, 1.0)])
NGON_V = _near([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [1, 2, 0.2], [2, 0, 0.1],
                [2.5, 1.2, 0.3]])
OCTA_V = _near([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
FAN_V = _near([[0, 0, 0], [1, 0, 0], [0.7, 0.7, 0.1], [0, 1, 0], [-0.7, 0.7, 0.2]])
SEAM_UV_V = _near([[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [3, 0], [3, 1], [2, 1]])
TRI_UV_V = _near([[0, 0], [1, 0], [1, 1], [2, 0], [3, 1], [2, 1]])


def _sharpness(shape, g, dtype):
    """Semi-sharp crease/corner values in ``[0.3, 2.8]`` (decaying over the levels)."""
    return 0.3 + 2.5 * torch.rand(shape, generator=g, dtype=torch.float64)


def _buffer(v: torch.Tensor, rows: int) -> torch.Tensor:
    """A fresh ``(*, rows, D)`` output buffer for data ``v`` (the ``out=`` entries), NaN
    where it is floating, so that a result not written into it fails the laws."""
    fill = float("nan") if v.dtype.is_floating_point else 0
    return torch.full((*v.shape[:-2], rows, v.shape[-1]), fill, dtype=v.dtype, device=v.device)


def _wdtype(v: torch.Tensor) -> dict:
    """Operator weights in the data's dtype (``None``: the default, for integer data)."""
    return {"dtype": v.dtype if v.is_floating_point() else None}


def _frames(limit) -> tuple[torch.Tensor, ...]:
    return tuple(x for x in limit if x is not None)


def _tags(creases=None, crease_s=None, corners=None, corner_s=None, holes=None):
    empty = M.SubdivisionTags.empty(torch.float64)
    return empty._replace(
        **{k: v for k, v in (("creases", creases), ("crease_sharpness", crease_s),
                             ("corners", corners), ("corner_sharpness", corner_s),
                             ("holes", holes)) if v is not None})


def _faces(shape, g, dtype):
    """Valid padded polygons ``(F, K)``: 3 to ``K`` distinct vertices of ``0 .. 2K - 1`` per
    face, trailing ``-1`` padding (integer values in a float tensor, see :func:`_on_faces`)."""
    K = shape[-1]
    verts = torch.rand(*shape[:-1], 2 * K, generator=g).argsort(-1)[..., :K]
    size = torch.randint(3, K + 1, shape[:-1], generator=g)
    return torch.where(torch.arange(K) >= size[..., None], -1, verts).double()


def _long_same_layout(x: torch.Tensor) -> torch.Tensor:
    """``x.long()`` with the strides of ``x`` (strided and expanded layouts are kept)."""
    n = x.untyped_storage().nbytes() // x.element_size()
    whole = torch.empty(0, dtype=x.dtype).set_(x.untyped_storage(), 0, (n,), (1,))
    return whole.long().as_strided(x.shape, x.stride(), x.storage_offset())


def _on_faces(fn):
    """Call a topology function on integer faces and return its integer result as floats.

    The harness casts every input to the float dtype under test, so float-coded faces go
    in as a long tensor of the same layout (integer faces as they are), and the result
    comes back in the input's float dtype (float32 for integer faces) for the clauses to
    compare: empty faces, wrong ranks, strided and expanded faces, no mutation.
    """
    def call(faces: torch.Tensor) -> torch.Tensor:
        index = _long_same_layout(faces) if faces.is_floating_point() else faces
        out = fn(index)
        return out.to(faces.dtype if faces.is_floating_point() else torch.float32)

    return call


FACES = Arg("faces", (5, 5), _faces, "index")
BADF = ((5,), (2, 5, 5))  # not (F, K)
VERTS8 = Arg("verts", (2, 8, 3), CUBE_V)
BADV = ((3,),)  # not (*, V, D)
BADV8 = ((2, 7, 3), (3,))  # an operator fixes V
POS3 = ("length", "length", "length", "unitless")  # positions, tangents, normals

_CC_CUBE = M.catmull_clark_operator(CUBE_F, 8, dtype=torch.float64)
_CC_GRID = M.catmull_clark_operator(GRID_F, 9, dtype=torch.float64,
                                    options=M.SchemeOptions(boundary="edge_and_corner"))
_LOOP_OCTA = M.loop_operator(OCTA_F, 6, dtype=torch.float64)
_CC_INF = M.catmull_clark_operator(
    CUBE_F, 8, dtype=torch.float64,
    tags=_tags(CUBE_CREASES, torch.full((3,), 10.0, dtype=torch.float64)))

# ----------------------------------------------------------------------------- the entries

ENTRIES: list[Entry] = [
    # --- padded faces: topology only (index law); a NaN index has no meaning (no NaN
    # clause: the integer faces cannot carry one)
    Entry("mesh.pad_faces", _on_faces(M.pad_faces), (FACES,), out="index", empty=(0, 0),
          bad=BADF, nan="skip", int_ok=True, mixed=None),
    Entry("mesh.face_sizes", _on_faces(M.face_sizes), (FACES,), out="index", empty=(0, 0),
          bad=BADF, nan="skip", int_ok=True, mixed=None),
    Entry("mesh.triangulate_faces", _on_faces(M.triangulate_faces), (FACES,), out="index",
          empty=(0, 0), bad=BADF, nan="skip", int_ok=True, mixed=None),
    Entry("mesh.unpad_faces", _on_faces(lambda f: M.pad_faces(M.unpad_faces(f))), (FACES,),
          out="index", empty=(0, 0), bad=BADF, nan="skip", int_ok=True, mixed=None),
    # --- Catmull-Clark
    Entry("mesh.catmull_clark", lambda v: M.catmull_clark(v, CUBE_F)[0], (VERTS8,),
          empty=((0, 0), (0, -1)), bad=BADV),
    Entry("mesh.catmull_clark[levels2]", lambda v: M.catmull_clark(v, CUBE_F, levels=2)[0],
          (VERTS8,), empty=(0, 0), bad=BADV),
    Entry("mesh.catmull_clark[boundary]",
          lambda v: M.catmull_clark(v, GRID_F,
                                    options=M.SchemeOptions(boundary="edge_and_corner"))[0],
          (Arg("verts", (2, 9, 3), GRID_V),), empty=(0, 0), bad=BADV),
    Entry("mesh.catmull_clark[none]", lambda v: M.catmull_clark(v, GRID_F,
                                                                options=M.SchemeOptions(boundary="none"))[0],
          (Arg("verts", (2, 9, 3), GRID_V),), empty=(0, 0), bad=BADV),
    Entry("mesh.catmull_clark[ngon]",
          lambda v: M.catmull_clark(v, NGON_F, levels=2,
                                    options=M.SchemeOptions(triangle_rule="smooth"))[0],
          (Arg("verts", (2, 7, 3), NGON_V),), empty=(0, 0), bad=BADV),
    Entry("mesh.catmull_clark[no_faces]", lambda v: M.catmull_clark(v, [])[0],
          (Arg("verts", (2, 4, 3)),), empty=((0, -2),), bad=BADV),  # V = 0: nothing to refine
    Entry("mesh.CatmullClark",
          lambda v: M.CatmullClark(CUBE_F, 8, levels=2, **_wdtype(v))(v), (VERTS8,),
          empty=(0, 0), bad=BADV8),
    Entry("mesh.catmull_clark_operator",
          lambda v: M.apply_operator(M.catmull_clark_operator(NGON_F, 7, **_wdtype(v)), v),
          (Arg("verts", (2, 7, 3), NGON_V),), empty=(0, 0), bad=((2, 6, 3), (3,))),
    Entry("mesh.apply_operator", lambda v: M.apply_operator(_CC_CUBE, v), (VERTS8,),
          empty=((0, 0), (0, -1)), bad=BADV8),
    Entry("mesh.apply_operator[batch0d]", lambda v: M.apply_operator(_CC_CUBE, v),
          (Arg("verts", (8, 2), CUBE_V),), empty=(0, -1), bad=((7, 2), (2,))),
    Entry("mesh.apply_operator[out]",
          lambda v: M.apply_operator(_CC_CUBE, v, out=_buffer(v, _CC_CUBE.num_vertices_out)),
          (VERTS8,), empty=((0, 0), (0, -1)), bad=BADV8),
    Entry("mesh.CatmullClark[out]",
          lambda v: M.CatmullClark(CUBE_F, 8, levels=2, **_wdtype(v))(v, out=_buffer(v, 98)),
          (VERTS8,), empty=(0, 0), bad=BADV8),
    Entry("mesh.LoopSubdivision[out]",
          lambda v: M.LoopSubdivision(OCTA_F, 6, levels=1, **_wdtype(v))(v, out=_buffer(v, 18)),
          (Arg("verts", (2, 6, 3), OCTA_V),), empty=(0, 0), bad=((2, 5, 3), (3,))),
    Entry("mesh.apply_stencils", lambda x: M.apply_stencils(_CC_CUBE.stencils, x),
          (Arg("x", (2, 8, 3), CUBE_V),), empty=((0, 0), (0, -1)), bad=((2, 7, 3), (3,))),
    Entry("mesh.limit_positions", lambda v: M.limit_positions(_CC_CUBE, v), (VERTS8,),
          empty=(0, 0), bad=BADV8),
    Entry("mesh.limit_positions[boundary]", lambda v: M.limit_positions(_CC_GRID, v),
          (Arg("verts", (2, 9, 3), GRID_V),), empty=(0, 0), bad=((2, 8, 3),)),
    Entry("mesh.limit_positions[loop]", lambda v: M.limit_positions(_LOOP_OCTA, v),
          (Arg("verts", (2, 6, 3), OCTA_V),), empty=(0, 0), bad=((2, 5, 3),)),
    # --- Loop
    Entry("mesh.loop_subdivide", lambda v: M.loop_subdivide(v, OCTA_F)[0],
          (Arg("verts", (2, 6, 3), OCTA_V),), empty=((0, 0), (0, -1)), bad=BADV),
    Entry("mesh.loop_subdivide[boundary]",
          lambda v: M.loop_subdivide(v, FAN_F, levels=2,
                                     options=M.SchemeOptions(boundary="edge_and_corner"))[0],
          (Arg("verts", (2, 5, 3), FAN_V),), empty=(0, 0), bad=BADV),
    Entry("mesh.loop_subdivide[no_faces]", lambda v: M.loop_subdivide(v, [])[0],
          (Arg("verts", (2, 4, 3)),), empty=((0, -2),), bad=BADV),
    Entry("mesh.loop_operator",
          lambda v: M.apply_operator(M.loop_operator(FAN_F, 5, **_wdtype(v)), v),
          (Arg("verts", (2, 5, 3), FAN_V),), empty=(0, 0), bad=((2, 4, 3), (3,))),
    Entry("mesh.LoopSubdivision",
          lambda v: M.LoopSubdivision(OCTA_F, 6, levels=2, **_wdtype(v))(v),
          (Arg("verts", (2, 6, 3), OCTA_V),), empty=(0, 0), bad=((2, 5, 3), (3,))),
    # --- bilinear
    Entry("mesh.bilinear_operator",
          lambda v: M.apply_operator(M.bilinear_operator(NGON_F, 7, **_wdtype(v)), v),
          (Arg("verts", (2, 7, 3), NGON_V),), empty=(0, 0), bad=((2, 6, 3), (3,))),
    # --- tags: sharpness does not scale with the positions; it follows their dtype
    Entry("mesh.SubdivisionTags",
          lambda v, s: M.catmull_clark(v, CUBE_F, levels=2,
                                       tags=_tags(CUBE_CREASES, s))[0],
          (VERTS8, Arg("crease_sharpness", (3,), _sharpness, "unitless")),
          empty=(0, 0), bad=BADV, mixed=("follow", 0)),
    Entry("mesh.SubdivisionTags[corners]",
          lambda v, s: M.catmull_clark(v, CUBE_F, levels=2,
                                       options=M.SchemeOptions(crease_method="chaikin"),
                                       tags=_tags(CUBE_CREASES, s[:3], torch.tensor([4, 7]),
                                                  s[3:]))[0],
          (VERTS8, Arg("sharpness", (5,), _sharpness, "unitless")),
          empty=(0, 0), bad=BADV, mixed=("follow", 0)),
    Entry("mesh.SubdivisionTags[loop]",
          lambda v, s: M.loop_subdivide(v, OCTA_F, levels=2,
                                        options=M.SchemeOptions(crease_method="chaikin"),
                                        tags=_tags(OCTA_CREASES, s))[0],
          (Arg("verts", (2, 6, 3), OCTA_V), Arg("crease_sharpness", (2,), _sharpness,
                                                 "unitless")),
          empty=(0, 0), bad=BADV, mixed=("follow", 0)),
    Entry("mesh.SubdivisionTags[holes]",
          lambda v: M.catmull_clark(v, CUBE_F, tags=_tags(holes=torch.tensor([1])))[0],
          (VERTS8,), empty=(0, 0), bad=BADV),
    # --- limit frames: positions and tangents are lengths, normals unit vectors
    Entry("mesh.limit_frames", lambda v: _frames(M.limit_frames(_CC_CUBE, v)), (VERTS8,),
          out=POS3, empty=(0, 0), bad=BADV8),
    Entry("mesh.limit_frames[crease]", lambda v: _frames(M.limit_frames(_CC_INF, v)), (VERTS8,),
          out=POS3, empty=(0, 0), bad=BADV8),
    Entry("mesh.limit_frames[boundary]", lambda v: _frames(M.limit_frames(_CC_GRID, v)),
          (Arg("verts", (2, 9, 3), GRID_V),), out=POS3, empty=(0, 0), bad=((2, 8, 3),)),
    Entry("mesh.limit_frames[loop]", lambda v: _frames(M.limit_frames(_LOOP_OCTA, v)),
          (Arg("verts", (2, 6, 3), OCTA_V),), out=POS3, empty=(0, 0), bad=((2, 5, 3),)),
    Entry("mesh.limit_frames[2d]", lambda v: _frames(M.limit_frames(_CC_GRID, v)),
          (Arg("verts", (2, 9, 2), GRID_V),), out=POS3[:3], empty=(0, 0), bad=((2, 8, 2),)),
    # --- face-varying values (UVs): linear like positions
    Entry("mesh.face_varying_subdivide",
          lambda uv: M.face_varying_subdivide(uv, SEAM_F, SEAM_UV, 6, levels=2)[0],
          (Arg("uvs", (2, 8, 2), SEAM_UV_V),), empty=((0, 0), (0, -1)), bad=((3,),)),
    Entry("mesh.face_varying_subdivide[none]",
          lambda uv: M.face_varying_subdivide(uv, SEAM_F, SEAM_UV, 6,
                                              options=M.SchemeOptions(fvar_interpolation="none"))[0],
          (Arg("uvs", (2, 8, 2), SEAM_UV_V),), empty=(0, 0), bad=((3,),)),
    Entry("mesh.face_varying_subdivide[boundaries]",
          lambda uv: M.face_varying_subdivide(uv, SEAM_F, SEAM_UV, 6,
                                              options=M.SchemeOptions(fvar_interpolation="boundaries"))[0],
          (Arg("uvs", (2, 8, 2), SEAM_UV_V),), empty=(0, 0), bad=((3,),)),
    Entry("mesh.face_varying_subdivide[loop]",
          lambda uv: M.face_varying_subdivide(uv, TRI_SEAM_F, TRI_SEAM_UV, 4, scheme="loop",
                                              options=M.SchemeOptions(fvar_interpolation="corners_plus1"))[0],
          (Arg("uvs", (2, 6, 2), TRI_UV_V),), empty=(0, 0), bad=((3,),)),
    Entry("mesh.face_varying_operator",
          lambda uv: M.apply_operator(  # apply_operator names its data "verts"
              M.face_varying_operator(SEAM_F, SEAM_UV, 6, 8,
                                      options=M.SchemeOptions(fvar_interpolation="all"),
                                      **_wdtype(uv)), uv),
          (Arg("verts", (2, 8, 2), SEAM_UV_V),), empty=(0, 0), bad=((2, 7, 2), (3,))),
    Entry("mesh.FaceVaryingSubdivision",
          lambda uv: M.FaceVaryingSubdivision(SEAM_F, SEAM_UV, 6, 8, levels=2,
                                              options=M.SchemeOptions(fvar_interpolation="corners_plus2"),
                                              **_wdtype(uv))(uv),
          (Arg("uvs", (2, 8, 2), SEAM_UV_V),), empty=(0, 0), bad=((2, 7, 2), (3,))),
]

EXEMPT: dict[str, str] = {
    "mesh.check_faces": "pure validator of integer faces (ValueError naming the face; "
                        "tests/mesh/test_subdivision.py)",
    "mesh.SubdivisionOperator": "result type (NamedTuple) of the operator builders, under "
                                "contract through apply_operator and the builders' entries",
    "mesh.LimitFrames": "result type (NamedTuple) of limit_frames",
    "mesh.SchemeOptions": "option bundle (frozen dataclass of strings), validated when built "
                          "(tests/mesh/test_subdivision_options.py)",
    "mesh.StencilMatrix": "result type (NamedTuple) of the stencil builders, under contract "
                          "through apply_stencils",
}
