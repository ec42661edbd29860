"""Mesh I/O and trimesh interop: round trips, peer readers, polygons kept, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.mesh.faces import check_faces, pad_faces, triangulate_faces, unpad_faces
from torchgeo_cg.mesh.io import Mesh, from_trimesh, load_mesh, save_mesh, to_trimesh
from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags

MIXED = [[0, 1, 2, 3], [1, 4, 2], [2, 4, 5, 6, 3]]


def _verts(dtype=torch.float64):
    return torch.tensor(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0.5], [1, 2, 0]],
        dtype=dtype,
    )


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".PLY", ".off"])
@pytest.mark.parametrize("binary", [True, False])
def test_round_trip_keeps_polygons(tmp_path, suffix, binary, dtype):
    v = _verts(dtype)
    path = tmp_path / f"m{suffix}"
    save_mesh(path, v, MIXED, binary=binary)
    mesh = load_mesh(path, dtype=dtype)
    assert isinstance(mesh, Mesh)
    assert mesh.verts.dtype == dtype and mesh.faces.dtype == torch.long
    assert unpad_faces(mesh.faces) == MIXED
    torch.testing.assert_close(mesh.verts, v, rtol=0, atol=0)  # exact: %.9g / %.17g / binary


def test_load_device_dtype(tmp_path, device):
    save_mesh(tmp_path / "m.obj", _verts(), MIXED)
    mesh = load_mesh(tmp_path / "m.obj", dtype=torch.float32, device=device)
    assert mesh.verts.device.type == device.type and mesh.faces.device.type == device.type
    assert mesh.verts.dtype == torch.float32


def test_obj_parser_features(tmp_path):
    text = (
        "# comment\nmtllib x.mtl\no thing\nv 0 0 0\nv 1 0 0 1.0\nvt 0 0\nvn 0 0 1\n"
        "v 1 1 0 0.5 0.5 0.5\ng grp\nusemtl m\nf 1//1 2//1 3//1\nv 0 1 0\n"
        "f -4 -2 -1 # trailing comment\n\tf  2 3 4\n"
    )
    (tmp_path / "t.obj").write_text(text)
    mesh = load_mesh(tmp_path / "t.obj", dtype=torch.float64)
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 2, 3]]
    assert mesh.verts.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]


def test_obj_matches_trimesh_reader(tmp_path):
    """Triangle meshes: our reader and trimesh's agree exactly (peer, live)."""
    ico = trimesh.creation.icosphere(subdivisions=2)
    path = tmp_path / "ico.obj"
    ico.export(path)
    ref = trimesh.load(path, process=False, maintain_order=True)
    mesh = load_mesh(path, dtype=torch.float64)
    np.testing.assert_array_equal(mesh.faces.numpy(), ref.faces)
    np.testing.assert_allclose(mesh.verts.numpy(), ref.vertices, rtol=0, atol=1e-12)


@pytest.mark.parametrize("encoding", ["binary", "ascii"])
def test_ply_matches_trimesh_writer(tmp_path, encoding):
    ico = trimesh.creation.icosphere(subdivisions=2)
    path = tmp_path / "ico.ply"
    ico.export(path, encoding=encoding)
    mesh = load_mesh(path, dtype=torch.float64)
    np.testing.assert_array_equal(mesh.faces.numpy(), ico.faces)
    np.testing.assert_allclose(mesh.verts.numpy(), ico.vertices, rtol=0, atol=1e-6)


def test_ply_uniform_quads_read_by_trimesh(tmp_path):
    """Our binary PLY writer is readable by trimesh (uniform faces: trimesh's supported case)."""
    v = _verts()
    quads = [[0, 1, 2, 3], [1, 4, 5, 2]]
    save_mesh(tmp_path / "q.ply", v, quads)
    raw = trimesh.load(tmp_path / "q.ply", process=False).metadata["_ply_raw"]["face"]["data"]
    got = np.asarray(raw["vertex_indices"]["f1"]).tolist()
    assert got == quads


