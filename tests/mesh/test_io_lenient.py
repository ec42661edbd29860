"""Files that real exporters write outside the strict formats: read, with one warning.

Mixed ``v/vt/vn`` and ``v//vn`` faces, latin-1 comments and names, unknown OBJ
statements and non-ASCII PLY comments load; each file gives at most one
``MeshFileWarning`` naming the file, the first line skipped and how many were.
Positions and faces are compared with trimesh reading the same file
(``process=False``; trimesh holds triangles, so ours are fan-triangulated).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from torchgeo_cg.mesh.faces import triangulate_faces, unpad_faces
from torchgeo_cg.mesh.io import Mesh, MeshFileWarning, load_mesh, save_mesh
from torchgeo_cg.mesh.subdivision import face_varying_subdivide

QUADS = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\nv 3 0 0\nv 3 1 0\n"
UVS = b"vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
NORMALS = b"vn 0 0 1\n"

# one object with UVs and normals, one with normals only, one with positions only
MIXED_OBJ = (QUADS + UVS + NORMALS
             + b"o textured\nf 1/1/1 2/2/1 3/3/1 4/4/1\n"
             + b"o plain\nf 2//1 5//1 6//1 3//1\n"
             + b"o bare\nf 5 7 6\n"
             + b"o textured_again\nf 6/1 7/2 8/3\n")


def _load(tmp_path, name: str, content: bytes, expect_warning: bool = True):
    """Load ``content`` as ``name``; return the mesh and the warnings it gave (all)."""
    path = tmp_path / name
    path.write_bytes(content)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mesh = load_mesh(path, dtype=torch.float64)
    assert len(caught) == (1 if expect_warning else 0), [str(w.message) for w in caught]
    return mesh, caught, path


def _assert_warning(caught, path, count: int, line: int, what: str):
    (w,) = caught
    assert w.category is MeshFileWarning and issubclass(MeshFileWarning, UserWarning)
    assert MeshFileWarning.__name__ in __import__("torchgeo_cg.mesh.io").mesh.io.__all__
    plural = "s" if count > 1 else ""
    assert str(w.message) == (f"{path}: skipped what cannot change positions or faces on "
                              f"{count} line{plural}; the first, line {line}: {what}")
    assert w.filename == __file__  # points at the caller of load_mesh


def _triangle_set(tris: np.ndarray) -> np.ndarray:
    """The triangles, each rotated to start at its smallest index (winding kept), sorted."""
    shift = np.argmin(tris, axis=1)[:, None]
    rows = np.take_along_axis(tris, (shift + np.arange(3)) % 3, axis=1)
    return rows[np.lexsort(rows.T[::-1])]


def _assert_same_as_trimesh(mesh: Mesh, path):
    """Same positions, in order, and the same triangles, with their winding, as trimesh's.

    trimesh splits a quad ``a b c d`` as ``a b c, c d a`` (our fan: ``a b c, a c d``) and,
    with UVs, lists the first halves of all quads before the second halves; so the
    triangles are compared as sets, each from its smallest index on. trimesh drops
    unreferenced vertices when the file has UVs: the files here reference all.
    """
    ref = trimesh.load(path, process=False, maintain_order=True, force="mesh")
    np.testing.assert_array_equal(mesh.verts.numpy(), ref.vertices)
    ours = triangulate_faces(mesh.faces).numpy()
    np.testing.assert_array_equal(_triangle_set(ours), _triangle_set(np.asarray(ref.faces)))


# ---------------------------------------------------------------------------
# Faces with and without texture indices in one file
# ---------------------------------------------------------------------------

def test_mixed_corner_forms_read_like_trimesh(tmp_path):
    mesh, _, path = _load(tmp_path, "mixed.obj", MIXED_OBJ, expect_warning=False)
    assert unpad_faces(mesh.faces) == [[0, 1, 2, 3], [1, 4, 5, 2], [4, 6, 5], [5, 6, 7]]
    # -1 on every corner of the faces without texture indices; padding where faces is -1
    assert mesh.uv_faces.tolist() == [[0, 1, 2, 3], [-1, -1, -1, -1], [-1, -1, -1, -1],
                                      [0, 1, 2, -1]]
    assert mesh.faces[3, 3] == -1 and mesh.faces[1].min() >= 0
    assert mesh.uvs.shape == (4, 2)
    _assert_same_as_trimesh(mesh, path)


def test_mixed_forms_save_v_and_v_vt_and_round_trip(tmp_path):
    mesh, _, _ = _load(tmp_path, "mixed.obj", MIXED_OBJ, expect_warning=False)
    save_mesh(tmp_path / "back.obj", mesh)
    text = (tmp_path / "back.obj").read_text()
    assert text.splitlines()[-4:] == ["f 1/1 2/2 3/3 4/4", "f 2 5 6 3", "f 5 7 6",
                                      "f 6/1 7/2 8/3"]
    assert "//" not in text
    back, _, _ = _load(tmp_path, "back.obj", text.encode(), expect_warning=False)
    for a, b in zip(back[:4], mesh[:4]):
        assert torch.equal(a, b)


def test_save_refuses_texture_indices_on_some_corners_only(tmp_path):
    mesh, _, _ = _load(tmp_path, "mixed.obj", MIXED_OBJ, expect_warning=False)
    uv_faces = mesh.uv_faces.clone()
    uv_faces[1, 0] = 0
    with pytest.raises(ValueError, match=r"uv_faces: face 1 has texture indices on some "
                                         r"corners only \(\[0, -1, -1, -1\]\)"):
        save_mesh(tmp_path / "bad.obj", mesh._replace(uv_faces=uv_faces))


def test_face_varying_subdivision_names_the_faces_without_uvs(tmp_path):
    mesh, _, _ = _load(tmp_path, "mixed.obj", MIXED_OBJ, expect_warning=False)
    with pytest.raises(ValueError, match=r"uv_faces: face 1 has 0 values but faces\[1\] has "
                                         r"4 vertices \(-1 on every corner"):
        face_varying_subdivide(mesh.uvs, mesh.faces, mesh.uv_faces, len(mesh.verts))
    textured = [0, 3]  # the faces that have UVs subdivide
    uv, _ = face_varying_subdivide(mesh.uvs, mesh.faces[textured], mesh.uv_faces[textured],
                                   len(mesh.verts))
    assert uv.shape[-1] == 2 and torch.isfinite(uv).all()


def test_all_faces_without_texture_indices_give_none(tmp_path):
    content = QUADS + UVS + NORMALS + b"f 1//1 2//1 3//1\nf 1 3 4\n"
    mesh, _, path = _load(tmp_path, "nouv.obj", content, expect_warning=False)
    assert mesh.uv_faces is None and mesh.uvs.shape == (4, 2)
    _assert_same_as_trimesh(mesh, path)


# ---------------------------------------------------------------------------
# latin-1 bytes and unknown statements: skipped, one warning
# ---------------------------------------------------------------------------

LATIN1_OBJ = (b"# Export\xe9 par Caf\xe9 3D\n" + QUADS
              + b"mtllib mat\xe9riaux.mtl\no Th\xe9i\xe8re\ng cou\xe9vercle\n"
              + b"usemtl m\xe9tal\nf 1 2 3 4\n# fin \xe9\ns 1\nf 2 5 6 3\nf 6 7 8\n")


def test_latin1_comments_and_names_read_like_trimesh(tmp_path):
    mesh, caught, path = _load(tmp_path, "latin1.obj", LATIN1_OBJ)
    assert unpad_faces(mesh.faces) == [[0, 1, 2, 3], [1, 4, 5, 2], [5, 6, 7]]
    _assert_warning(caught, path, 6, 1, "bytes that are not UTF-8 in a comment or a name")
    _assert_same_as_trimesh(mesh, path)
    plain, _, _ = _load(tmp_path, "plain.obj", LATIN1_OBJ.replace(b"\xe9", b"e").replace(
        b"\xe8", b"e"), expect_warning=False)
    assert torch.equal(mesh.verts, plain.verts) and torch.equal(mesh.faces, plain.faces)


UNKNOWN_OBJ = (QUADS + b"vx 1 2 3\n" + UVS + b"call other.obj\ncsh ls\nnewmtl red\n"
               + b"Kd 1 0 0\nf 1/1 2/2 3/3 4/4\n# a comment\nweird_statement_longer_than_16\n"
               + b"f 2/1 5/2 6/3 3/4\nf 6/1 7/2 8/3\n")


def test_unknown_statements_skipped_like_trimesh(tmp_path):
    mesh, caught, path = _load(tmp_path, "unknown.obj", UNKNOWN_OBJ)
    _assert_warning(caught, path, 6, 9, "unknown OBJ statement 'vx'")
    assert unpad_faces(mesh.faces) == [[0, 1, 2, 3], [1, 4, 5, 2], [5, 6, 7]]
    assert mesh.uv_faces.tolist() == [[0, 1, 2, 3], [0, 1, 2, 3], [0, 1, 2, -1]]
    _assert_same_as_trimesh(mesh, path)


def test_unknown_and_latin1_lines_counted_once_in_one_warning(tmp_path):
    content = QUADS + b"g caf\xe9\nnewmtl \xe9\nf 1 2 3\n\xe9trange 1 2\n" + b"vx 0\n" * 50
    mesh, caught, path = _load(tmp_path, "both.obj", content)
    _assert_warning(caught, path, 53, 9, "bytes that are not UTF-8 in a comment or a name")
    assert mesh.faces.tolist() == [[0, 1, 2]]


def test_clean_files_give_no_warning(tmp_path):
    content = b"# caf\xc3\xa9 in UTF-8\n" + QUADS + b"g a\no b\nusemtl c\ns off\nf 1 2 3\n"
    _load(tmp_path, "clean.obj", content, expect_warning=False)
    save_mesh(tmp_path / "q.ply", torch.eye(3), [[0, 1, 2]])
    _load(tmp_path, "q.ply", (tmp_path / "q.ply").read_bytes(), expect_warning=False)


def _random_lenient_obj(rng):
    """Random OBJ text, its skipped line numbers, and the brute-force expected mesh."""
    lines, verts, uvs, faces, uv_faces, skipped = [], [], [], [], [], []
    for _ in range(int(rng.integers(3, 60))):
        kind = rng.choice(["v", "vt", "f", "junk", "name", "comment"])
        if kind == "v" or len(verts) < 3:
            verts.append((rng.normal(size=3) * 100).round(3).tolist())
            lines.append(b"v %r %r %r" % tuple(verts[-1]))
        elif kind == "vt":
            uvs.append(rng.random(2).round(3).tolist())
            lines.append(b"vt %r %r" % tuple(uvs[-1]))
        elif kind == "f":
            k = int(rng.integers(3, 6))
            vi = rng.integers(0, len(verts), k).tolist()
            form = int(rng.integers(0, 4)) if uvs else int(rng.choice([0, 3]))
            ti = rng.integers(0, max(len(uvs), 1), k).tolist()
            corner = [b"%d", b"%d/%d", b"%d/%d/1", b"%d//1"][form]
            args = [(v + 1, t + 1) if form in (1, 2) else (v + 1,) for v, t in zip(vi, ti)]
            lines.append(b"f " + b" ".join(corner % a for a in args))
            faces.append(vi)
            uv_faces.append(ti if form in (1, 2) else [-1] * k)
        elif kind == "junk":
            lines.append(rng.choice([b"vx 1 2 3", b"call x.obj", b"csh ls", b"newmtl m",
                                     b"\xe9 x"]))
            skipped.append(len(lines))
        elif kind == "name":
            latin = rng.random() < 0.5
            lines.append(rng.choice([b"g ", b"o ", b"usemtl "]) + (b"n\xe9" if latin else b"n"))
            if latin:
                skipped.append(len(lines))
        else:
            latin = rng.random() < 0.5
            lines.append(b"# c" + (b"\xe9" if latin else b""))
            if latin:
                skipped.append(len(lines))
    return b"\n".join(lines) + b"\n", skipped, verts, uvs, faces, uv_faces


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_lenient_reader_matches_brute_force(tmp_path_factory, seed):
    content, skipped, verts, uvs, faces, uv_faces = _random_lenient_obj(
        np.random.default_rng(seed))
    path = tmp_path_factory.mktemp("len") / "r.obj"
    path.write_bytes(content)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mesh = load_mesh(path, dtype=torch.float64)
    assert len(caught) == (1 if skipped else 0)
    if skipped:
        message = str(caught[0].message)
        count = f"{len(skipped)} line{'s' if len(skipped) > 1 else ''}"
        assert f"on {count}; the first, line {skipped[0]}:" in message, message
    assert mesh.verts.tolist() == verts
    assert (unpad_faces(mesh.faces) if faces else []) == faces
    has_uv = [f for f in uv_faces if f[0] >= 0]
    if not has_uv:
        assert mesh.uv_faces is None
    else:
        got = [row[row >= 0].tolist() if row.max() >= 0 else [-1] * int(n)
               for row, n in zip(mesh.uv_faces, (mesh.faces >= 0).sum(1))]
        assert got == uv_faces and mesh.uvs.tolist() == uvs


# ---------------------------------------------------------------------------
# PLY: non-ASCII comment and obj_info lines
# ---------------------------------------------------------------------------

def _ply(fmt: str, comments: bytes) -> bytes:
    header = (b"ply\nformat " + fmt.encode() + b" 1.0\n" + comments
              + b"element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
              + b"element face 2\nproperty list uchar int vertex_indices\nend_header\n")
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    if fmt == "ascii":
        return header + b"0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n"
    faces = np.array([[3, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0]] * 2, np.uint8)
    faces[1, 5], faces[1, 9] = 2, 3
    return header + verts.tobytes() + faces.tobytes()


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_utf8_comments_read_like_trimesh(tmp_path, fmt):
    comments = "comment Erstellt für Café\nobj_info © 2024\ncomment plain\n".encode()
    mesh, caught, path = _load(tmp_path, "u.ply", _ply(fmt, comments))
    _assert_warning(caught, path, 2, 3, "a 'comment' or 'obj_info' line that is not ASCII")
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    _assert_same_as_trimesh(mesh, path)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_latin1_comments_read_as_without_them(tmp_path, fmt):
    """trimesh refuses latin-1 in a PLY header, so the peer reads the file without them."""
    mesh, caught, path = _load(tmp_path, "l.ply", _ply(fmt, b"comment caf\xe9\n"
                                                           b"obj_info \xa9 x\n"))
    _assert_warning(caught, path, 2, 3, "a 'comment' or 'obj_info' line that is not ASCII")
    _, _, plain = _load(tmp_path, "p.ply", _ply(fmt, b""), expect_warning=False)
    _assert_same_as_trimesh(mesh, plain)


def test_latin1_in_a_comment_after_numbers_is_skipped(tmp_path):
    content = QUADS.replace(b"v 1 0 0\n", b"v 1 0 0 # caf\xe9\n") + b"f 1 2 3 # \xe9\n"
    mesh, caught, path = _load(tmp_path, "inline.obj", content)
    _assert_warning(caught, path, 2, 2, "bytes that are not UTF-8 in a comment or a name")
    plain, _, _ = _load(tmp_path, "plain.obj", QUADS + b"f 1 2 3\n", expect_warning=False)
    assert torch.equal(mesh.verts, plain.verts) and torch.equal(mesh.faces, plain.faces)


def test_mixed_forms_resolve_negative_texture_indices(tmp_path):
    content = (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 1\nf 1//1 2//1 3//1\n"
               b"f 1/-1 2/-2 3/-1\nvt 5 5\nf -1/-1 -2/1 -3/2\nf 1 2 3\n")
    mesh, _, _ = _load(tmp_path, "neg.obj", content, expect_warning=False)
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 1, 2], [2, 1, 0], [0, 1, 2]]
    assert mesh.uv_faces.tolist() == [[-1, -1, -1], [1, 0, 1], [2, 0, 1], [-1, -1, -1]]
