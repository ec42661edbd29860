"""The malformed-file corpus: every file ``load_mesh`` must refuse, with the error expected.

Each :class:`Case` is built here, in code, so the corpus is reviewable and
regenerates exactly: ``python -m tests.mesh.malformed.make_corpus DIR`` writes the
files to ``DIR``; the tests write them to a temporary folder. ``expected`` is the
end of the message after ``"<file>, "`` (the line or element it names included):
``load_mesh`` must raise ``ValueError("<path>, <expected>")`` or, where no line
applies, ``ValueError("<path>: <expected>")``.

The first cases are the classic malformations (a ``v`` line with two
coordinates, a byte-order mark, binary garbage, faces of degree 0-2, ``3 0 1.7 2``,
``element face 3`` with one face line, OBJ index 0, ``99999999999999999999``,
``-1`` in a face, unknown property types, property before element, truncated
binary data, a 200-byte PLY declaring a billion faces).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

__all__ = ["Case", "CASES", "write_corpus", "ply_header", "TRIANGLE_OBJ"]


class Case(NamedTuple):
    name: str  # file name (its suffix picks the reader)
    content: bytes
    expected: str  # message after "<path>, " (or "<path>: " when it starts with ":")


TRIANGLE_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"
QUAD_OBJ = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n"


def ply_header(fmt: str = "ascii", n_verts: int = 3, n_faces: int = 1, count: str = "uchar",
               item: str = "int", extra: str = "") -> bytes:
    """A PLY header with float x, y, z vertices and one face list."""
    return (
        f"ply\nformat {fmt} 1.0\nelement vertex {n_verts}\nproperty float x\n"
        f"property float y\nproperty float z\n{extra}element face {n_faces}\n"
        f"property list {count} {item} vertex_indices\nend_header\n"
    ).encode()


ASCII_VERTS = b"0 0 0\n1 0 0\n0 1 0\n"  # lines 10-12 after ply_header()


def _binary_verts(n: int = 3) -> bytes:
    return np.arange(3 * n, dtype="<f4").tobytes()


def _binary_face(*idx: int, count: str = "<u1", item: str = "<i4") -> bytes:
    return np.array([len(idx)], count).tobytes() + np.array(idx, item).tobytes()


def _obj_cases() -> list[Case]:
    t, q = TRIANGLE_OBJ, QUAD_OBJ
    return [
        Case("v_two_coords.obj", b"v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n",
             "line 2: 'v' needs 3, 4, 6 or 7 values, got 2"),
        Case("v_one_coord.obj", t + b"v 5\n", "line 4: 'v' needs 3, 4, 6 or 7 values, got 1"),
        Case("v_five_values.obj", b"v 0 0 0 1 1\n", "line 1: 'v' needs 3, 4, 6 or 7 values, got 5"),
        Case("v_no_values.obj", t + b"v\n", "line 4: 'v' needs 3, 4, 6 or 7 values, got 0"),
        Case("v_letter.obj", b"v 0 x 0\n", "line 1: expected a number, got 'x'"),
        Case("v_decimal_comma.obj", t + b"v 0,5 0 0\n", "line 4: expected a number, got '0,5'"),
        Case("v_bare_sign.obj", b"v 0 - 0\n", "line 1: expected a number, got '-'"),
        Case("vt_four_values.obj", t + b"vt 0 0 0 0\n",
             "line 4: 'vt' needs 1, 2 or 3 values, got 4"),
        Case("vt_no_values.obj", t + b"vt\n", "line 4: 'vt' needs 1, 2 or 3 values, got 0"),
        Case("f_degree_two.obj", t + b"f 1 2\n", "line 4: a face needs at least 3 vertices, got 2"),
        Case("f_degree_one.obj", t + b"f 1\n", "line 4: a face needs at least 3 vertices, got 1"),
        Case("f_degree_zero.obj", t + b"f\n", "line 4: a face needs at least 3 vertices, got 0"),
        Case("f_degree_zero_spaces.obj", t + b"f   \n",
             "line 4: a face needs at least 3 vertices, got 0"),
        Case("f_index_zero.obj", t + b"f 0 1 2\n",
             "line 4: vertex index 0 (OBJ indices start at 1)"),
        Case("f_index_past_end.obj", t + b"f 1 2 4\n",
             "line 4: vertex index 4 out of range, the file has 3 vertices"),
        Case("f_negative_too_far.obj", t + b"f -4 -2 -1\n",
             "line 4: vertex index -4 out of range, the file has 3 vertices"),
        Case("f_negative_before_vertices.obj", b"f -1 -2 -3\n" + t,
             "line 1: vertex index -1 out of range, the file has 3 vertices"),
        Case("f_overflow.obj", t + b"f 1 2 99999999999999999999\n",
             "line 4: integer out of range"),
        Case("f_float_index.obj", t + b"f 1 2 3.5\n", "line 4: expected an integer, got '3.5'"),
        Case("f_letter_index.obj", t + b"f 1 2 a\n", "line 4: expected an integer, got 'a'"),
        Case("f_bare_minus.obj", t + b"f 1 2 -\n", "line 4: expected an integer, got '-'"),
        Case("f_trailing_slash.obj", t + b"f 1/ 2/ 3/\n", "line 4: malformed face corner '1/'"),
        Case("f_leading_slash.obj", t + b"vt 0 0\nf /1 2 3\n",
             "line 5: malformed face corner '/1'"),
        Case("f_three_slashes.obj", t + b"vt 0 0\nf 1///1 2 3\n",
             "line 5: malformed face corner '1///1'"),
        Case("f_some_corners_vt.obj", t + b"vt 0 0\nf 1/1 2/1 3\n",
             "line 5: face has texture indices on some corners only"),
        Case("f_vt_past_end.obj", t + b"vt 0 0\nf 1/1 2/2 3/1\n",
             "line 5: texture coordinate index 2 out of range, the file has 1 texture coordinates"),
        Case("f_vt_zero.obj", t + b"vt 0 0\nf 1/0 2/1 3/1\n",
             "line 5: texture coordinate index 0 (OBJ indices start at 1)"),
        Case("f_vt_without_vt_lines.obj", t + b"f 1/1 2/1 3/1\n",
             "line 4: texture coordinate index 1 out of range, the file has 0 texture coordinates"),
        Case("glued_keyword.obj", b"v1 2 3\n", "line 1: unknown OBJ statement 'v1' (a 'v' "
             "glued to its first number; skipping it would lose a record)"),
        Case("glued_face.obj", t + b"f1 2 3\n", "line 4: unknown OBJ statement 'f1' (a 'f'"),
        Case("glued_vt.obj", t + b"vt0.5 0\n", "line 4: unknown OBJ statement 'vt0.5' (a 'vt'"),
        Case("glued_tag.obj", t + b"t-1\n", "line 4: unknown OBJ statement 't-1' (a 't'"),
        Case("f_some_corners_vt_vn.obj", t + b"vt 0 0\nvn 0 0 1\nf 1/1/1 2//1 3/1/1\n",
             "line 6: face has texture indices on some corners only"),
        Case("f_mixed_vt_past_end.obj", t + b"vt 0 0\nf 1//1 2//1 3//1\nf 1/2 2/1 3/1\n",
             "line 6: texture coordinate index 2 out of range, the file has 1 texture coordinates"),
        Case("latin1_in_vertex.obj", t + b"v 1 2 3\xe9\n", "line 4: not valid UTF-8 text (byte "
             "0xe9)"),
        Case("latin1_in_number.obj", t + b"v 1 2\xe9 3\n", "line 4: not valid UTF-8 text"),
        Case("latin1_in_vt.obj", t + b"vt 0 \xb0\n", "line 4: not valid UTF-8 text (byte 0xb0)"),
        Case("latin1_in_vn.obj", t + b"vn 0 0 1\xe9\n", "line 4: not valid UTF-8 text"),
        Case("latin1_in_face.obj", t + b"f 1 2\xe9 3\n", "line 4: not valid UTF-8 text"),
        Case("latin1_in_face_corner.obj", t + b"vt 0 0\nf 1/1 2/\xe91 3/1\n",
             "line 5: not valid UTF-8 text"),
        Case("latin1_in_tag.obj", q + b"t crease 2/1/0 0 1 2\xe9\n",
             "line 6: not valid UTF-8 text"),
        Case("latin1_on_a_continued_face.obj", t + b"# ok\nf 1 2 \\\n3\xe9\n",
             "line 5: not valid UTF-8 text"),  # a statement's errors name its first line
        Case("utf8_in_face.obj", t + "f 1 2 3é\n".encode(), "line 4: expected an integer, got "
             "'3é'"),
        Case("utf8_in_vertex.obj", t + "v 1 2 3µ\n".encode(), "line 4: expected a number, got "
             "'3µ'"),
        Case("binary_garbage.obj", bytes(range(256)) * 4,
             "line 1: binary data (byte 0x00), not a text file"),
        Case("nul_on_line_3.obj", t[:16] + b"\x00\x01\x02\n",
             "line 3: binary data (byte 0x00), not a text file"),
        Case("utf16.obj", "v 0 0 0\n".encode("utf-16"),
             "line 1: binary data (byte 0x00), not a text file"),
        Case("crlf_error_line_3.obj", b"v 0 0 0\r\nv 1 0 0\r\nv 1\r\n",
             "line 3: 'v' needs 3, 4, 6 or 7 values, got 1"),
        Case("lone_cr_error_line_2.obj", b"v 0 0 0\rv 1\r", "line 2: 'v' needs 3, 4, 6 or 7 "
             "values, got 1"),
        Case("bom_error_line_2.obj", b"\xef\xbb\xbfv 0 0 0\nv 1 2\n",
             "line 2: 'v' needs 3, 4, 6 or 7 values, got 2"),
        Case("continuation_error.obj", b"v 0 0 \\\n0\nv 1 \\\n0\nf 1 2 3\n",
             "line 3: 'v' needs 3, 4, 6 or 7 values, got 2"),
        Case("continuation_crlf_error.obj", t + b"f 1 \\\r\n2 3\r\nf 1 2\r\n",
             "line 6: a face needs at least 3 vertices, got 2"),
        Case("comment_hides_vertex.obj", t + b"f 1 2 # 3\n",
             "line 4: a face needs at least 3 vertices, got 2"),
    ] + _tag_cases(q)


def _tag_cases(q: bytes) -> list[Case]:
    return [
        Case("tag_crease_not_edge.obj", q + b"t crease 2/1/0 0 2 1\n",
             "line 6: crease [0, 2] is not an edge of the mesh"),
        Case("tag_crease_out_of_range.obj", q + b"t crease 2/1/0 0 9 1\n",
             "line 6: crease [0, 9] out of range [0, 4)"),
        Case("tag_crease_negative.obj", q + b"t crease 2/1/0 0 1 -1\n",
             "line 6: crease sharpness must be finite and >= 0, got -1.0"),
        Case("tag_crease_nan.obj", q + b"t crease 2/1/0 0 1 nan\n",
             "line 6: crease sharpness must be finite and >= 0, got nan"),
        Case("tag_crease_odd_ints.obj", q + b"t crease 3/1/0 0 1 2 1\n",
             "line 6: tag 'crease': expected 2k ints, 1 or k floats and no strings, got 3/1/0"),
        Case("tag_crease_too_few.obj", q + b"t crease 2/1/0 0 1\n",
             "line 6: tag 'crease' 2/1/0 needs 3 values, got 2"),
        Case("tag_crease_bad_spec.obj", q + b"t crease 2/1 0 1 2\n",
             "line 6: tag 'crease': expected 'ints/floats/strings' counts, got '2/1'"),
        Case("tag_crease_float_index.obj", q + b"t crease 2/1/0 0 1.5 2\n",
             "line 6: tag arguments are not integers"),
        Case("tag_crease_text_sharpness.obj", q + b"t crease 2/1/0 0 1 sharp\n",
             "line 6: tag arguments are not numbers"),
        Case("tag_crease_twice.obj", q + b"t crease 2/1/0 0 1 1\nt crease 2/1/0 1 0 2\n",
             "line 7: crease [1, 0] tagged twice"),
        Case("tag_corner_out_of_range.obj", q + b"t corner 1/1/0 7 1\n",
             "line 6: corner [7] out of range [0, 4)"),
        Case("tag_corner_float_count.obj", q + b"t corner 2/3/0 0 1 1 1 1\n",
             "line 6: tag 'corner': expected k ints, 1 or k floats and no strings, got 2/3/0"),
        Case("tag_hole_out_of_range.obj", q + b"t hole 1/0/0 5\n",
             "line 6: hole [5] out of range [0, 1)"),
        Case("tag_hole_with_float.obj", q + b"t hole 1/1/0 0 1.0\n",
             "line 6: tag 'hole': expected n/0/0 and n face ids"),
        Case("tag_unsupported.obj", q + b"t vertexedit 1/0/0 0\n",
             "line 6: unsupported tag 'vertexedit'"),
        Case("tag_boundary_code.obj", q + b"t interpolateboundary 1/0/0 7\n",
             "line 6: tag 'interpolateboundary': expected 1/0/0 and an integer in [0, 3)"),
        Case("tag_boundary_twice.obj",
             q + b"t interpolateboundary 1/0/0 1\nt interpolateboundary 1/0/0 2\n",
             "line 7: tag 'interpolateboundary' given twice"),
        Case("tag_creasemethod_word.obj", q + b"t creasemethod 0/0/1 sharp\n",
             "line 6: tag 'creasemethod': expected 0/0/1 and one of ['chaikin', 'normal']"),
        Case("tag_name_only.obj", q + b"t crease\n",
             "line 6: a tag needs a name and an 'ints/floats/strings' count"),
        Case("tag_empty.obj", q + b"t\n",
             "line 6: a tag needs a name and an 'ints/floats/strings' count"),
    ]


def _ply_ascii_cases() -> list[Case]:
    h = ply_header()
    return [
        Case("ply_float_in_face.ply", h + ASCII_VERTS + b"3 0 1.7 2\n",
             "line 13: vertex_indices: expected a int32, got 1.7"),
        Case("ply_face_count_short.ply", ply_header(n_faces=3) + ASCII_VERTS + b"3 0 1 2\n",
             "line 7: element 'face' declares 3 records, but only 1 non-blank lines are left "
             "for it"),
        Case("ply_minus_one.ply", h + ASCII_VERTS + b"3 0 -1 2\n",
             "line 13: face 0 has vertex index -1, out of range [0, 3)"),
        Case("ply_index_past_end.ply", h + ASCII_VERTS + b"3 0 1 3\n",
             "line 13: face 0 has vertex index 3, out of range [0, 3)"),
        Case("ply_index_overflow.ply", h + ASCII_VERTS + b"3 0 1 99999999999999999999\n",
             "line 13: vertex_indices: expected a int32, got 1e+20"),
        Case("ply_count_overflow.ply", h + ASCII_VERTS + b"300 0 1 2\n",
             "line 13: list count: expected a uint8, got 300.0"),
        Case("ply_face_degree_two.ply", h + ASCII_VERTS + b"2 0 1\n",
             "line 13: face 0 has 2 vertices; a face needs at least 3"),
        Case("ply_face_degree_zero.ply", h + ASCII_VERTS + b"0\n",
             "line 13: face 0 has 0 vertices; a face needs at least 3"),
        Case("ply_face_list_short.ply", h + ASCII_VERTS + b"4 0 1 2\n",
             "line 13: element 'face': the list holds 4 values, so the line needs 5 values, got 4"),
        Case("ply_vertex_two_values.ply", h + b"0 0 0\n1 0\n0 1 0\n3 0 1 2\n",
             "line 11: element 'vertex': expected 3 values, got 2"),
        Case("ply_vertex_letter.ply", h + b"0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n",
             "line 11: expected a number, got 'x'"),
        Case("ply_extra_line.ply", h + ASCII_VERTS + b"3 0 1 2\n3 0 1 2\n",
             "line 14: extra line after the 4 declared records"),
        Case("ply_huge_vertex_count_ascii.ply", ply_header(n_verts=10**9) + ASCII_VERTS,
             "line 3: element 'vertex' declares 1000000000 records, but only 3 non-blank lines "
             "are left for it"),
        Case("ply_unknown_type.ply", ply_header(extra="property float128 w\n") + ASCII_VERTS,
             "line 7: unknown property type 'float128'"),
        Case("ply_property_before_element.ply",
             b"ply\nformat ascii 1.0\nproperty float x\nelement vertex 0\nend_header\n",
             "line 3: 'property' before any 'element'"),
        Case("ply_no_magic.ply", b"PLY\nformat ascii 1.0\nend_header\n",
             "line 1: not a PLY file (the first line must read 'ply')"),
        Case("ply_binary_garbage.ply", bytes(range(256)) * 4,
             "line 1: not a PLY file (the first line must read 'ply')"),
        Case("ply_no_end_header.ply", b"ply\nformat ascii 1.0\nelement vertex 0\n",
             ": no 'end_header' line"),
        Case("ply_end_header_in_comment_only.ply",
             b"ply\nformat ascii 1.0\ncomment see end_header\nelement vertex 0\n",
             ": no 'end_header' line"),
        Case("ply_no_format.ply", b"ply\nelement vertex 0\nproperty float x\nend_header\n",
             "line 4: no 'format' line before 'end_header'"),
        Case("ply_format_twice.ply", b"ply\nformat ascii 1.0\nformat ascii 1.0\nend_header\n",
             "line 3: expected one 'format ascii|binary_little_endian|binary_big_endian 1.0' "
             "line before the elements"),
        Case("ply_version_2.ply", b"ply\nformat ascii 2.0\nend_header\n",
             "line 2: unsupported PLY version '2.0'"),
        Case("ply_negative_count.ply", b"ply\nformat ascii 1.0\nelement vertex -3\nend_header\n",
             "line 3: expected 'element <name> <count>'"),
        Case("ply_element_twice.ply",
             b"ply\nformat ascii 1.0\nelement vertex 0\nelement vertex 0\nend_header\n",
             "line 4: element 'vertex' declared twice"),
        Case("ply_unknown_header_line.ply", b"ply\nformat ascii 1.0\nfoo bar\nend_header\n",
             "line 3: unknown header line 'foo bar'"),
        Case("ply_float_list_count.ply", ply_header(count="float"),
             "line 8: list count type must be an integer, got 'float'"),
        Case("ply_two_lists.ply", ply_header(extra="") .replace(
             b"end_header", b"property list uchar int more\nend_header"),
             "line 9: an element with two list properties is not supported"),
        Case("ply_no_vertex.ply", b"ply\nformat ascii 1.0\nelement point 1\nproperty float x\n"
             b"end_header\n1\n", ": no 'vertex' element"),
        Case("ply_vertex_without_z.ply", b"ply\nformat ascii 1.0\nelement vertex 1\n"
             b"property float x\nproperty float y\nend_header\n1 2\n",
             "line 3: 'vertex' lacks properties ['z']"),
        Case("ply_face_without_list.ply", b"ply\nformat ascii 1.0\nelement vertex 0\n"
             b"property float x\nproperty float y\nproperty float z\nelement face 0\n"
             b"property int a\nend_header\n",
             "line 7: 'face' needs an integer list property 'vertex_indices'"),
        Case("ply_header_not_ascii.ply", b"ply\nformat ascii 1.0\nelement vert\xe9x 0\n"
             b"end_header\n", "line 3: the header is not ASCII text"),
        Case("ply_header_utf8_property.ply", ply_header(extra="property float é\n"),
             "line 7: the header is not ASCII text"),
        Case("ply_ascii_body_latin1.ply",
             ply_header(extra="comment café\n") + ASCII_VERTS + b"3 0 1 2\xe9\n",
             "line 14: not valid UTF-8 text"),
        Case("ply_ascii_body_binary.ply", h + ASCII_VERTS + b"3 0 1 \x00\n",
             "line 13: binary data (byte 0x00), not a text file"),
    ]


def _ply_binary_cases() -> list[Case]:
    le = "binary_little_endian"
    h = ply_header(le)
    tri = _binary_face(0, 1, 2)
    mixed = ply_header(le, n_verts=4, n_faces=2) + _binary_verts(4)
    return [
        Case("ply_billion_faces.ply", ply_header(le, n_verts=1, n_faces=10**9)
             + _binary_verts(1) + tri,
             "line 7: element 'face' declares 1000000000 records needing at least 1000000000 "
             "bytes, but only 13 bytes follow"),
        Case("ply_truncated_vertices.ply", h + _binary_verts(3)[:30],
             "line 3: element 'vertex' declares 3 records needing at least 36 bytes, but only "
             "30 bytes follow"),
        Case("ply_truncated_faces.ply", h + _binary_verts(3) + tri[:9],
             ": element 'face' record 0: truncated: the record runs past the end of the file"),
        Case("ply_truncated_mixed_faces.ply", mixed + _binary_face(0, 1, 2, 3) + tri[:10],
             ": element 'face' record 1: truncated: the record runs past the end of the file"),
        Case("ply_trailing_bytes.ply", h + _binary_verts(3) + tri + b"\n\n\n\n",
             ": 4 bytes after the last element"),
        Case("ply_binary_index_past_end.ply", h + _binary_verts(3) + _binary_face(0, 1, 7),
             ": element 'face' record 0: face 0 has vertex index 7, out of range [0, 3)"),
        Case("ply_binary_minus_one.ply", h + _binary_verts(3) + _binary_face(0, -1, 2),
             ": element 'face' record 0: face 0 has vertex index -1, out of range [0, 3)"),
        Case("ply_binary_degree_two.ply", ply_header(le, n_faces=2) + _binary_verts(3)
             + _binary_face(0, 1) + _binary_face(0, 1, 2),
             ": element 'face' record 0: face 0 has 2 vertices; a face needs at least 3"),
        Case("ply_binary_negative_count.ply", ply_header(le, count="char", n_faces=2)
             + _binary_verts(3) + _binary_face(0, 1, 2, count="<i1") + b"\xff",
             ": element 'face' record 1: negative list count -1"),
        Case("ply_big_endian_past_end.ply", ply_header("binary_big_endian")
             + np.arange(9, dtype=">f4").tobytes() + _binary_face(0, 1, 5, item=">i4"),
             ": element 'face' record 0: face 0 has vertex index 5, out of range [0, 3)"),
    ]


def _off_cases() -> list[Case]:
    v = b"0 0 0\n1 0 0\n0 1 0\n"  # lines 3-5 after b"OFF\n3 1 0\n"
    h = b"OFF\n3 1 0\n"
    return [
        Case("off_coff.off", b"COFF\n3 1 0\n" + v + b"3 0 1 2\n",
             "line 1: expected 'OFF', got 'COFF'"),
        Case("off_empty.off", b"", ": empty file, expected 'OFF'"),
        Case("off_no_counts.off", b"OFF\n", ": no 'V F E' counts line"),
        Case("off_letter_count.off", b"OFF\n3 x 0\n", "line 2: expected a number, got 'x'"),
        Case("off_negative_count.off", b"OFF\n-3 1 0\n" + v,
             "line 2: expected the counts 'V F E' (non-negative integers)"),
        Case("off_faces_short.off", b"OFF\n3 2 0\n" + v + b"3 0 1 2\n",
             "line 2: the counts declare 3 vertices and 2 faces, but only 4 non-blank lines "
             "follow"),
        Case("off_billion_vertices.off", b"OFF\n1000000000 1 0\n0 0 0\n",
             "line 2: the counts declare 1000000000 vertices and 1 faces, but only 1 non-blank "
             "lines follow"),
        Case("off_extra_line.off", h + v + b"3 0 1 2\n3 0 1 2\n",
             "line 7: extra line after the 4 declared records"),
        Case("off_vertex_two_values.off", h + b"0 0 0\n1 0\n0 1 0\n3 0 1 2\n",
             "line 4: a vertex needs 3 values, got 2"),
        Case("off_face_degree_two.off", b"OFF\n3 1 0\n" + v + b"2 0 1\n",
             "line 6: a face needs at least 3 vertices, got 2"),
        Case("off_face_short.off", h + v + b"4 0 1 2\n",
             "line 6: a face of 4 vertices needs 5 values (+ 3 or 4 colour values), got 4"),
        Case("off_index_past_end.off", h + v + b"3 0 1 3\n",
             "line 6: vertex index 3 is not an integer in [0, 3)"),
        Case("off_index_float.off", h + v + b"3 0 1.5 2\n",
             "line 6: vertex index 1.5 is not an integer in [0, 3)"),
        Case("off_index_minus_one.off", h + v + b"3 0 -1 2\n",
             "line 6: vertex index -1 is not an integer in [0, 3)"),
        Case("off_degree_float.off", h + v + b"3.5 0 1 2\n",
             "line 6: the vertex count of a face must be an integer, got 3.5"),
        Case("off_binary_garbage.off", bytes(range(256)) * 4,
             "line 1: binary data (byte 0x00), not a text file"),
    ]


CASES: list[Case] = _obj_cases() + _ply_ascii_cases() + _ply_binary_cases() + _off_cases()


def write_corpus(directory: str | Path) -> list[Path]:
    """Write every case of :data:`CASES` into ``directory``; returns the paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for case in CASES:  # test data generation, a few dozen files
        path = directory / case.name
        path.write_bytes(case.content)
        paths.append(path)
    return paths


if __name__ == "__main__":
    print(len(write_corpus(sys.argv[1] if len(sys.argv) > 1 else "malformed_corpus")))
