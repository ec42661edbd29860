"""Object File Format (OFF): vertex positions and polygon faces of any size.

Convention:
    - The first statement is ``OFF`` (optionally followed by the counts on the same
      line), then ``V F [E]``, then ``V`` lines ``x y z`` and ``F`` lines
      ``n i0 .. i(n-1)`` (0-based), optionally followed by an RGB or RGBA face
      colour (read and dropped). One record per line; ``#`` starts a comment;
      blank lines are skipped. Other variants (``COFF``, ``NOFF``, ``4OFF``, ...)
      are refused rather than misread.
    - Counts are checked against the lines present before anything is read.
    - Errors name the file and the line.
"""

from __future__ import annotations

import numpy as np

from torchgeo_cg.mesh.io._text import (
    TextLines,
    blank_comments,
    check_padding,
    file_error,
    first_chars,
    format_faces,
    format_rows,
    gather_lines,
    line_tokens,
    parse_numbers,
    read_text,
)

__all__: list[str] = []


def _line_numbers(text: TextLines, line: int) -> np.ndarray:
    blob, segs = gather_lines(text, np.array([line]), text.starts[[line]])
    tokens = line_tokens(blob, segs)
    return parse_numbers(text, np.array([line]), blob, segs, tokens, np.float64)


def _counts(text: TextLines, records: np.ndarray) -> tuple[int, int, int]:
    """Parse the ``OFF`` and ``V F E`` statements; returns ``(V, F, first record line)``."""
    if records.size == 0:
        raise file_error(text.name, None, "empty file, expected 'OFF'")
    head = records[0]
    start = int(first_chars(text)[head])
    word = bytes(text.buf[start : text.ends[head]]).split()
    if word[0] != b"OFF":
        raise file_error(text.name, text.numbers[head],
                         f"expected 'OFF', got {word[0].decode(errors='replace')[:20]!r}")
    text.buf[start : start + 3] = 32
    at = 0 if len(word) > 1 else 1
    if at >= len(records):
        raise file_error(text.name, None, "no 'V F E' counts line")
    counts = _line_numbers(text, records[at])
    bad = len(counts) not in (2, 3) or (counts < 0).any() or (counts != np.floor(counts)).any()
    if bad:
        raise file_error(text.name, text.numbers[records[at]],
                         "expected the counts 'V F E' (non-negative integers)")
    return int(counts[0]), int(counts[1]), at + 1


def _faces(text, lines, num_vertices):
    blob, segs = gather_lines(text, lines, text.starts[lines])
    tokens = line_tokens(blob, segs)
    values = parse_numbers(text, lines, blob, segs, tokens, np.float64)
    first = np.cumsum(tokens.counts) - tokens.counts
    degrees_f = values[first] if len(lines) else np.zeros(0)
    bad = (degrees_f != np.floor(degrees_f)) | (np.abs(degrees_f) > 2**31)
    if bad.any():
        i = int(np.argmax(bad))
        raise file_error(text.name, text.numbers[lines[i]],
                         "the vertex count of a face must be an integer, "
                         f"got {float(degrees_f[i])!r}")
    degrees = degrees_f.astype(np.int64)
    extra = tokens.counts - 1 - degrees
    bad = (degrees < 3) | ~np.isin(extra, (0, 3, 4))
    if bad.any():
        i = int(np.argmax(bad))
        msg = (f"a face needs at least 3 vertices, got {degrees[i]}" if degrees[i] < 3 else
               f"a face of {degrees[i]} vertices needs {degrees[i] + 1} values (+ 3 or 4 "
               f"colour values), got {tokens.counts[i]}")
        raise file_error(text.name, text.numbers[lines[i]], msg)
    longest = text.numbers[lines[int(np.argmax(degrees))]] if degrees.size else None
    width = check_padding(text.name, longest, degrees, len(text.buf))
    valid = np.arange(width) < degrees[:, None]
    idx = np.where(valid, values[np.where(valid, first[:, None] + 1 + np.arange(width), 0)], -1)
    bad_f = ((idx != np.floor(idx)) | (idx < -1) | (idx >= num_vertices)
             | ((idx == -1) & valid)).any(1)
    if bad_f.any():
        i = int(np.argmax(bad_f))
        row = idx[i][valid[i]]
        wrong = row[(row != np.floor(row)) | (row < 0) | (row >= num_vertices)][0]
        raise file_error(text.name, text.numbers[lines[i]],
                         f"vertex index {float(wrong):g} is not an integer in [0, {num_vertices})")
    return idx.astype(np.int64)


def read_off(data: bytes, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(verts (V, 3) float64, faces (F, K) int64 padded with -1)`` of an OFF file.

    Example:
        >>> text = b"OFF\\n# a triangle\\n3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n"
        >>> v, f = read_off(text, "t.off")
        >>> v.shape, f.tolist()
        ((3, 3), [[0, 1, 2]])
    """
    text = read_text(data, name)
    if b"#" in data:
        blank_comments(text)
    records = np.flatnonzero(text.buf[first_chars(text)] != 10)
    num_vertices, n_faces, row = _counts(text, records)
    left = len(records) - row
    if num_vertices + n_faces > left:
        raise file_error(text.name, text.numbers[records[row - 1]],
                         f"the counts declare {num_vertices} vertices and {n_faces} faces, "
                         f"but only "
                         f"{left} non-blank lines follow")
    if num_vertices + n_faces < left:
        raise file_error(text.name, text.numbers[records[row + num_vertices + n_faces]],
                         f"extra line after the {num_vertices + n_faces} declared records")
    lines = records[row : row + num_vertices]
    blob, segs = gather_lines(text, lines, text.starts[lines])
    tokens = line_tokens(blob, segs)
    bad = tokens.counts != 3
    if bad.any():
        i = int(np.argmax(bad))
        raise file_error(text.name, text.numbers[lines[i]],
                         f"a vertex needs 3 values, got {tokens.counts[i]}")
    verts = parse_numbers(text, lines, blob, segs, tokens, np.float64).reshape(-1, 3)
    faces = _faces(text, records[row + num_vertices :], num_vertices)
    return verts, faces if faces.shape[1] else faces.reshape(0, 3)


def format_off(verts_v3: np.ndarray, faces_fk: np.ndarray, precision: int) -> str:
    """OFF text: ``OFF``, ``V F 0``, one ``x y z`` line per vertex, one ``n i..`` per face.

    Example:
        >>> print(format_off(np.eye(3), np.array([[0, 1, 2]]), 9), end="")
        OFF
        3 1 0
        1 0 0
        0 1 0
        0 0 1
        3 0 1 2
    """
    faces = format_faces("", faces_fk, 0, count=True)
    verts = format_rows("", verts_v3, precision)
    return f"OFF\n{len(verts_v3)} {len(faces_fk)} 0\n" + verts + faces