def test_mixed_binary_ply_with_extra_face_property(tmp_path):
    """Variable lists plus a trailing scalar (uchar flag) and big-endian ints and doubles."""
    header = (
        b"ply\nformat binary_big_endian 1.0\nelement vertex 5\nproperty double x\n"
        b"property double y\nproperty double z\nproperty uchar red\nelement face 2\n"
        b"property list uchar uint vertex_indices\nproperty uchar flag\nend_header\n"
    )
    vdt = np.dtype([("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("r", "u1")])
    verts = np.zeros(5, dtype=vdt)
    verts["x"] = np.arange(5)
    body = verts.tobytes()
    body += bytes([4]) + np.array([0, 1, 2, 3], ">u4").tobytes() + bytes([7])
    body += bytes([3]) + np.array([1, 4, 2], ">u4").tobytes() + bytes([9])
    (tmp_path / "b.ply").write_bytes(header + body)
    mesh = load_mesh(tmp_path / "b.ply", dtype=torch.float64)
    assert unpad_faces(mesh.faces) == [[0, 1, 2, 3], [1, 4, 2]]
    assert mesh.verts[:, 0].tolist() == [0, 1, 2, 3, 4]


def test_to_trimesh_from_tensors_and_result():
    v = _verts()
    tm = to_trimesh(v, MIXED)
    assert tm.faces.shape == (2 + 1 + 3, 3)
    np.testing.assert_array_equal(tm.vertices, v.numpy())
    tm2 = to_trimesh(Mesh(v, pad_faces(MIXED)))
    np.testing.assert_array_equal(tm2.faces, tm.faces)

    class Result:  # any object with .verts/.faces (e.g. a marching-cubes result)
        verts = v.requires_grad_(True)
        faces = torch.tensor([[0, 1, 2], [0, 2, 3]])

    tm3 = to_trimesh(Result())
    assert tm3.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    # collapsed triangles (as merged marching-cubes output may have) are accepted
    assert to_trimesh(v.detach(), [[0, 1, 1]]).faces.tolist() == [[0, 1, 1]]


def test_to_from_trimesh_round_trip(dtype, device):
    box = trimesh.creation.box()
    mesh = from_trimesh(box, dtype=dtype, device=device)
    assert mesh.verts.dtype == dtype and mesh.verts.device.type == device.type
    back = to_trimesh(mesh)
    np.testing.assert_allclose(back.vertices, box.vertices)
    np.testing.assert_array_equal(back.faces, box.faces)
    assert back.is_watertight and np.isclose(back.volume, box.volume)


def test_triangulate_area_matches_trimesh_polygon_area():
    v = _verts()
    tris = triangulate_faces(MIXED)
    assert tris.shape == (6, 3)
    assert tris.tolist()[:3] == [[0, 1, 2], [0, 2, 3], [1, 4, 2]]
    area = trimesh.triangles.area(v.numpy()[tris.numpy()]).sum()
    # hand-derived: unit square 1 + triangle (1,0),(2,0),(1,1) 0.5 + pentagon by shoelace-ish
    pent = trimesh.triangles.area(v.numpy()[[[2, 4, 5], [2, 5, 6], [2, 6, 3]]]).sum()
    assert np.isclose(area, 1.5 + pent)


def test_pad_faces_inputs():
    assert pad_faces(np.array([[0, 1, 2]])).dtype == torch.long
    assert pad_faces([]).shape == (0, 0)
    obj = np.empty(2, dtype=object)
    obj[0], obj[1] = np.array([0, 1, 2, 3]), np.array([1, 4, 2])
    assert pad_faces(obj).tolist() == [[0, 1, 2, 3], [1, 4, 2, -1]]
    with pytest.raises(TypeError, match="faces"):
        pad_faces(torch.zeros(2, 3))
    with pytest.raises(TypeError, match="integer"):
        pad_faces([[0.5, 1, 2]])
    with pytest.raises(ShapeError, match="faces"):
        pad_faces(torch.zeros(3, dtype=torch.long))


@pytest.mark.parametrize(
    "faces, match",
    [
        ([[0, 1, 2], [0, 2, 9]], "face 1 has index 9, out of range"),
        ([[0, 1, 2], [0, -2, 3]], "face 1 has index -2"),
        ([[0, -1, 2, 3]], "face 0 has -1 padding before"),
        ([[0, 1, 2], [3, 3, 4]], "face 1 has fewer than 3 distinct"),
        ([[0, 1, 2, 1]], "face 0 repeats a vertex"),
        ([[0, 1, 2], [1, 2, 3], [2, 1, 0]], "face 2 repeats face 0"),
    ],
)
def test_check_faces_errors(faces, match):
    with pytest.raises(ValueError, match=match):
        check_faces(faces, 5)


def test_check_faces_other_errors():
    with pytest.raises(ShapeError, match="at least 3 columns"):
        check_faces(torch.tensor([[0, 1]]), 3)
    with pytest.raises(TypeError, match="num_vertices"):
        check_faces([[0, 1, 2]], 3.0)
    with pytest.raises(ValueError, match="num_vertices"):
        check_faces([[0, 1, 2]], -1)


def test_io_bad_input(tmp_path):
    v = _verts()
    with pytest.raises(ValueError, match="suffix"):
        save_mesh(tmp_path / "m.stl", v, MIXED)
    with pytest.raises(ValueError, match="suffix"):
        load_mesh(tmp_path / "m.stl")
    with pytest.raises(ShapeError, match="verts"):
        save_mesh(tmp_path / "m.obj", v[:, :2], MIXED)
    with pytest.raises(TypeError, match="verts"):
        save_mesh(tmp_path / "m.obj", v.long(), MIXED)
    with pytest.raises(ValueError, match="out of range"):
        save_mesh(tmp_path / "m.obj", v[:3], MIXED)
    (tmp_path / "bad.obj").write_text("v 0 0 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match="bad.obj, line 2: vertex index 2 out of range"):
        load_mesh(tmp_path / "bad.obj")
    (tmp_path / "bad.ply").write_text("not a ply")
    with pytest.raises(ValueError, match="PLY"):
        load_mesh(tmp_path / "bad.ply")
    with pytest.raises(TypeError, match="to_trimesh"):
        to_trimesh(v)
    with pytest.raises(TypeError, match="trimesh"):
        from_trimesh(v)
    if torch.cuda.is_available():
        with pytest.raises(ValueError, match="same device"):
            to_trimesh(v.cuda(), torch.tensor([[0, 1, 2]]))


def test_ply_error_paths(tmp_path):
    big = torch.zeros(300, 3)
    with pytest.raises(ValueError, match="255"):
        save_mesh(tmp_path / "big.ply", big, [list(range(300))])
    (tmp_path / "fmt.ply").write_text(
        "ply\nformat binary_middle_endian 1.0\nelement vertex 0\nproperty float x\nend_header\n"
    )
    with pytest.raises(ValueError, match="fmt.ply, line 2: expected one 'format"):
        load_mesh(tmp_path / "fmt.ply")
    (tmp_path / "lists.ply").write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement edge 1\n"
        b"property list uchar int vertex_indices\nend_header\n" + bytes([2, 0, 0, 0, 0, 1, 0, 0, 0])
    )
    with pytest.raises(ValueError, match="lists.ply: no 'vertex' element"):
        load_mesh(tmp_path / "lists.ply")


# ---------------------------------------------------------------------------
# Malformed files: every case of the corpus raises the exact ValueError expected
# ---------------------------------------------------------------------------

from tests.mesh.malformed.make_corpus import (  # noqa: E402
    CASES,
    TRIANGLE_OBJ,
    ply_header,
    write_corpus,
)


def test_malformed_corpus_is_large_and_unique(tmp_path):
    assert len(CASES) >= 60
    assert len({c.name for c in CASES}) == len(CASES)
    paths = write_corpus(tmp_path)
    assert [p.read_bytes() for p in paths] == [c.content for c in CASES]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_malformed_file_raises_value_error_naming_file_and_line(tmp_path, case):
    path = tmp_path / case.name
    path.write_bytes(case.content)
    with pytest.raises(ValueError) as err:
        load_mesh(path)
    sep = "" if case.expected.startswith(":") else ", "
    assert str(err.value).startswith(f"{path}{sep}{case.expected}"), str(err.value)


# ---------------------------------------------------------------------------
# Files a naive reader misreads: they load exactly
# ---------------------------------------------------------------------------

TRI = [[0, 1, 2]]


def _load_bytes(tmp_path, name, content, **kw):
    path = tmp_path / name
    path.write_bytes(content)
    return load_mesh(path, dtype=torch.float64, **kw)


def test_bom_keeps_first_vertex(tmp_path):
    mesh = _load_bytes(tmp_path, "bom.obj", b"\xef\xbb\xbfv 5 6 7\n" + TRIANGLE_OBJ + b"f 1 2 3\n")
    assert mesh.verts.tolist() == [[5, 6, 7], [0, 0, 0], [1, 0, 0], [0, 1, 0]]


def test_crlf_and_lone_cr_equal_lf(tmp_path):
    text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.5 0.25\nf 1/1 2/1 3/1\nt corner 1/1/0 2 3\n"
    ref = _load_bytes(tmp_path, "lf.obj", text)
    for end in (b"\r\n", b"\r"):
        got = _load_bytes(tmp_path, "x.obj", text.replace(b"\n", end))
        for a, b in zip(got, ref):
            if isinstance(a, torch.Tensor):
                assert torch.equal(a, b)
        assert torch.equal(got.tags.corners, ref.tags.corners) and got.uvs.tolist() == [[0.5, 0.25]]


def test_obj_line_continuation(tmp_path):
    mesh = _load_bytes(tmp_path, "c.obj", b"v 0 0 \\\n 0\nv 1 0 0\nv 0 1 0\nf 1 \\\r\n2 \\\n3\n")
    assert mesh.faces.tolist() == TRI and mesh.verts[0].tolist() == [0, 0, 0]


def test_obj_negative_indices_count_vertices_read_so_far(tmp_path):
    """OBJ spec: -1 is the last vertex read *before* the face, not the last of the file."""
    text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 1 1 0\nf -3 -2 -1\nf 1 -1 3\n"
    mesh = _load_bytes(tmp_path, "neg.obj", text)
    assert mesh.faces.tolist() == [[0, 1, 2], [1, 2, 3], [0, 3, 2]]


def test_obj_vertex_with_w_and_colours_keeps_xyz(tmp_path):
    text = b"v 1 2 3 1.0\nv 4 5 6 0.1 0.2 0.3\nv 7 8 9 0.1 0.2 0.3 1\nf 1 2 3\n"
    assert _load_bytes(tmp_path, "w.obj", text).verts.tolist() == [[1, 2, 3], [4, 5, 6], [7, 8, 9]]


def test_ply_comment_mentioning_end_header_does_not_end_it(tmp_path):
    body = b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    text = ply_header().replace(b"element vertex", b"comment see end_header\nelement vertex")
    mesh = _load_bytes(tmp_path, "c.ply", text + body)
    assert mesh.faces.tolist() == TRI and mesh.verts.shape == (3, 3)


def test_ply_blank_lines_in_ascii_body_are_skipped(tmp_path):
    body = b"\n\n0 0 0\n  \n1 0 0\n0 1 0\r\n\n3 0 1 2\n\n"
    mesh = _load_bytes(tmp_path, "b.ply", ply_header() + body)
    assert mesh.faces.tolist() == TRI and mesh.verts[1].tolist() == [1, 0, 0]


@pytest.mark.parametrize("suffix, binary", [(".obj", False), (".ply", False), (".ply", True)])
def test_empty_mesh_round_trip(tmp_path, suffix, binary):
    path = tmp_path / f"empty{suffix}"
    save_mesh(path, torch.zeros(0, 3, dtype=torch.float64), [], binary=binary)
    mesh = load_mesh(path, dtype=torch.float64)
    assert mesh.verts.shape == (0, 3) and mesh.faces.shape[0] == 0


def test_save_refuses_faces_of_fewer_than_three_vertices(tmp_path):
    v = _verts()
    for faces, msg in (([[0, 1, 2], []], "face 1 has 0 vertices"),
                       ([[0, 1]], "face 0 has 2 vertices"),
                       (torch.tensor([[0, 1, 2], [3, -1, -1]]), "face 1 has 1 vertices")):
        for suffix in (".obj", ".ply"):
            with pytest.raises(ValueError, match=msg):
                save_mesh(tmp_path / f"m{suffix}", v, faces)
    assert not (tmp_path / "m.obj").exists()


def test_ply_refuses_uvs_and_tags(tmp_path):
    v = _verts()
    tags = SubdivisionTags.empty()._replace(holes=torch.tensor([0]))
    with pytest.raises(ValueError, match="PLY holds no uvs"):
        save_mesh(tmp_path / "m.ply", v, MIXED, tags=tags)
    with pytest.raises(ValueError, match="PLY holds no uvs"):
        save_mesh(tmp_path / "m.ply", v, MIXED, uvs=torch.zeros(1, 2))
    with pytest.raises(ValueError, match="OFF holds no uvs"):
        save_mesh(tmp_path / "m.off", v, MIXED, options={"boundary": "none"})


def test_mesh_defaults_keep_two_field_construction():
    assert Mesh._fields == ("verts", "faces", "uvs", "uv_faces", "tags", "options")
    m = Mesh(_verts(), pad_faces(MIXED))
    assert m.uvs is None and m.uv_faces is None and m.tags is None and m.options is None
    verts, faces, *_ = m
    assert verts is m.verts and faces is m.faces


# ---------------------------------------------------------------------------
# Round trips of UVs and tags (OBJ), against hand-written values
# ---------------------------------------------------------------------------

def _tagged_cube(dtype=torch.float64):
    import itertools

    verts = torch.tensor(list(itertools.product([0.0, 1.0], repeat=3)), dtype=dtype)
    faces = torch.tensor([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6],
                          [0, 2, 6, 4], [1, 5, 7, 3]])
    tags = SubdivisionTags(
        creases=torch.tensor([[0, 1], [1, 3], [4, 6]]),
        crease_sharpness=torch.tensor([0.5, 2.3, 10.0], dtype=dtype),
        corners=torch.tensor([7, 2]),
        corner_sharpness=torch.tensor([1.0 / 3.0, 4.0], dtype=dtype),
        holes=torch.tensor([5]),
    )
    return verts, faces, tags


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_tags_and_options_round_trip(tmp_path, dtype):
    verts, faces, tags = _tagged_cube(dtype)
    options = {"boundary": "none", "crease_method": "chaikin", "triangle_rule": "smooth",
               "fvar_interpolation": "corners_plus1", "fvar_propagate_corners": True}
    save_mesh(tmp_path / "cube.obj", verts, faces, tags=tags, options=options)
    mesh = load_mesh(tmp_path / "cube.obj", dtype=dtype)
    assert mesh.options == options
    for got, want in zip(mesh.tags, tags):
        assert got.dtype == want.dtype and torch.equal(got, want)  # exact: %.9g / %.17g
    again = tmp_path / "again.obj"
    save_mesh(again, mesh)  # a Mesh writes itself, tags included
    assert again.read_text() == (tmp_path / "cube.obj").read_text()


def test_uvs_with_seams_round_trip(tmp_path, dtype):
    verts, faces, _ = _tagged_cube(dtype)
    # a seam: the 6 faces use 14 texture vertices, more than the 8 positions
    uvs = torch.rand(14, 2, dtype=dtype, generator=torch.Generator().manual_seed(0))
    uv_faces = torch.tensor([[0, 1, 3, 2], [4, 6, 7, 5], [8, 9, 1, 0], [2, 3, 11, 10],
                             [0, 2, 12, 13], [1, 5, 7, 3]])
    save_mesh(tmp_path / "uv.obj", verts, faces, uvs=uvs, uv_faces=uv_faces)
    mesh = load_mesh(tmp_path / "uv.obj", dtype=dtype)
    assert torch.equal(mesh.uvs, uvs) and torch.equal(mesh.uv_faces, uv_faces)
    assert torch.equal(mesh.faces, faces) and torch.equal(mesh.verts, verts)
    assert "f 1/1 2/2 4/4 3/3" in (tmp_path / "uv.obj").read_text()


def test_mixed_polygons_with_uvs_round_trip(tmp_path):
    v = _verts()
    uvs = torch.arange(20, dtype=torch.float64).reshape(10, 2) / 7
    uv_faces = [[9, 8, 7, 6], [5, 4, 3], [2, 1, 0, 9, 8]]
    save_mesh(tmp_path / "m.obj", v, MIXED, uvs=uvs, uv_faces=uv_faces)
    mesh = load_mesh(tmp_path / "m.obj", dtype=torch.float64)
    assert unpad_faces(mesh.uv_faces) == uv_faces and unpad_faces(mesh.faces) == MIXED
    with pytest.raises(ValueError, match="uv_faces: face 0 has texture indices on some corners"):
        save_mesh(tmp_path / "m.obj", v, MIXED, uvs=uvs, uv_faces=[[1, 2, 3]] * 3)
    with pytest.raises(ValueError, match="uv_faces: expected the padding of faces"):
        save_mesh(tmp_path / "m.obj", v, MIXED, uvs=uvs, uv_faces=[[1, 2, 3, 4, 5]] * 3)
    with pytest.raises(ValueError, match="uv_faces: face 0 has index 10, out of range"):
        save_mesh(tmp_path / "m.obj", v, MIXED, uvs=uvs, uv_faces=[[10, 8, 7, 6], [5, 4, 3],
                                                                   [2, 1, 0, 9, 8]])


OPENSUBDIV_SHAPE = (  # the layout of OpenSubdiv's regression/shapes/catmark_cube_creases0.h
    b"# This file uses centimeters as units for non-parametric coordinates.\n\n"
    b"v 0.000000 -1.414214 1.000000\nv 1.414214 0.000000 1.000000\n"
    b"v -1.414214 0.000000 1.000000\nv 0.000000 1.414214 1.000000\n"
    b"v -1.414214 0.000000 -1.000000\nv 0.000000 1.414214 -1.000000\n"
    b"v 0.000000 -1.414214 -1.000000\nv 1.414214 0.000000 -1.000000\n"
    + b"".join(b"vt %g %g \n" % (0.375 + 0.25 * (i % 2), 0.25 * (i // 2)) for i in range(10))
    + b"vt 0.875 0\nvt 0.875 0.25\nvt 0.125 0\nvt 0.125 0.25\n"
    + b"vn 0 0 1\n" * 24 + b"s off\n"
    b"f 1/1/1 2/2/2 4/4/3 3/3/4\nf 3/3/5 4/4/6 6/6/7 5/5/8\nf 5/5/9 6/6/10 8/8/11 7/7/12\n"
    b"f 7/7/13 8/8/14 2/10/15 1/9/16\nf 2/2/17 8/11/18 6/12/19 4/4/20\n"
    b"f 7/13/21 1/1/22 3/3/23 5/14/24\n"
    b"t crease 2/1/0 0 1 2.0\nt crease 2/1/0 1 3 2.0\nt interpolateboundary 1/0/0 2\n"
)


def test_opensubdiv_shape_tags_and_uvs(tmp_path):
    mesh = _load_bytes(tmp_path, "catmark_cube_creases0.obj", OPENSUBDIV_SHAPE)
    assert mesh.faces.tolist()[0] == [0, 1, 3, 2] and mesh.uvs.shape == (14, 2)
    assert mesh.uv_faces.tolist()[3] == [6, 7, 9, 8]
    assert mesh.tags.creases.tolist() == [[0, 1], [1, 3]]
    assert mesh.tags.crease_sharpness.tolist() == [2.0, 2.0]
    assert mesh.options == {"boundary": "edge_only"}
    assert mesh.tags.corners.shape == (0,) and mesh.tags.holes.shape == (0,)


def test_crease_tag_with_several_edges_and_sharpness_per_edge(tmp_path):
    text = TRIANGLE_OBJ + b"v 1 1 0\nf 1 2 4 3\nt crease 4/2/0 0 1 1 3 0.5 3\n"
    text += b"t crease 4/1/0 3 2 2 0 7\nt corner 2/1/0 0 3 1.5\nt hole 1/0/0 0\n"
    tags = _load_bytes(tmp_path, "t.obj", text).tags
    assert tags.creases.tolist() == [[0, 1], [1, 3], [3, 2], [2, 0]]
    assert tags.crease_sharpness.tolist() == [0.5, 3, 7, 7]
    assert tags.corners.tolist() == [0, 3] and tags.corner_sharpness.tolist() == [1.5, 1.5]
    assert tags.holes.tolist() == [0]


# ---------------------------------------------------------------------------
# A brute-force reference reader (one line at a time) on random valid OBJ files
# ---------------------------------------------------------------------------

def _reference_obj(text: str):
    verts, uvs, faces, uv_faces = [], [], [], []
    for line in text.splitlines():
        words = line.split("#")[0].split()
        if not words:
            continue
        if words[0] == "v":
            verts.append([float(x) for x in words[1:4]])
        elif words[0] == "vt":
            uvs.append([float(words[1]), float(words[2]) if len(words) > 2 else 0.0])
        elif words[0] == "f":
            corners = [w.split("/") for w in words[1:]]

            def fix(i, n):
                i = int(i)
                return i - 1 if i > 0 else n + i

            faces.append([fix(c[0], len(verts)) for c in corners])
            if len(corners[0]) > 1 and corners[0][1]:
                uv_faces.append([fix(c[1], len(uvs)) for c in corners])
    return verts, uvs, faces, uv_faces


def _random_obj(rng) -> str:
    """Interleaved v / vt / f / comment / group lines; every index valid where it stands."""
    with_uv = bool(rng.integers(2))
    lines, n_v, n_t = ["v 0 0 0", "v 1 0 0", "v 0 1 0", "vt 0.5 0.5"], 3, 1
    for _ in range(int(rng.integers(0, 40))):
        kind = rng.choice(["v", "vt", "f", "f", "#", "", "g"])
        if kind == "v":
            lines.append("v " + " ".join(f"{x:.6g}" for x in rng.normal(size=3) * 1e3)
                         + (" 1" if rng.random() < 0.1 else ""))
            n_v += 1
        elif kind == "vt":
            lines.append(f"vt {rng.random():.6g} {rng.random():.6g}")
            n_t += 1
        elif kind == "f":
            k = int(rng.integers(3, 7))
            vi = rng.integers(0, n_v, k)
            corners = [str(i + 1) if rng.random() < 0.5 else str(i - n_v) for i in vi]
            if with_uv:
                corners = [f"{c}/{int(rng.integers(1, n_t + 1))}" for c in corners]
            sep = " " if rng.random() < 0.8 else "\t "
            lines.append("f " + sep.join(corners) + (" # c" if rng.random() < 0.2 else ""))
        else:
            lines.append({"#": "# comment v 1 2", "": "  ", "g": "g group"}[kind])
    return "\n".join(lines) + ("\n" if rng.random() < 0.5 else "")


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_obj_reader_matches_line_by_line_reference(tmp_path_factory, seed):
    text = _random_obj(np.random.default_rng(seed))
    path = tmp_path_factory.mktemp("ref") / "r.obj"
    path.write_text(text)
    mesh = load_mesh(path, dtype=torch.float64)
    verts, uvs, faces, uv_faces = _reference_obj(text)
    assert mesh.verts.tolist() == verts and mesh.uvs.tolist() == uvs
    assert unpad_faces(mesh.faces) == faces if faces else mesh.faces.shape[0] == 0
    if uv_faces:
        assert unpad_faces(mesh.uv_faces) == uv_faces
    else:
        assert mesh.uv_faces is None


# ---------------------------------------------------------------------------
# Damaged files: a ValueError or a mesh, never another exception
# ---------------------------------------------------------------------------

def _valid_files():
    v = _verts()
    out = {}
    for name, binary in (("a.obj", False), ("a.ply", False), ("b.ply", True), ("a.off", False)):
        import tempfile

        with tempfile.TemporaryDirectory() as d:
            path = f"{d}/{name}"
            save_mesh(path, v, MIXED, binary=binary, **({"uvs": torch.zeros(3, 2),
                      "uv_faces": [[0, 1, 2, 0], [1, 2, 0], [2, 0, 1, 2, 0]],
                      "tags": SubdivisionTags(torch.tensor([[0, 1]]), torch.tensor([1.5]),
                                              torch.tensor([2]), torch.tensor([3.0]),
                                              torch.tensor([1]))
                      } if name.endswith(".obj") else {}))
            with open(path, "rb") as fh:
                out[name] = fh.read()
    return out


VALID = _valid_files()


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(sorted(VALID)), data=st.data())
def test_damaged_files_raise_value_error_or_load(tmp_path_factory, name, data):
    content = bytearray(VALID[name])
    for _ in range(data.draw(st.integers(1, 4))):
        kind = data.draw(st.sampled_from(["flip", "cut", "insert", "delete"]))
        at = data.draw(st.integers(0, len(content) - 1))
        if kind == "flip":
            content[at] = data.draw(st.integers(0, 255))
        elif kind == "cut":
            del content[at:]
        elif kind == "insert":
            content[at:at] = data.draw(st.binary(min_size=1, max_size=4))
        else:
            del content[at:at + data.draw(st.integers(1, 8))]
        if not content:
            content = bytearray(b"?")
    path = tmp_path_factory.mktemp("dmg") / name
    path.write_bytes(bytes(content))
    try:
        mesh = load_mesh(path, dtype=torch.float64)
    except ValueError as err:
        assert str(err).startswith(str(path))
        return
    assert mesh.verts.ndim == 2 and mesh.verts.shape[1] == 3
    if mesh.faces.shape[0]:
        assert ((mesh.faces >= 0).sum(1) >= 3).all() and int(mesh.faces.max()) < len(mesh.verts)


def test_continuation_on_the_last_line(tmp_path):
    mesh = _load_bytes(tmp_path, "end.obj", TRIANGLE_OBJ + b"f 1 2 \\\n3\\\n")
    assert mesh.faces.tolist() == TRI


def test_off_matches_trimesh_writer_and_keeps_colours_out(tmp_path):
    ico = trimesh.creation.icosphere(subdivisions=2)
    ico.export(tmp_path / "ico.off")
    mesh = load_mesh(tmp_path / "ico.off", dtype=torch.float64)
    np.testing.assert_array_equal(mesh.faces.numpy(), ico.faces)
    np.testing.assert_allclose(mesh.verts.numpy(), ico.vertices, rtol=1e-7, atol=1e-12)
    text = b"OFF 4 2 0\n0 0 0\n1 0 0\n1 1 0\n# c\n0 1 0\n4 0 1 2 3 255 0 0\n3 0 1 2 1 1 1 1\n"
    mesh = _load_bytes(tmp_path, "c.off", text)
    assert unpad_faces(mesh.faces) == [[0, 1, 2, 3], [0, 1, 2]] and mesh.verts.shape == (4, 3)


def test_save_refuses_tags_that_would_not_read_back(tmp_path):
    verts, faces, tags = _tagged_cube()
    cases = [
        (tags._replace(creases=torch.tensor([[0, 1], [1, 3], [0, 7]])), r"tags.creases: item 2: "
         r"crease \[0, 7\] is not an edge of the mesh"),
        (tags._replace(corner_sharpness=torch.tensor([1.0, -2.0], dtype=torch.float64)),
         "tags.corners: item 1: corner sharpness must be finite and >= 0, got -2.0"),
        (tags._replace(holes=torch.tensor([6])), r"tags.holes: item 0: hole \[6\] out of range"),
        (tags._replace(creases=torch.tensor([[0, 1], [1, 3], [1, 0]])),
         r"tags.creases: item 2: crease \[1, 0\] tagged twice"),
    ]
    for bad, msg in cases:
        with pytest.raises(ValueError, match=msg):
            save_mesh(tmp_path / "bad.obj", verts, faces, tags=bad)
    with pytest.raises(ValueError, match="options: boundary='sharp' is not one of"):
        save_mesh(tmp_path / "bad.obj", verts, faces, options={"boundary": "sharp"})
    with pytest.raises(ValueError, match="options: unknown keys"):
        save_mesh(tmp_path / "bad.obj", verts, faces, options={"sharpness": 1})
    assert not (tmp_path / "bad.obj").exists()


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_other_elements_and_properties_are_read_and_dropped(tmp_path, fmt):
    """Scalars before and after the face list, an extra list element, mixed face sizes."""
    header = (
        f"ply\nformat {fmt} 1.0\nelement vertex 4\nproperty uchar red\nproperty double x\n"
        "property double y\nproperty double z\nelement face 2\nproperty short tag\n"
        "property list uchar uint vertex_indices\nproperty float weight\nelement edge 2\n"
        "property list ushort int vertex_pair\nproperty char kind\nend_header\n"
    ).encode()
    verts = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.5]]
    faces = [[0, 1, 2, 3], [0, 2, 3]]
    if fmt == "ascii":
        body = "".join(f"7 {x} {y} {z}\n" for x, y, z in verts)
        body += "-3 4 0 1 2 3 0.5\n5 3 0 2 3 1.5\n2 0 1 -1\n2 2 3 1\n"
        data = header + body.encode()
    else:
        e = "<" if fmt.endswith("little_endian") else ">"
        vdt = np.dtype([("r", "u1"), ("x", e + "f8"), ("y", e + "f8"), ("z", e + "f8")])
        v = np.zeros(4, vdt)
        v["x"], v["y"], v["z"] = np.array(verts).T
        body = v.tobytes()
        for tag, f, w in ((-3, faces[0], 0.5), (5, faces[1], 1.5)):
            body += np.array([tag], e + "i2").tobytes() + bytes([len(f)])
            body += np.array(f, e + "u4").tobytes() + np.array([w], e + "f4").tobytes()
        for pair, kind in (([0, 1], -1), ([2, 3], 1)):
            body += np.array([2], e + "u2").tobytes() + np.array(pair, e + "i4").tobytes()
            body += np.array([kind], "i1").tobytes()
        data = header + body
    mesh = _load_bytes(tmp_path, "x.ply", data)
    assert mesh.verts.tolist() == verts and unpad_faces(mesh.faces) == faces
    for cut in (1, 5) if fmt != "ascii" else ():  # truncated: refused, never misread
        with pytest.raises(ValueError, match="x.ply: "):
            _load_bytes(tmp_path, "x.ply", data[:-cut])


def test_one_huge_face_does_not_pad_every_face_to_gigabytes(tmp_path):
    """200k triangles + one 800-gon would pad to 200k x 800 int64 (1.2 GiB) from a 2 MB file."""
    text = b"v 0 0 0\n" * 800 + b"f 1 2 3\n" * 200_000 + b"f " + b" ".join(
        str(i).encode() for i in range(1, 801)) + b"\n"
    with pytest.raises(ValueError, match=r"line 200801: a face of 800 vertices pads 200001 faces"):
        _load_bytes(tmp_path, "big.obj", text)


# ----------------------------------------------------------------------------- contract ------
@pytest.mark.parametrize("suffix, binary", [(".obj", True), (".ply", True), (".ply", False),
                                            (".off", True)])
def test_bfloat16_verts_save_exactly(tmp_path, suffix, binary):
    # unguarded: TypeError "Got unsupported ScalarType BFloat16" from .numpy()
    v = (_verts(torch.float64) * 1.37 - 0.4).to(torch.bfloat16)
    path = tmp_path / f"m{suffix}"
    save_mesh(path, v, MIXED, binary=binary)
    back = load_mesh(path, dtype=torch.bfloat16)
    assert back.verts.dtype == torch.bfloat16 and torch.equal(back.verts, v)
    tm = to_trimesh(v, MIXED)
    assert np.array_equal(tm.vertices, v.double().numpy())


def test_uvs_and_sharpness_keep_their_own_digits(tmp_path):
    # unguarded: uvs and tag sharpness written with the digits of the verts' dtype (9 for float32)
    v = _verts(torch.float32)
    uvs = torch.tensor([[0.1, 0.2], [1 / 3, 2 / 3], [0.7, 0.9]], dtype=torch.float64)
    uv_faces = [[0, 1, 2, 0], [1, 2, 0], [2, 0, 1, 2, 0]]
    sharp = torch.tensor([1 / 3], dtype=torch.float64)
    empty = torch.zeros(0, dtype=torch.long)
    tags = SubdivisionTags(torch.tensor([[0, 1]]), sharp, empty, sharp[:0], empty)
    path = tmp_path / "m.obj"
    save_mesh(path, v, MIXED, uvs=uvs, uv_faces=uv_faces, tags=tags)
    back = load_mesh(path, dtype=torch.float64)
    assert torch.equal(back.uvs, uvs)  # 17 digits: exact in float64
    assert torch.equal(back.tags.crease_sharpness, sharp)
    assert torch.equal(back.verts, v.double())


@pytest.mark.parametrize("dtype", [torch.long, torch.bool, "float64"])
def test_non_float_dtype_raises(tmp_path, dtype):
    # unguarded: load_mesh(dtype=torch.long) truncated the coordinates silently
    path = tmp_path / "m.obj"
    save_mesh(path, _verts() + 0.25, MIXED)
    with pytest.raises(TypeError, match="dtype: expected a floating-point dtype"):
        load_mesh(path, dtype=dtype)
    with pytest.raises(TypeError, match="dtype: expected a floating-point dtype"):
        from_trimesh(trimesh.creation.box(), dtype=dtype)


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_half_dtype_saturates_instead_of_inf(tmp_path, dtype):
    # unguarded: 1e5 (float16) or 1e39 (bfloat16) in the file became inf
    big = 1e39 if dtype == torch.bfloat16 else 1e5
    v = _verts() * big
    path = tmp_path / "m.obj"
    save_mesh(path, v, MIXED)
    top = torch.finfo(dtype).max
    want = torch.where(v > top, top, v).to(dtype)
    assert torch.equal(load_mesh(path, dtype=dtype).verts, want)
    assert torch.equal(from_trimesh(to_trimesh(v, MIXED), dtype=dtype).verts, want)
