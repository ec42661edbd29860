"""Text mesh files (OBJ, ASCII PLY, OFF) as numpy byte arrays, with line-exact errors.

The whole file is handled as one ``uint8`` array: lines are found with one
vectorized search for ``\\n``, the lines of one kind are gathered into one blob
and their numbers are converted in bulk (``np.fromstring``). Only when a bulk
check fails is the offending line looked for, so every error names the file and
the line while the hot path has no Python loop over lines.

Convention:
    - Lines are numbered from 1 as a text editor shows them (physical lines): a
      line joined to the next by a trailing backslash keeps its own number, and
      the lines after it keep theirs.
    - A UTF-8 byte-order mark is skipped; ``\\r\\n`` and a lone ``\\r`` end a line.
    - Bytes below 0x20 other than tab, ``\\n``, ``\\r``, ``\\v`` and ``\\f`` mean
      binary data and raise. Non-ASCII bytes must be valid UTF-8 (else an error),
      unless the reader asks for the offsets of the invalid ones (``strict=False``,
      OBJ) to decide line by line: they may stand only where nothing is read.
    - Every error is a ``ValueError`` reading ``"<file>, line <n>: <what>"``; what is
      skipped because it cannot change positions or faces is reported by one
      :class:`MeshFileWarning` per file (:func:`skipped_message`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__: list[str] = []

_BOM = b"\xef\xbb\xbf"
_INT64 = np.iinfo(np.int64)


class MeshFileWarning(UserWarning):
    """A mesh file held lines (or parts of lines) that cannot change positions or faces
    and that the format does not allow, and they were skipped."""


def skipped_message(name: str, numbers: np.ndarray, first: str) -> str | None:
    """The one warning text for the physical lines ``numbers`` skipped in file ``name``.

    Args:
        name: the file name.
        numbers: ``(S,)`` physical line numbers, increasing (``S = 0``: nothing skipped).
        first: what was skipped on the first of them.

    Returns:
        The message, or ``None`` when nothing was skipped.

    Example:
        >>> print(skipped_message("m.obj", np.array([4, 9]), "unknown OBJ statement 'vx'"))
        m.obj: skipped what cannot change positions or faces on 2 lines; the first, line 4: \
