"""DeepSDF-style training samples from an analytic SDF or a triangle mesh, headless.

DeepSDF (Park et al. 2019, section 5) trains on points concentrated near the surface:
each surface sample is perturbed twice with isotropic Gaussian noise (variances
0.0025 and 0.00025 in the paper; 0.005 and 0.0005 here, as in many re-implementations)
and a small share of points is drawn uniformly in the bounds. Their preprocessing and
``mesh_to_sdf`` render depth maps with OpenGL; this sampler needs no display: surface
points are drawn directly on the triangles (area-weighted) or projected onto the zero
set of an analytic SDF, and distances come from :func:`~torchgeo_cg.sdf.mesh_distance.mesh_sdf`
or the function itself.

Convention:
    - SDF negative inside; points ``(N, 3)`` in world units.
    - Without balancing, the rows come in blocks: the surface points perturbed with
      ``variances[0]``, then with ``variances[1]`` (and so on), then the uniform ones.
    - ``variances`` are per-axis variances ``sigma^2`` of the Gaussian offsets.
    - Randomness comes from one ``torch.Generator`` seeded with ``seed`` on the CPU, so a
      seed reproduces the samples on every device.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from torchgeo_cg.core.check import check_float, check_shape
from torchgeo_cg.sdf.grid import _bounds
from torchgeo_cg.sdf.mesh_distance import _check_mesh, mesh_sdf

__all__ = ["SDFSamples", "SDFSampler", "sample_mesh_surface", "save_samples", "load_samples"]


class SDFSamples(NamedTuple):
    """Training samples.

    Attributes:
        points: ``(N, 3)`` positions.
        sdf: ``(N,)`` signed distances (clamped when the sampler clamps).
    """

    points: torch.Tensor
    sdf: torch.Tensor


def sample_mesh_surface(
    vertices: torch.Tensor, faces: torch.Tensor, n: int, generator: torch.Generator | None = None
) -> torch.Tensor:
    """Uniform (area-weighted) random points on a triangle mesh.

    Convention:
        A face is chosen with probability proportional to its area, then a point with
        uniform barycentric density ``(1 - sqrt(r1), sqrt(r1) (1 - r2), sqrt(r1) r2)``.

    Args:
        vertices: ``(V, 3)``.
        faces: ``(F, 3)`` integer; at least one face with positive area.
        n: number of points.
        generator: a CPU ``torch.Generator`` (default: the global one).

    Returns:
        ``(n, 3)`` points, dtype and device of ``vertices``.

    Example:
        >>> tri = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        >>> p = sample_mesh_surface(tri, torch.tensor([[0, 1, 2]]), 1000,
        ...                         torch.Generator().manual_seed(0))
        >>> bool((p[:, 2] == 0).all() and (p[:, 0] + p[:, 1] <= 1).all())
        True
    """
    _check_mesh(vertices, faces)
    tri = vertices[faces.long()]
    area = torch.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=-1).norm(dim=-1)
    if not bool((area > 0).any()):
        raise ValueError("faces: expected at least one face with positive area")
    face = torch.multinomial(area.detach().double().cpu(), n, replacement=True,
                             generator=generator)
    r = torch.rand(n, 2, generator=generator, dtype=torch.float64)
    s = r[:, 0].sqrt()
    w = torch.stack([1 - s, s * (1 - r[:, 1]), s * r[:, 1]], dim=-1).to(vertices)
    corners = tri[face.to(vertices.device)]  # (n, 3, 3)
    return (w.unsqueeze(-1) * corners).sum(1)


class SDFSampler:
    """Draws ``(points, sdf)`` with the DeepSDF distribution from an SDF or a mesh.

    Convention:
        See the module docstring; SDF negative inside.

    Args:
        source: an SDF callable ``(M, 3) -> (M,)`` (function or ``nn.Module``), or a
            mesh as ``(vertices (V, 3), faces (F, 3))`` or any object with
            ``.vertices`` and ``.faces`` arrays (e.g. ``trimesh.Trimesh``).
        bounds: box for uniform samples, ``(lo, hi)`` or ``((x0, y0, z0), (x1, y1, z1))``.
            Default: ``(-1, 1)`` for functions; for meshes the bounding box grown by
            10% on each side.
        variances: Gaussian variances of the near-surface perturbations; each surface
            point is perturbed once per variance.
        uniform_fraction: share of uniform samples in ``[0, 1]`` (default 0.06).
        balanced: return as many negative as positive samples (``n // 2`` negatives).
        clamp: clamp the returned SDF to ``[-clamp, clamp]`` (DeepSDF uses 0.1).
        seed: seed of the sampler's own generator (``None``: nondeterministic).
        sign: sign method passed to ``mesh_sdf`` for meshes.
        device, dtype: of the returned samples (default: of the mesh, else CPU and
            the default dtype).

    Example:
        >>> from torchgeo_cg.sdf.primitives import sphere
        >>> s = SDFSampler(sphere, seed=0).sample(1000)
        >>> s.points.shape, s.sdf.shape
        (torch.Size([1000, 3]), torch.Size([1000]))
        >>> bool(torch.allclose(s.sdf, sphere(s.points)))
        True
    """

    def __init__(
        self,
        source,
        bounds=None,
        variances: Sequence[float] = (0.005, 0.0005),
        uniform_fraction: float = 0.06,
        balanced: bool = False,
        clamp: float | None = None,
        seed: int | None = None,
        sign: str = "auto",
        device=None,
        dtype=None,
    ):
        self.vertices: torch.Tensor | None = None
        self.faces: torch.Tensor | None = None
        if callable(source) and not hasattr(source, "faces"):
            self.sdf_fn: Callable | None = source
            kind_dtype, kind_device = None, None
        else:
            if isinstance(source, (tuple, list)) and len(source) == 2:
                verts, faces = source
            elif hasattr(source, "vertices") and hasattr(source, "faces"):
                verts, faces = source.vertices, source.faces
            else:
                raise TypeError("source: expected an SDF callable, a (vertices, faces) pair or "
                                f"a mesh object, got {type(source).__name__}")
            verts = torch.as_tensor(np.asarray(verts) if not isinstance(verts, torch.Tensor)
                                    else verts)
            faces = torch.as_tensor(np.asarray(faces) if not isinstance(faces, torch.Tensor)
                                    else faces)
            _check_mesh(verts, faces)
            self.vertices, self.faces, self.sdf_fn = verts, faces.long(), None
            kind_dtype, kind_device = verts.dtype, verts.device
        self.dtype = dtype or kind_dtype or torch.get_default_dtype()
        self.device = torch.device(device) if device is not None else (
            kind_device or torch.device("cpu"))
        if bounds is None:
            if self.vertices is None:
                bounds = (-1.0, 1.0)
            else:
                lo, hi = self.vertices.amin(0), self.vertices.amax(0)
                pad = 0.1 * (hi - lo).clamp_min(1e-6)
                bounds = torch.stack([lo - pad, hi + pad]).double()
        self.bounds = _bounds(bounds, "cpu", torch.float64)
        variances = tuple(float(v) for v in variances)
        if len(variances) == 0 or min(variances) <= 0:
            raise ValueError(f"variances: expected positive variances, got {variances}")
        if not 0.0 <= uniform_fraction <= 1.0:
            raise ValueError(f"uniform_fraction: expected a value in [0, 1], "
                             f"got {uniform_fraction}")
        if clamp is not None and not clamp > 0:
            raise ValueError(f"clamp: expected a positive number or None, got {clamp}")
        self.variances = variances
        self.uniform_fraction = float(uniform_fraction)
        self.balanced = bool(balanced)
        self.clamp = clamp
        self.sign = sign
        self.generator = torch.Generator()
        if seed is None:
            self.generator.seed()
        else:
            self.generator.manual_seed(int(seed))

    # ----------------------------------------------------------------- pieces
    def _uniform(self, n: int) -> torch.Tensor:
        r = torch.rand(n, 3, generator=self.generator, dtype=torch.float64)
        return self.bounds[0] + r * (self.bounds[1] - self.bounds[0])

    def _evaluate(self, points64: torch.Tensor) -> torch.Tensor:
        pts = points64.to(self.device, self.dtype)
        if self.sdf_fn is not None:
            with torch.no_grad():
                values = self.sdf_fn(pts)
            if not isinstance(values, torch.Tensor) or values.shape != pts.shape[:-1]:
                raise ValueError(f"source: expected the SDF to return shape "
                                 f"{tuple(pts.shape[:-1])}, got "
                                 f"{getattr(values, 'shape', type(values))}")
            return values.to(self.dtype)
        verts = self.vertices.to(self.device, self.dtype)
        return mesh_sdf(verts, self.faces.to(self.device), pts, sign=self.sign).sdf

    def surface_points(self, n: int) -> torch.Tensor:
        """``(n, 3)`` float64 CPU points on the surface.

        Meshes: area-weighted uniform. Functions: uniform points in the bounds pushed
        onto the zero set by 8 Newton steps ``p <- p - f grad f / |grad f|^2``, keeping
        those that converged (``|f| < 1e-6`` times the bounds' size) inside the bounds.
        For an exact SDF one step lands on the closest surface point, so the density
        favours convex, exposed parts; it is not exactly area-uniform.
        """
        if self.sdf_fn is None:
            verts = self.vertices.detach().cpu().double()
            return sample_mesh_surface(verts, self.faces.cpu(), n, self.generator)
        size = float((self.bounds[1] - self.bounds[0]).max())
        found: list[torch.Tensor] = []
        have = 0
        for _ in range(50):  # rounds of rejection, not a loop over points
            p = self._uniform(max(2 * (n - have), 64)).to(self.device, self.dtype)
            for _ in range(8):
                with torch.enable_grad():
                    q = p.detach().requires_grad_(True)
                    f = self.sdf_fn(q)
                    (g,) = torch.autograd.grad(f.sum(), q)
                g2 = (g * g).sum(-1, keepdim=True)
                step = f.detach().unsqueeze(-1) * g / torch.where(g2 > 0, g2, torch.ones_like(g2))
                p = (p - step).detach()
            with torch.no_grad():
                f = self.sdf_fn(p)
            lo, hi = self.bounds.to(p)
            ok = (f.abs() < 1e-6 * size * (10 if self.dtype == torch.float32 else 1)) & (
                (p >= lo) & (p <= hi)).all(-1)
            found.append(p[ok].double().cpu())
            have += int(ok.sum())
            if have >= n:
                return torch.cat(found)[:n]
        raise RuntimeError(f"SDFSampler: found only {have} of {n} surface points in 50 rounds; "
                           "does the shape's zero set lie inside the bounds?")

    def _draw(self, n: int) -> tuple[torch.Tensor, torch.Tensor]:
        n_uniform = int(round(n * self.uniform_fraction))
        n_near = n - n_uniform
        k = len(self.variances)
        per = math.ceil(n_near / k) if n_near else 0
        blocks = []
        if per:
            surface = self.surface_points(per)
            for var in self.variances:
                noise = torch.randn(per, 3, generator=self.generator, dtype=torch.float64)
                blocks.append(surface + math.sqrt(var) * noise)
        near = torch.cat(blocks)[:n_near] if blocks else torch.zeros(0, 3, dtype=torch.float64)
        points = torch.cat([near, self._uniform(n_uniform)])
        return points.to(self.device, self.dtype), self._evaluate(points)

    # ----------------------------------------------------------------- public
    def sample(self, n: int) -> SDFSamples:
        """Draw ``n`` samples ``(points (n, 3), sdf (n,))``.

        With ``balanced=True`` exactly ``n // 2`` are negative and the rest positive
        (extra rounds are drawn as needed; an error if the source has no inside).

        Example:
            >>> from torchgeo_cg.sdf.primitives import sphere
            >>> s = SDFSampler(sphere, balanced=True, clamp=0.1, seed=1).sample(100)
            >>> int((s.sdf < 0).sum()), round(float(s.sdf.abs().max()), 4)
            (50, 0.1)
        """
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"n: expected a positive int, got {n!r}")
        if not self.balanced:
            points, sdf = self._draw(n)
        else:
            n_neg, n_pos = n // 2, n - n // 2
            negs, poss, got_neg, got_pos = [], [], 0, 0
            for _ in range(50):
                p, s = self._draw(max(n, 256))
                inside = s < 0
                negs.append((p[inside], s[inside]))
                poss.append((p[~inside], s[~inside]))
                got_neg += int(inside.sum())
                got_pos += int((~inside).sum())
                if got_neg >= n_neg and got_pos >= n_pos:
                    break
            else:
                raise RuntimeError(f"SDFSampler: cannot balance, found {got_neg} negative and "
                                   f"{got_pos} positive samples in 50 rounds")
            neg_p = torch.cat([a for a, _ in negs])[:n_neg]
            neg_s = torch.cat([b for _, b in negs])[:n_neg]
            pos_p = torch.cat([a for a, _ in poss])[:n_pos]
            pos_s = torch.cat([b for _, b in poss])[:n_pos]
            points, sdf = torch.cat([pos_p, neg_p]), torch.cat([pos_s, neg_s])
        if self.clamp is not None:
            sdf = sdf.clamp(-self.clamp, self.clamp)
        return SDFSamples(points, sdf)

    __call__ = sample

    def save(self, path: str | Path, samples: SDFSamples) -> None:
        """Same as :func:`save_samples`."""
        save_samples(path, samples)

    @staticmethod
    def load(path: str | Path, device=None, dtype=None) -> SDFSamples:
        """Same as :func:`load_samples`."""
        return load_samples(path, device, dtype)


def save_samples(path: str | Path, samples: SDFSamples) -> None:
    """Save samples to ``.npz`` in DeepSDF's layout: ``pos`` and ``neg``, each ``(M, 4)``.

    Rows are ``(x, y, z, sdf)``; ``pos`` holds ``sdf >= 0``, ``neg`` holds ``sdf < 0``.

    Args:
        path: file path (``.npz`` is appended by NumPy if missing).
        samples: :class:`SDFSamples` with ``points (N, 3)`` and ``sdf (N,)``.

    Returns:
        ``None``; writes the file.

    Example:
        >>> import tempfile, os
        >>> s = SDFSamples(torch.tensor([[0.0, 0, 0], [2, 0, 0]]), torch.tensor([-1.0, 1.0]))
        >>> with tempfile.TemporaryDirectory() as d:
        ...     save_samples(os.path.join(d, "s.npz"), s)
        ...     load_samples(os.path.join(d, "s.npz")).sdf
        tensor([ 1., -1.])
    """
    points, sdf = samples
    check_float(points, "points")
    check_shape(points, ["N", "3"], "points")
    check_shape(sdf, ["N"], "sdf", {"N": points.shape[0]})
    rows = torch.cat([points, sdf[:, None]], dim=1).detach().cpu().numpy()
    inside = rows[:, 3] < 0
    np.savez(path, pos=rows[~inside], neg=rows[inside])


def load_samples(path: str | Path, device=None, dtype=None) -> SDFSamples:
    """Load ``.npz`` samples written by :func:`save_samples` (or DeepSDF): ``pos`` then ``neg``.

    Args:
        path: the ``.npz`` file.
        device, dtype: of the result (default: CPU, the stored dtype).

    Returns:
        :class:`SDFSamples` ``(points (N, 3), sdf (N,))``, positive rows first.

    Example:
        >>> import tempfile, os
        >>> rows = np.array([[0.0, 0.0, 2.0, 1.0], [0.0, 0.0, 0.5, -0.5]])
        >>> with tempfile.TemporaryDirectory() as d:
        ...     np.savez(os.path.join(d, "deepsdf.npz"), pos=rows[:1], neg=rows[1:])
        ...     load_samples(os.path.join(d, "deepsdf.npz"), dtype=torch.float32)
        SDFSamples(points=tensor([[0.0000, 0.0000, 2.0000],
                [0.0000, 0.0000, 0.5000]]), sdf=tensor([ 1.0000, -0.5000]))
    """
    with np.load(path) as data:
        if "pos" not in data or "neg" not in data:
            raise ValueError(f"path: expected arrays 'pos' and 'neg' in {path}, "
                             f"got {sorted(data.keys())}")
        rows = torch.from_numpy(np.concatenate([data["pos"], data["neg"]]))
    if rows.dim() != 2 or rows.shape[1] != 4:
        raise ValueError(f"path: expected (M, 4) rows, got {tuple(rows.shape)}")
    rows = rows.to(device=device, dtype=dtype or rows.dtype)
    return SDFSamples(rows[:, :3], rows[:, 3])
