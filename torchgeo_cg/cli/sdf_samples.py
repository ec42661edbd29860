"""``torchgeo-cg sdf-samples``: DeepSDF training samples for every mesh under a folder.

Usage::

    torchgeo-cg sdf-samples INPUT OUTPUT [--points N] [--seed S] [--resume]
    torchrun --nproc_per_node K --no-python torchgeo-cg sdf-samples INPUT OUTPUT ...

Every ``.obj``, ``.ply`` and ``.off`` file under ``INPUT`` (recursively, sorted by
relative path) gives one file ``OUTPUT/<relative path>.npz`` (``chairs/a.obj`` ->
``chairs/a.obj.npz``), an uncompressed NumPy archive with

- ``points``: ``(N, 3)`` float32 sample positions in the normalized frame;
- ``sdf``: ``(N,)`` float32 signed distances (negative inside) in the normalized frame;
- ``normalization``: ``(4,)`` float64 ``(ox, oy, oz, s)``: a mesh point ``x`` maps to
  ``(x + o) * s``, which puts the bounding-box centre at the origin and the mesh in the
  unit sphere (DeepSDF's normalization; divide by ``s`` to return to mesh units).

Samples come from :class:`~torchgeo_cg.sdf.sampler.SDFSampler` (DeepSDF distribution,
polygons triangulated). Each mesh's stream is seeded from ``--seed`` and its relative
path only (``SeedSequence``), and every process computes with one thread, so a mesh's
file is the same bit for bit whichever process or machine computes it, and the zip
entries carry a fixed timestamp.

Scale-out: under ``torchrun`` (or any launcher setting ``RANK`` and ``WORLD_SIZE``)
rank ``r`` handles the meshes ``i`` with ``i % WORLD_SIZE == r``; no process group is
needed. Files are written to a temporary name and renamed (``os.replace``), so a killed
run leaves no partial file and ``--resume`` skips the finished meshes. A mesh that
cannot be read or sampled is reported on stderr and skipped.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import os
import sys
import warnings
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["add_parser"]  # a command: `torchgeo-cg` calls its add_parser

_SUFFIXES = (".obj", ".ply", ".off")
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


def _find_meshes(root: Path) -> list[str]:
    """Relative POSIX paths of the meshes under ``root`` (or ``[name]`` for a file), sorted.

    Example:
        >>> import tempfile
        >>> d = Path(tempfile.mkdtemp())
        >>> for name in ("b.OBJ", "a/c.ply", "notes.txt"):
        ...     (d / name).parent.mkdir(exist_ok=True)
        ...     _ = (d / name).write_text("")
        >>> _find_meshes(d)
        ['a/c.ply', 'b.OBJ']
    """
    if root.is_file():
        return [root.name]
    found = (p for p in root.rglob("*") if p.is_file() and p.suffix.lower() in _SUFFIXES)
    return sorted(p.relative_to(root).as_posix() for p in found)


def _mesh_seed(seed: int, relative_path: str) -> int:
    """63-bit seed of one mesh from the run's seed and the mesh's relative path.

    Example:
        >>> _mesh_seed(0, "a.obj") == _mesh_seed(0, "a.obj") != _mesh_seed(1, "a.obj")
        True
    """
    digest = hashlib.sha256(relative_path.encode("utf-8")).digest()
    words = [int.from_bytes(digest[i : i + 4], "little") for i in range(0, 16, 4)]
    state = np.random.SeedSequence([seed & (2**63 - 1), *words]).generate_state(2, np.uint32)
    return (int(state[0]) << 31 ^ int(state[1])) & (2**63 - 1)


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write an uncompressed ``.npz`` atomically with fixed zip timestamps (reproducible bytes).

    Example:
        >>> import tempfile
        >>> p = Path(tempfile.mkdtemp()) / "x.npz"
        >>> _write_npz(p, {"a": np.arange(3)})
        >>> np.load(p)["a"].tolist()
        [0, 1, 2]
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_STORED) as zf:
            for name, array in arrays.items():
                buffer = io.BytesIO()
                np.lib.format.write_array(buffer, np.ascontiguousarray(array),
                                          allow_pickle=False)
                zf.writestr(zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_TIME),
                            buffer.getvalue())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _load(path: Path):
    """Vertices (float64) and padded faces of a mesh file (OFF through trimesh)."""
    import torch

    if path.suffix.lower() == ".off":
        import trimesh

        mesh = trimesh.load(path, force="mesh", process=False)
        return torch.as_tensor(mesh.vertices, dtype=torch.float64), torch.as_tensor(mesh.faces)
    from torchgeo_cg.mesh.io import load_mesh

    mesh = load_mesh(path, dtype=torch.float64)
    return mesh.verts, mesh.faces


def _sdf_samples_for_mesh(path: Path, relative: str, points: int, seed: int) -> dict:
    """The arrays written for one mesh (see the module docstring for the format)."""
    import torch

    from torchgeo_cg.mesh.faces import check_mesh
    from torchgeo_cg.sdf.sampler import SDFSampler

    verts, faces = _load(path)
    faces = check_mesh(verts, faces, finite=True)
    lo, hi = verts.amin(0), verts.amax(0)
    offset = -(lo + hi) / 2
    radius = float((verts + offset).norm(dim=-1).max())
    if not radius > 0:
        raise ValueError("mesh has no extent (all vertices coincide)")
    scale = 1.0 / radius
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "not watertight, using winding numbers"
        sampler = SDFSampler(((verts + offset) * scale, faces),
                             generator=torch.Generator().manual_seed(_mesh_seed(seed, relative)),
                             dtype=torch.float64)
        samples = sampler.sample(points)
    return {
        "points": samples.points.numpy().astype(np.float32),
        "sdf": samples.sdf.numpy().astype(np.float32),
        "normalization": np.array([*offset.tolist(), scale], dtype=np.float64),
    }


def _rank() -> tuple[int, int]:
    rank, world = int(os.environ.get("RANK", "0")), int(os.environ.get("WORLD_SIZE", "1"))
    if world < 1 or not 0 <= rank < world:
        raise ValueError(f"RANK={rank} and WORLD_SIZE={world}: expected 0 <= RANK < WORLD_SIZE")
    return rank, world


def _run(args: argparse.Namespace) -> int:
    import torch
    from tqdm.auto import tqdm

    prog = "torchgeo-cg sdf-samples"
    src, dst = Path(args.input), Path(args.output)
    try:
        if not src.exists():
            raise ValueError(f"INPUT: no such file or directory: {src}")
        if args.points < 1:
            raise ValueError(f"--points: expected a positive int, got {args.points}")
        rank, world = _rank()
    except ValueError as err:
        print(f"{prog}: error: {err}", file=sys.stderr)
        return 2
    meshes = _find_meshes(src)[rank::world]
    base = src.parent if src.is_file() else src
    torch.set_num_threads(1)  # bit-identical results whichever process computes a mesh
    written = skipped = 0
    failed: list[str] = []
    bar = tqdm(meshes, desc=f"sdf-samples rank {rank}/{world}", unit="mesh",
               disable=args.no_progress or rank != 0)
    for rel in bar:  # loop over files
        out = dst / f"{rel}.npz"
        if args.resume and out.exists():
            skipped += 1
            continue
        try:
            _write_npz(out, _sdf_samples_for_mesh(base / rel, rel, args.points, args.seed))
            written += 1
        except Exception as err:  # noqa: BLE001 - a bad mesh is reported, never fatal
            failed.append(rel)
            message = str(err).splitlines()[0] if str(err) else type(err).__name__
            print(f"{prog}: skipped {rel}: {message}", file=sys.stderr)
    print(f"rank {rank}/{world}: {written} written, {skipped} already done, "
          f"{len(failed)} failed" + (f" ({', '.join(failed)})" if failed else ""))
    return 0


def add_parser(sub) -> None:
    """Add the ``sdf-samples`` subcommand to the ``torchgeo-cg`` subparsers ``sub``."""
    p = sub.add_parser(
        "sdf-samples",
        help="DeepSDF samples (npz: points, sdf, normalization) for every mesh under INPUT",
        description=__doc__.split("\n\n")[0],
    )
    p.add_argument("input", metavar="INPUT", help="folder of .obj/.ply/.off meshes (or one file)")
    p.add_argument("output", metavar="OUTPUT", help="folder for the .npz files")
    p.add_argument("--points", type=int, default=250_000, help="samples per mesh (250000)")
    p.add_argument("--seed", type=int, default=0, help="base seed (0)")
    p.add_argument("--resume", action="store_true", help="skip meshes whose file exists")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=_run)
