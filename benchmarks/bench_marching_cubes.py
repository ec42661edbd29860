"""Marching cubes against scikit-image and PyMCubes.

Targets (ratio ours / peer, torch at 1 thread against single-threaded peers), all with
``ambiguity="asymptotic"`` (the default):
- torus SDF 128^3 and 256^3, float32: <= 0.6x ``skimage.measure.marching_cubes``;
  PyMCubes reported alongside;
- an MRI-like uint16 volume (many ambiguous cells): reported against skimage and
  against our ``ambiguity="separate"`` (the cost of the decider);
- forward+backward at 128^3: <= 2.0x our forward;
- a batch of 8 volumes at 64^3 in one call: <= 0.5x looping scikit-image;
- the kernels (``backend="warp"``: cube cases, welding and face lists compiled) on the
  256^3 torus: <= 0.4x scikit-image, and on the batch of 8 x 64^3: <= 0.5x its loop;
  the torch steps (``backend="torch"``) reported beside them;
- peak memory at 256^3 and 512^3 (extra memory above the input, in a fresh process with
  ``MALLOC_MMAP_THRESHOLD_`` fixed, so glibc's adaptive threshold does not change the
  peak between identical runs): <= 1.5x scikit-image's.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import torch

from benchmarks.harness import Case
from torchgeo_cg.mesh import marching_cubes
from torchgeo_cg.mesh.data import mri_phantom

_PEAK_SCRIPT = r"""
import json, sys, torch
n, tool = int(sys.argv[1]), sys.argv[2]


def high_water_kb():  # VmHWM belongs to this process image (ru_maxrss survives fork+exec)
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM"))


x = torch.linspace(-1.2, 1.2, n)
f = torch.empty(n, n, n)
Y, Z = torch.meshgrid(x, x, indexing="ij")
for i in range(n):  # slice by slice: the input is the only big allocation
    f[i] = ((x[i] ** 2 + Y**2).sqrt() - 0.7).hypot(Z) - 0.3
if tool == "skimage":
    from skimage.measure import marching_cubes as sk
    fn = f.numpy()
    sk(fn[::16, ::16, ::16].copy(), 0.0)
else:
    from torchgeo_cg.mesh import marching_cubes
    marching_cubes(f[::16, ::16, ::16].contiguous(), ambiguity="asymptotic")
before = high_water_kb()
if tool == "skimage":
    sk(fn, 0.0)
else:
    marching_cubes(f, ambiguity="asymptotic")
