"""Mesh I/O and trimesh interop: round trips, peer readers, polygons kept, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.mesh import faces as faces_mod
from torchgeo_cg.mesh import io as io_mod
from torchgeo_cg.mesh.faces import check_faces, pad_faces, triangulate_faces, unpad_faces
from torchgeo_cg.mesh.io import Mesh, from_trimesh, load_mesh, save_mesh, to_trimesh

MIXED = [[0, 1, 2, 3], [1, 4, 2], [2, 4, 5, 6, 3]]


def _verts(dtype=torch.float64):
    return torch.tensor(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0.5], [1, 2, 0]],
        dtype=dtype,
    )


def test_public_surface():
    assert set(io_mod.__all__) == {"Mesh", "load_mesh", "save_mesh", "from_trimesh", "to_trimesh"}
    assert set(faces_mod.__all__) == {
        "pad_faces", "face_sizes", "check_faces", "triangulate_faces", "unpad_faces"
    }


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".PLY"])
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


def test_package_exports_io_and_subdivision():
    import torchgeo_cg.mesh as mesh

    names = {
        "Mesh", "load_mesh", "save_mesh", "from_trimesh", "to_trimesh", "pad_faces",
        "face_sizes", "check_faces", "triangulate_faces", "unpad_faces", "SubdivisionOperator",
        "catmull_clark_operator", "apply_operator", "catmull_clark", "CatmullClark",
        "limit_positions",
    }
    assert names <= set(mesh.__all__)
    assert all(hasattr(mesh, n) for n in names)


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

from tests.mesh.malformed.make_corpus import CASES, TRIANGLE_OBJ, write_corpus  # noqa: E402


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