unknown OBJ statement 'vx'
    """
    if numbers.size == 0:
        return None
    count = f"{numbers.size} line{'s' if numbers.size > 1 else ''}"
    return (f"{name}: skipped what cannot change positions or faces on {count}; the first, "
            f"line {int(numbers[0])}: {first}")


def file_error(name: str, line: int | None, message: str) -> ValueError:
    """The ``ValueError`` for a malformed file: ``"<name>, line <line>: <message>"``.

    Example:
        >>> print(file_error("m.obj", 3, "'v' needs 3 coordinates, got 2"))
        m.obj, line 3: 'v' needs 3 coordinates, got 2
    """
    where = name if line is None else f"{name}, line {int(line)}"
    return ValueError(f"{where}: {message}")


class TextLines(NamedTuple):
    """A text file split into lines, all arrays ``(L,)`` over its ``L`` lines.

    Attributes:
        name: the file name used in error messages.
        buf: ``(N,)`` uint8, a private writable copy of the text, ending with ``\\n``
            (continuations and ``\\r`` already replaced, byte offsets unchanged).
        starts: ``(L,)`` int64, offset of each line's first byte.
        ends: ``(L,)`` int64, offset of each line's ``\\n``.
        numbers: ``(L,)`` int64, the physical line number of each line (1-based).
        invalid: ``(B,)`` int64 offsets in ``buf`` of the bytes that are not valid
            UTF-8 (``read_text(strict=False)`` only; else ``None``).
    """

    name: str
    buf: np.ndarray
    starts: np.ndarray
    ends: np.ndarray
    numbers: np.ndarray
    invalid: np.ndarray | None = None

    def line_number_at(self, offset: int) -> int:
        """The physical line number holding byte ``offset`` of ``buf``."""
        line = int(np.searchsorted(self.ends, offset, side="left"))
        return int(self.numbers[min(line, len(self.numbers) - 1)])


def invalid_utf8(raw: bytes) -> np.ndarray:
    """``(B,)`` int64 byte offsets of the bytes of ``raw`` that are not valid UTF-8.

    Python's decoder decides: each byte it cannot decode becomes one escaped code
    point (U+DC80..U+DCFF, which valid UTF-8 never yields), so one decode, one
    UTF-32 view and one cumulative sum of the code points' UTF-8 sizes find them all.

    Example:
        >>> invalid_utf8("é-".encode() + b"caf\\xe9 \\xff").tolist()
        [6, 8]
    """
    code = np.frombuffer(raw.decode("utf-8", "surrogateescape").encode(
        "utf-32-le", "surrogatepass"), np.uint32)
    escaped = (code >= 0xDC80) & (code <= 0xDCFF)
    size = 1 + (code >= 0x80).astype(np.int64) + (code >= 0x800) + (code >= 0x10000)
    size[escaped] = 1
    return (np.cumsum(size) - size)[escaped]


def _check_bytes(buf: np.ndarray, raw: bytes, name: str, first_line: int, strict: bool = True
                 ) -> np.ndarray | None:
    """Refuse binary data (control bytes) and, if ``strict``, invalid UTF-8, naming the line;
    else return the offsets of the bytes that are not valid UTF-8."""
    control = (buf < 9) | ((buf > 13) & (buf < 32))
    if control.any():
        at = int(np.argmax(control))
        line = first_line + int(np.count_nonzero(buf[:at] == 10))
        raise file_error(name, line, f"binary data (byte 0x{int(buf[at]):02x}), not a text file")
    if raw.isascii():
        return None if strict else np.zeros(0, np.int64)
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError as err:
        if not strict:
            return invalid_utf8(raw)
        line = first_line + raw.count(b"\n", 0, err.start)
        raise file_error(name, line, f"not valid UTF-8 text ({err.reason})") from None
    return None if strict else np.zeros(0, np.int64)


def _join_continuations(buf: np.ndarray) -> np.ndarray:
    """Blank ``\\`` + line break pairs in place; return the offsets of the joined ``\\n``."""
    slash = np.flatnonzero(buf[:-1] == 92)
    nxt = buf[slash + 1]
    crlf = (nxt == 13) & (buf[np.minimum(slash + 2, len(buf) - 1)] == 10)
    cont = (nxt == 10) | crlf
    slash, crlf = slash[cont], crlf[cont]
    newline = slash + 1 + crlf
    buf[slash] = 32
    buf[slash + 1] = 32
    buf[newline] = 32
    return newline


def read_text(
    data: bytes, name: str, offset: int = 0, first_line: int = 1, continuations: bool = False,
    strict: bool = True,
) -> TextLines:
    """Split ``data[offset:]`` into lines after checking that it is text.

    Args:
        data: the raw file bytes.
        name: file name for the error messages.
        offset: where the text starts (a PLY body); a BOM there is skipped.
        first_line: the physical line number of the first line.
        continuations: join a line ending with ``\\`` to the next (OBJ).
        strict: refuse bytes that are not valid UTF-8; ``False``: keep them and give
            their offsets in ``TextLines.invalid`` (the caller checks where they stand).

    Returns:
        :class:`TextLines`.

    Raises:
        ValueError: binary data or (``strict``) invalid UTF-8, naming the line.

    Example:
        >>> raw = b"\\xef\\xbb\\xbfv 1 2 3\\r\\nf 1 \\\\\\n 2 3"
        >>> t = read_text(raw, "m.obj", continuations=True)
        >>> t.numbers.tolist(), bytes(t.buf[t.starts[1]:t.ends[1]])
        ([1, 2], b'f 1    2 3')
    """
    if data.startswith(_BOM, offset):
        offset += len(_BOM)
    raw = data[offset:]
    buf = np.frombuffer(raw, dtype=np.uint8)
    invalid = _check_bytes(buf, raw, name, first_line, strict)
    buf = np.concatenate([buf, np.full(1 if not raw.endswith(b"\n") else 0, 10, np.uint8)])
    joined = np.zeros(0, dtype=np.int64)
    if continuations and b"\\" in raw:
        joined = _join_continuations(buf)
    if b"\r" in raw:
        cr = np.flatnonzero(buf == 13)
        buf[cr] = np.where(buf[cr + 1] == 10, 32, 10)  # "\r\n" -> " \n", lone "\r" -> "\n"
    if buf[-1] != 10:  # a continuation joined the last line break
        buf = np.concatenate([buf, np.full(1, 10, np.uint8)])
    ends = np.flatnonzero(buf == 10)
    starts = np.concatenate([[0], ends[:-1] + 1])
    numbers = first_line + np.arange(len(ends)) + np.searchsorted(joined, starts)
    return TextLines(name, buf, starts, ends, numbers, invalid)


def blank_comments(text: TextLines, marker: int = 35) -> None:
    r"""Blank, in place, every byte from a ``#`` (``marker``) to the end of its line.

    Example:
        >>> t = read_text(b"v 1 2 3 # a # b\n# c\n", "m.obj")
        >>> blank_comments(t)
        >>> bytes(t.buf)
        b'v 1 2 3        \n   \n'
    """
    hashes = np.flatnonzero(text.buf == marker)
    if hashes.size == 0:
        return
    line = np.searchsorted(text.ends, hashes)
    first = np.concatenate([[True], line[1:] != line[:-1]])
    delta = np.zeros(len(text.buf) + 1, dtype=np.int8)
    delta[hashes[first]] += 1
    delta[text.ends[line[first]]] -= 1
    text.buf[np.cumsum(delta[:-1], dtype=np.int8).view(bool)] = 32


def first_chars(text: TextLines) -> np.ndarray:
    r"""``(L,)`` int64 offset of each line's first non-blank byte (its ``\n`` if blank).

    Example:
        >>> first_chars(read_text(b"v 1\n  \tf 1\n\n", "m.obj")).tolist()
        [0, 7, 11]
    """
    buf, pos = text.buf, text.starts.copy()
    c = buf[pos]
    lead = np.flatnonzero((c == 32) | (c == 9) | (c == 11) | (c == 12))
    while lead.size:  # loop over the depth of leading blanks, not over lines
        pos[lead] += 1
        c = buf[pos[lead]]
        lead = lead[(c == 32) | (c == 9) | (c == 11) | (c == 12)]
    return pos


def chars_at(text: TextLines, pos: np.ndarray, width: int) -> np.ndarray:
    r"""``(M, width)`` uint8 bytes from each offset ``pos``, stopped at the first blank (0 after).

    Example:
        >>> t = read_text(b"usemtl x\nvt 0 0\n", "m.obj")
        >>> chars_at(t, first_chars(t), 8).view("S8").ravel().tolist()
        [b'usemtl', b'vt']
    """
    cols = np.minimum(pos[:, None] + np.arange(width), len(text.buf) - 1)
    chars = text.buf[cols]
    return np.where(np.cumsum(chars <= 32, axis=1) > 0, 0, chars).astype(np.uint8)


def gather_lines(text: TextLines, lines: np.ndarray, begin: np.ndarray) -> tuple:
    r"""One blob holding bytes ``begin[i] .. ends[lines[i]]`` (its ``\n`` included) of each line.

    Args:
        text: the file.
        lines: ``(M,)`` increasing line indices.
        begin: ``(M,)`` first offset to keep on each line (after its keyword).

    Returns:
        ``(blob (B,) uint8, seg_starts (M,) int64)``, a view when the lines are
        consecutive and ``begin`` is their start (the usual OBJ/PLY block).

    Example:
        >>> t = read_text(b"1 2\n# x\n3 4\n", "m.txt")
        >>> blob, segs = gather_lines(t, np.array([0, 2]), t.starts[[0, 2]])
        >>> bytes(blob), segs.tolist()
        (b'1 2\n3 4\n', [0, 4])
    """
    ends = text.ends[lines] + 1
    if lines.size == 0:
        return np.zeros(0, np.uint8), np.zeros(0, np.int64)
    contiguous = lines[-1] - lines[0] + 1 == lines.size and (begin == text.starts[lines]).all()
    if contiguous:
        return text.buf[begin[0] : ends[-1]], begin - begin[0]
    delta = np.zeros(len(text.buf) + 1, dtype=np.int8)
    delta[begin] += 1
    delta[ends] -= 1
    keep = np.cumsum(delta[:-1], dtype=np.int8).view(bool)
    lengths = ends - begin
    return text.buf[keep], np.concatenate([[0], np.cumsum(lengths)[:-1]])


class LineTokens(NamedTuple):
    """Blank-separated tokens of gathered lines.

    Attributes:
        counts: ``(M,)`` int64, tokens on each line.
        starts: ``(T,)`` int64, offset in the blob of each token's first byte.
    """

    counts: np.ndarray
    starts: np.ndarray

    def line(self) -> np.ndarray:
        """``(T,)`` int64, the gathered line (``0 .. M-1``) of each token."""
        return np.repeat(np.arange(len(self.counts)), self.counts)


def line_tokens(blob: np.ndarray, seg_starts: np.ndarray) -> LineTokens:
    r"""Tokens of the lines gathered in ``blob`` (see :func:`gather_lines`), vectorized.

    Example:
        >>> tok = line_tokens(np.frombuffer(b" 1 22\n\n333\n", np.uint8), np.array([0, 6, 7]))
        >>> tok.counts.tolist(), tok.starts.tolist(), tok.line().tolist()
        ([2, 0, 1], [1, 3, 7], [0, 0, 2])
    """
    if blob.size == 0:
        return LineTokens(np.zeros(len(seg_starts), np.int64), np.zeros(0, np.int64))
    blank = blob <= 32
    start_mask = ~blank
    start_mask[1:] &= blank[:-1]
    starts = np.flatnonzero(start_mask)
    bounds = np.searchsorted(starts, np.append(seg_starts, len(blob)))
    return LineTokens(np.diff(bounds), starts)


def _first_bad_line(blob, seg_starts, counts, dtype) -> tuple[int, str]:
    """Error path only: the first gathered line whose numbers do not parse."""
    bounds = np.append(seg_starts, len(blob))
    for i in range(len(seg_starts)):  # runs only after a bulk parse failed
        seg = blob[bounds[i] : bounds[i + 1]].tobytes()
        tokens = seg.split()
        kind = "an integer" if dtype == np.int64 else "a number"
        for tok in tokens:
            if tok in (b"-", b"+"):
                return i, f"expected {kind}, got {tok.decode(errors='replace')!r}"
            try:
                got = np.fromstring(tok, dtype=dtype, sep=" ")
            except ValueError:
                got = ()
            if len(got) != 1:
                return i, f"expected {kind}, got {tok.decode(errors='replace')!r}"
    return 0, "could not read the numbers"  # pragma: no cover - the bulk parse disagreed


def parse_numbers(
    text: TextLines, lines: np.ndarray, blob: np.ndarray, seg_starts: np.ndarray,
    tokens: LineTokens, dtype=np.float64,
) -> np.ndarray:
    r"""All tokens of the gathered lines as one flat ``float64`` or ``int64`` array.

    Raises:
        ValueError: a token is not a number (or an integer out of the int64 range),
            naming the file and its line.

    Example:
        >>> t = read_text(b"1 2\n3 x\n", "m.txt")
        >>> lines = np.arange(2)
        >>> blob, segs = gather_lines(t, lines, t.starts)
        >>> parse_numbers(t, lines, blob, segs, line_tokens(blob, segs))
        Traceback (most recent call last):
        ...
        ValueError: m.txt, line 2: expected a number, got 'x'
    """
    total = int(tokens.counts.sum())
    if total == 0:
        return np.zeros(0, dtype=dtype)
    bare_sign = False
    if dtype == np.int64:  # numpy reads a bare "-" as the integer 0
        signs = np.flatnonzero((blob == 45) | (blob == 43))
        bare_sign = signs.size and (blob[np.minimum(signs + 1, len(blob) - 1)] <= 32).any()
    values = None
    if not bare_sign:
        try:
            values = np.fromstring(blob.tobytes(), dtype=dtype, sep=" ")
        except ValueError:
            values = None
    if values is None or len(values) != total:
        i, message = _first_bad_line(blob, seg_starts, tokens.counts, dtype)
        raise file_error(text.name, text.numbers[lines[i]], message)
    if dtype == np.int64 and (values.max() == _INT64.max or values.min() == _INT64.min):
        clipped = (values == _INT64.max) | (values == _INT64.min)
        if clipped.any():
            line = text.numbers[lines[tokens.line()[int(np.argmax(clipped))]]]
            raise file_error(text.name, line, "integer out of range")
    return values


def format_rows(prefix: str, values: np.ndarray, precision: int | None = None) -> str:
    """One text line per row of ``values``: ``prefix`` then the row's numbers.

    One ``%`` formatting call for the whole array (no Python loop over rows).

    Args:
        prefix: start of every line (``"v"``, or ``""`` for none).
        values: ``(N, C)`` array; floats are written with ``precision`` significant digits,
            integers exactly (``precision=None``).
        precision: significant digits (17 round-trips float64, 9 float32).

    Example:
        >>> print(format_rows("v", np.array([[0.5, 1, 2], [3, 4, 1/3]]), 9), end="")
        v 0.5 1 2
        v 3 4 0.333333333
    """
    if len(values) == 0:
        return ""
    fmt = "%d" if precision is None else f"%.{precision}g"
    row = (prefix + " " if prefix else "") + " ".join([fmt] * values.shape[1]) + "\n"
    return (row * len(values)) % tuple(values.ravel().tolist())


def format_faces(prefix: str, faces_fk: np.ndarray, offset: int, uv_faces_fk=None,
                 count: bool = False) -> str:
    """One line per padded face: ``prefix``, optionally its size, then its indices + ``offset``.

    Args:
        prefix: ``"f"`` (OBJ) or ``""``.
        faces_fk: ``(F, K)`` int, padded with ``-1``.
        offset: added to every index (1 for OBJ).
        uv_faces_fk: ``(F, K)`` int padded like ``faces_fk``: corners written ``v/vt``;
            a face with ``-1`` on every corner is written with ``v`` corners.
        count: write the face size first (PLY, OFF).

    Example:
        >>> print(format_faces("f", np.array([[0, 1, 2, 3], [1, 4, 2, -1]]), 1,
        ...                    np.array([[0, 1, 2, 3], [-1, -1, -1, -1]])), end="")
        f 1/1 2/2 3/3 4/4
        f 2 5 3
    """
    if len(faces_fk) == 0:
        return ""
    valid_fk = faces_fk >= 0
    sizes_f = valid_fk.sum(1)
    head = [prefix + (" " if prefix and count else "") + (str(k) if count else "")
            for k in range(faces_fk.shape[1] + 1)]  # one template per face size
    templates = [h + " %d" * k + "\n" for k, h in enumerate(head)]
    values = faces_fk[valid_fk] + offset
    pick = sizes_f
    if uv_faces_fk is not None:
        templates += [h + " %d/%d" * k + "\n" for k, h in enumerate(head)]
        uv_f = (uv_faces_fk >= 0).any(1)
        pick = sizes_f + uv_f * len(head)
        pairs = np.stack([values, uv_faces_fk[valid_fk] + offset], axis=1)
        keep = np.stack([np.ones(len(values), bool), np.repeat(uv_f, sizes_f)], axis=1)
        values = pairs[keep]
    templates = np.array(templates, dtype=object)
    return "".join(templates[pick].tolist()) % tuple(values.ravel().tolist())


def check_padding(name: str, line: int | None, degrees: np.ndarray, file_bytes: int) -> int:
    """Width ``K`` of the padded ``(F, K)`` faces; refuse a padding far larger than the file.

    One face of many vertices pads every face to its size. Before allocating, the
    ``F x K`` int64 entries are compared with the file: more than ``64 x`` its size
    (and over 1 GiB) raises, naming the line of the longest face (``line``).

    Example:
        >>> check_padding("m.obj", 3, np.array([3, 4, 3]), 100)
        4
        >>> check_padding("m.obj", 7, np.array([3] * 10**6 + [10**6]), 10**7)
        Traceback (most recent call last):
        ...
        ValueError: m.obj, line 7: a face of 1000000 vertices pads 1000001 faces to 7451 GiB \
of indices (the file has 0.0093 GiB); split it
    """
    width = max(int(degrees.max()) if degrees.size else 3, 3)
    need = 8 * len(degrees) * width
    if need > max(64 * file_bytes, 2**30):
        raise file_error(name, line, f"a face of {width} vertices pads {len(degrees)} faces to "
                         f"{need / 2**30:.4g} GiB of indices (the file has "
                         f"{file_bytes / 2**30:.2g} GiB); split it")
    return width
