"""A live OpenSubdiv reference: ``osd_driver/osd_driver.cpp`` compiled against ``libosd-dev``.

The driver is compiled once per source version with ``g++`` into the temporary directory
(an atomic rename, so parallel workers can race safely); tests that call :func:`run_osd`
skip where the compiler or OpenSubdiv's headers are absent.
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

SOURCE = Path(__file__).parent / "osd_driver" / "osd_driver.cpp"


@functools.lru_cache(maxsize=1)
def _driver() -> str | None:
    if shutil.which("g++") is None or not Path("/usr/include/opensubdiv/far").is_dir():
        return None
    digest = hashlib.sha1(SOURCE.read_bytes()).hexdigest()[:12]
    folder = Path(tempfile.gettempdir()) / f"torchgeo_cg_osd_{digest}"
    binary = folder / "osd_driver"
    if binary.exists():
        return str(binary)
    folder.mkdir(exist_ok=True)
    partial = folder / f"osd_driver.{os.getpid()}"
    result = subprocess.run(
        ["g++", "-O1", "-std=c++14", "-o", str(partial), str(SOURCE), "-losdCPU"],
        capture_output=True, text=True,
    )
    if result.returncode != 0:
        return None
    os.replace(partial, binary)
    return str(binary)


def osd_driver() -> str:
    """The compiled driver's path, or skip the test."""
    path = _driver()
    if path is None:
        pytest.skip("OpenSubdiv (libosd-dev) and g++ are needed for the live reference")
    return path


def _mesh_text(verts, faces, tags, scheme, boundary, crease_method, triangle_rule) -> list[str]:
    verts = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
    faces = [[int(i) for i in f if int(i) >= 0] for f in np.asarray(faces, dtype=object)
             ] if not isinstance(faces, list) else [[int(i) for i in f if int(i) >= 0]
                                                    for f in faces]
    lines = [f"{scheme} {boundary} {crease_method} {triangle_rule}", f"{len(verts)} {len(faces)}"]
    lines += [" ".join(repr(float(x)) for x in v) for v in verts]
    lines += [" ".join(map(str, [len(f), *f])) for f in faces]
    creases = corners = holes = ()
    crease_s = corner_s = ()
    if tags is not None:
        creases, crease_s = tags.creases.tolist(), tags.crease_sharpness.tolist()
        corners, corner_s = tags.corners.tolist(), tags.corner_sharpness.tolist()
        holes = tags.holes.tolist()
    lines.append(str(len(creases)))
    lines += [f"{a} {b} {s!r}" for (a, b), s in zip(creases, crease_s)]
    lines.append(str(len(corners)))
    lines += [f"{v} {s!r}" for v, s in zip(corners, corner_s)]
    lines.append(str(len(holes)))
    lines += [str(h) for h in holes]
    return lines


def run_osd(verts, faces, command: str, *, tags=None, scheme="catmark", boundary="edge_only",
            crease_method="uniform", triangle_rule="catmark", samples=None) -> np.ndarray:
    """Run one driver command; return its numbers as a float64 array, one row per line.

    ``command`` is ``"refine L"``, ``"limit L"``, ``"patch L"`` (then ``samples``: ``(N, 3)``
    rows ``ptex_face u v``) or ``"ptex"``. ``refine`` and ``limit`` drop the leading count.
    """
    lines = _mesh_text(verts, faces, tags, scheme, boundary, crease_method, triangle_rule)
    if command.startswith("patch"):
        samples = np.asarray(samples, dtype=np.float64).reshape(-1, 3)
        lines.append(f"{command} {len(samples)}")
        lines += [f"{int(f)} {float(u)!r} {float(v)!r}" for f, u, v in samples]
    else:
        lines.append(command)
    result = subprocess.run([osd_driver()], input="\n".join(lines) + "\n", capture_output=True,
                            text=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"osd_driver failed ({result.returncode}): {result.stderr.strip()}")
    rows = [list(map(float, line.split())) for line in result.stdout.splitlines() if line]
    if command.split()[0] in ("refine", "limit"):
        rows = rows[1:]
    return np.array(rows, dtype=np.float64)