after = high_water_kb()
print(json.dumps((after - before) / 1024))
"""


def torus_volume(n: int, batch: int | None = None, dtype=torch.float32) -> torch.Tensor:
    """Torus SDF (R = 0.7, r = 0.3) on ``[-1.2, 1.2]^3``, ``(n, n, n)`` or ``(batch, n, n, n)``."""
    x = torch.linspace(-1.2, 1.2, n, dtype=dtype)
    X, Y, Z = torch.meshgrid(x, x, x, indexing="ij")
    f = ((X**2 + Y**2).sqrt() - 0.7).hypot(Z) - 0.3
    if batch is None:
        return f.contiguous()
    radii = torch.linspace(0.0, 0.1, batch, dtype=dtype)  # 8 slightly different tori
    return (f[None] - radii[:, None, None, None]).contiguous()


def mri_volume(quick: bool) -> torch.Tensor:
    """The shipped MRI-like uint16 volume (ties everywhere), as float32 ``(X, Y, Z)``."""
    shape = (10, 96, 96) if quick else (10, 256, 256)
    return torch.from_numpy(mri_phantom(shape).astype("float32")).permute(2, 1, 0).contiguous()


def peak_extra_mb(n: int, tool: str) -> float | None:
    """Peak resident memory above the input for one call at ``n^3``, in a fresh process
    (fixed ``MALLOC_MMAP_THRESHOLD_``)."""
    env = dict(os.environ, MALLOC_MMAP_THRESHOLD_="65536")
    try:
        out = subprocess.run(
            [sys.executable, "-c", _PEAK_SCRIPT, str(n), tool],
            capture_output=True, text=True, timeout=300, check=True, env=env,
        )
        return float(json.loads(out.stdout.strip().splitlines()[-1]))
    except Exception:  # noqa: BLE001 - reported as missing, never fails the run
        return None


def cases(quick: bool) -> list[Case]:
    from skimage.measure import marching_cubes as sk_marching_cubes

    try:
        import mcubes
    except ImportError:  # pragma: no cover - optional peer
        mcubes = None
    import skimage

    sk_name = f"skimage {skimage.__version__} (lewiner)"
    out: list[Case] = []
    sizes = (64, 128) if quick else (128, 256)
    for n in sizes:
        vol = torus_volume(n)
        vol_np = vol.numpy()
        extra = {}
        if n == sizes[-1]:
            for m in (n,) if quick else (n, 2 * n):  # 256^3 and 512^3 in the full run
                ours_mb, sk_mb = peak_extra_mb(m, "ours"), peak_extra_mb(m, "skimage")
                extra[f"peak_extra_MB_ours_{m}^3"] = ours_mb
                extra[f"peak_extra_MB_skimage_{m}^3"] = sk_mb
                if ours_mb is not None and sk_mb:
                    extra[f"peak_ratio_{m}^3 (target <= 1.5)"] = round(ours_mb / sk_mb, 2)
        out.append(Case(
            name=f"marching_cubes torus {n}^3 f32 fwd asymptotic",
            ours=lambda v=vol: marching_cubes(v, ambiguity="asymptotic"),
            peer=lambda v=vol_np: sk_marching_cubes(v, 0.0),
            peer_name=sk_name,
            target=0.6,
            extra=extra,
        ))
        for backend, target in (("warp", 0.4 if n >= 256 else None), ("torch", None)):
            out.append(Case(
                name=f"marching_cubes torus {n}^3 f32 fwd asymptotic backend={backend}",
                ours=lambda v=vol, b=backend: marching_cubes(v, ambiguity="asymptotic",
                                                             backend=b),
                peer=lambda v=vol_np: sk_marching_cubes(v, 0.0),
                peer_name=sk_name,
                target=target,
            ))
        if mcubes is not None:
            out.append(Case(
                name=f"marching_cubes torus {n}^3 f32 fwd asymptotic (vs PyMCubes)",
                ours=lambda v=vol: marching_cubes(v, ambiguity="asymptotic"),
                peer=lambda v=vol_np: mcubes.marching_cubes(v, 0.0),
                peer_name="PyMCubes",
            ))

    mri = mri_volume(quick)
    mri_np = mri.numpy()
    out.append(Case(
        name=f"marching_cubes MRI-like {'x'.join(map(str, mri.shape))} f32 asymptotic",
        ours=lambda: marching_cubes(mri, 30000.25, ambiguity="asymptotic"),
        peer=lambda: sk_marching_cubes(mri_np, 30000.25),
        peer_name=sk_name,
    ))
    out.append(Case(
        name=f"marching_cubes MRI-like {'x'.join(map(str, mri.shape))} f32 asymptotic "
             "(vs separate)",
        ours=lambda: marching_cubes(mri, 30000.25, ambiguity="asymptotic"),
        peer=lambda: marching_cubes(mri, 30000.25, ambiguity="separate"),
        peer_name="ours ambiguity=separate",
    ))

    n = 64 if quick else 128
    vol = torus_volume(n)
    vol_grad = vol.clone().requires_grad_()

    def fwd_bwd():
        r = marching_cubes(vol_grad, ambiguity="asymptotic")
        (r.verts.sum() + r.normals.sum()).backward()
        vol_grad.grad = None

    out.append(Case(
        name=f"marching_cubes torus {n}^3 f32 fwd+bwd (verts, normals) asymptotic",
        ours=fwd_bwd,
        peer=lambda: marching_cubes(vol, ambiguity="asymptotic"),
        peer_name="ours fwd",
        target=2.0,
    ))

    n, batch = (32, 8) if quick else (64, 8)
    vols = torus_volume(n, batch)
    vols_np = [v.numpy() for v in vols]
    out.append(Case(
        name=f"marching_cubes batch {batch}x{n}^3 f32 one call asymptotic",
        ours=lambda: marching_cubes(vols, ambiguity="asymptotic"),
        peer=lambda: [sk_marching_cubes(v, 0.0) for v in vols_np],
        peer_name=f"{sk_name} loop",
        target=0.5,
    ))
    for backend, target in (("warp", 0.5), ("torch", None)):
        out.append(Case(
            name=f"marching_cubes batch {batch}x{n}^3 f32 one call asymptotic backend={backend}",
            ours=lambda b=backend: marching_cubes(vols, ambiguity="asymptotic", backend=b),
            peer=lambda: [sk_marching_cubes(v, 0.0) for v in vols_np],
            peer_name=f"{sk_name} loop",
            target=target,
        ))
    return out
