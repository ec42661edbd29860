"""Mesh I/O: ``load_mesh`` against ``trimesh.load(process=False)`` on 1M-face files.

Target, 1 thread: ``load_mesh`` of a 1M-face OBJ ≤ 1.0x trimesh's load
time, with peak memory reported (``VmHWM`` of a fresh process, above its state
before the call). The files are a triangulated height-field grid (708 x 708
vertices, 999,698 triangles) written to a temporary folder, never committed.
Also reported: the same grid with ``v/vt`` corners, and binary/ASCII PLY.

Our reader checks every line (token counts, integer syntax, index ranges, 0
indices) and keeps file order; trimesh's OBJ reader checks less (it drops a ``v``
line with two coordinates, for example), so the comparison is conservative.
"""

from __future__ import annotations

import atexit
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

from benchmarks.harness import Case
from torchgeo_cg.mesh.io import load_mesh, save_mesh

_PEAK_SCRIPT = r"""
import json, sys
path, tool = sys.argv[1], sys.argv[2]


def high_water_kb():  # VmHWM belongs to this process image (ru_maxrss survives fork+exec)
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM"))


if tool == "trimesh":
    import trimesh
    load = lambda: trimesh.load(path, process=False)
else:
    import torch
    from torchgeo_cg.mesh import load_mesh
    load = lambda: load_mesh(path)
before = high_water_kb()
mesh = load()
print(json.dumps((high_water_kb() - before) / 1024))
"""


def grid_mesh(n: int = 708) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(verts (n*n, 3), faces (2(n-1)^2, 3), uvs (n*n, 2))`` of a wavy height field."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    uv = np.stack([i.ravel(), j.ravel()], 1) / (n - 1)
    verts = np.concatenate([uv, 0.05 * np.sin(10 * uv[:, :1]) * np.cos(7 * uv[:, 1:])], 1)
    a = (i[:-1, :-1] * n + j[:-1, :-1]).ravel()
    tris = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    return torch.from_numpy(verts), torch.from_numpy(tris), torch.from_numpy(uv)


def peak_extra_mb(path: Path, tool: str) -> float | None:
    """Peak resident memory added by one load, in a fresh process."""
    try:
        out = subprocess.run([sys.executable, "-c", _PEAK_SCRIPT, str(path), tool],
                             capture_output=True, text=True, timeout=600, check=True)
        return float(json.loads(out.stdout.strip().splitlines()[-1]))
    except Exception:  # noqa: BLE001 - reported as missing, never fails the run
        return None


def _files(n: int) -> dict[str, Path]:
    folder = Path(tempfile.mkdtemp(prefix="bench_io_"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    verts, faces, uvs = grid_mesh(n)
    paths = {k: folder / f"grid{k}" for k in (".obj", "_uv.obj", "_bin.ply", "_ascii.ply")}
    save_mesh(paths[".obj"], verts.float(), faces)
    save_mesh(paths["_uv.obj"], verts.float(), faces, uvs=uvs.float(), uv_faces=faces)
    save_mesh(paths["_bin.ply"], verts.float(), faces, binary=True)
    save_mesh(paths["_ascii.ply"], verts.float(), faces, binary=False)
    return paths


def cases(quick: bool = False) -> list[Case]:
    import trimesh

    n = 200 if quick else 708
    paths = _files(n)
    faces = 2 * (n - 1) ** 2
    peer = f"trimesh {trimesh.__version__} load(process=False)"
    out = []
    for key, label, target in ((".obj", "OBJ v/f", 1.0), ("_uv.obj", "OBJ v/vt", None),
                               ("_bin.ply", "PLY binary", None),
                               ("_ascii.ply", "PLY ascii", None)):
        path = paths[key]
        extra = {"file_MB": path.stat().st_size / 2**20}
        if key == ".obj":
            extra["peak_extra_MB_ours"] = peak_extra_mb(path, "ours")
            extra["peak_extra_MB_trimesh"] = peak_extra_mb(path, "trimesh")
        out.append(Case(
            name=f"load_mesh {label} {faces} tris",
            ours=lambda p=path: load_mesh(p),
            peer=lambda p=path: trimesh.load(p, process=False),
            peer_name=peer,
            target=target,
            threads=(1,),
            extra=extra,
        ))
    return out
