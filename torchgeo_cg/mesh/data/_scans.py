"""Synthetic scan pairs of the shipped rabbit for registration demos, tests and benchmarks.

A scan is an area-uniform sample of
the rabbit's Catmull-Clark surface (two levels; :func:`trimesh.sample.sample_surface`),
so two scans of the same surface share no point.
"""

from __future__ import annotations

from functools import lru_cache
from importlib.resources import files
from typing import NamedTuple

import numpy as np
import torch
import trimesh

from torchgeo_cg.core.check import check_generator
from torchgeo_cg.mesh.io import load_mesh, to_trimesh
from torchgeo_cg.mesh.subdivision.catmark import catmull_clark

__all__ = ["ScanPairs", "rabbit_surface", "rabbit_scan_pairs"]


class ScanPairs(NamedTuple):
    """Pairs of scans: ``target ~ truth @ source``.

    Attributes:
        source: ``(B, N, 3)`` float64, moved by the inverse of ``truth``.
        target: ``(B, M, 3)`` float64.
        truth: ``(B, 4, 4)`` the target-from-source transforms.
        size: the rabbit's bounding-box diagonal.
    """

    source: torch.Tensor
    target: torch.Tensor
    truth: torch.Tensor
    size: float


@lru_cache(maxsize=1)
def rabbit_surface() -> trimesh.Trimesh:
    """The shipped rabbit subdivided twice by Catmull-Clark, as a trimesh.

    Example:
        >>> rabbit_surface().is_watertight
        True
    """
    rabbit = load_mesh(files("torchgeo_cg.mesh.data") / "rabbit.obj", dtype=torch.float64)
    verts, faces = catmull_clark(rabbit.verts, rabbit.faces, levels=2)
    return to_trimesh(verts, faces)


def _rotation(rng, lo_deg, hi_deg):
    angle = np.deg2rad(rng.uniform(lo_deg, hi_deg))
    axis = rng.normal(size=3)
    x, y, z = axis / np.linalg.norm(axis)
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def rabbit_scan_pairs(count: int, points: int = 8000, *,
                      generator: torch.Generator | None = None, dropped: float = 0.2,
                      noise: float = 0.002, outliers: float = 0.0,
                      angles: tuple[float, float] = (10.0, 45.0),
                      shift: float = 0.1) -> ScanPairs:
    """``count`` scan pairs of the rabbit with a known transform between them.

    Each pair: two independent scans of ``points`` points; the source loses a
    ``dropped`` share of its points, both get Gaussian noise of ``noise`` x size, a
    share ``outliers`` of the source points is replaced by uniform points in its
    bounding box, and the source is moved by the inverse of a rotation by an angle
    in ``angles`` (degrees, random axis, about its centroid) and a shift of length
    ``shift`` x size.

    Randomness is ``generator=`` as everywhere (a CPU :class:`torch.Generator`; ``None``
    uses torch's default one): one number drawn from it seeds numpy's and trimesh's
    samplers, so a generator seeded alike gives the same pairs on every machine.

    Example:
        >>> pairs = rabbit_scan_pairs(2, 1000, generator=torch.Generator().manual_seed(0))
        >>> pairs.source.shape, pairs.target.shape, pairs.truth.shape
        (torch.Size([2, 800, 3]), torch.Size([2, 1000, 3]), torch.Size([2, 4, 4]))
    """
    if generator is not None:
        check_generator(generator)
    seed = int(torch.randint(0, 2**31 - 1, (), generator=generator))
    surface = rabbit_surface()
    size = float(np.linalg.norm(surface.bounds[1] - surface.bounds[0]))
    rng = np.random.default_rng(seed)
    kept = int(round((1 - dropped) * points))
    sources, targets, truths = [], [], []
    for c in range(count):  # loop over demo pairs (data generation, not an op)
        target = np.asarray(trimesh.sample.sample_surface(surface, points, seed=seed * 7919
                                                          + 2 * c)[0])
        source = np.asarray(trimesh.sample.sample_surface(surface, points, seed=seed * 7919
                                                          + 2 * c + 1)[0])
        source = source[rng.permutation(points)[:kept]]
        target = target + rng.normal(0, noise * size, target.shape)
        source = source + rng.normal(0, noise * size, source.shape)
        bad = rng.permutation(kept)[: int(round(outliers * kept))]
        lo, hi = source.min(0), source.max(0)
        source[bad] = lo + (hi - lo) * rng.uniform(size=(bad.size, 3))
        rot = _rotation(rng, *angles)
        step = rng.normal(size=3)
        step = shift * size * step / np.linalg.norm(step)
        centre = source.mean(0)
        truth = np.eye(4)
        truth[:3, :3], truth[:3, 3] = rot, centre + step - rot @ centre
        sources.append((source - truth[:3, 3]) @ rot)  # truth^-1 applied
        targets.append(target)
        truths.append(truth)
    return ScanPairs(torch.tensor(np.stack(sources)), torch.tensor(np.stack(targets)),
                     torch.tensor(np.stack(truths)), size)
