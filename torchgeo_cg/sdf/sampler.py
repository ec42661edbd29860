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
    - SDF negative inside; points ``(*, N, 3)`` in world units, ``*`` the batch of a
      mesh given as ``verts (*, V, 3)`` sharing one topology (no batch for SDF
      functions).
    - Polygon faces (``(F, K)`` padded with ``-1``, e.g. from
      :func:`~torchgeo_cg.mesh.io.load_mesh`) are fan-triangulated with
      :func:`~torchgeo_cg.mesh.faces.triangulate_faces` (``(v0, vk, vk+1)``), which is
      exact for planar convex polygons; a non-planar quad is replaced by two triangles.
    - Without balancing, the rows come in blocks: the surface points perturbed with
      ``variances[0]``, then with ``variances[1]`` (and so on), then the uniform ones.
    - ``variances`` are per-axis variances ``sigma^2`` of the Gaussian offsets.
    - Randomness comes from one CPU ``torch.Generator`` (``generator=``, as every random
      function here takes it; a fresh nondeterministic one when ``None``), so a seed
      reproduces the samples on every device. The sampler draws from the given generator
      and advances it.
    - DataLoader workers: a sampler created in a ``Dataset.__init__`` is copied into every
      worker with the same generator state, which would give every worker the same
      stream. The first draw inside a worker therefore reseeds the sampler's generator
      from ``(generator.initial_seed(), worker id)`` (``numpy.random.SeedSequence``), or
      from the worker's own seed (``torch.utils.data.get_worker_info().seed``, derived by
      the DataLoader from its base seed) when no generator was given: streams are independent across
      workers and reproducible across runs, without any ``worker_init_fn``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from torchgeo_cg.core.check import (
    ShapeError,
    check_broadcastable,
    check_float,
    check_generator,
    check_shape,
)
from torchgeo_cg.core.coerce import check_same_dtype
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.mesh.faces import check_mesh
from torchgeo_cg.sdf._closest_faces import resolve_backend
from torchgeo_cg.sdf.mesh_distance import mesh_sdf

__all__ = ["SDFSamples", "SDFSampler", "sample_mesh_surface", "save_samples", "load_samples"]


class SDFSamples(NamedTuple):
    """Training samples.

    Attributes:
        points: ``(*, N, 3)`` positions.
        sdf: ``(*, N)`` signed distances (clamped when the sampler clamps).
    """

    points: torch.Tensor
    sdf: torch.Tensor


def _worker_seed(seed: int | None) -> int | None:
    """Seed of the current DataLoader worker's stream, or ``None`` outside workers.

    ``SeedSequence([seed, worker_id])`` when ``seed`` is given, else the worker's own
    seed (from the DataLoader's base seed).

    Example:
        >>> _worker_seed(0) is None  # not inside a DataLoader worker
        True
    """
    from torch.utils.data import get_worker_info

    info = get_worker_info()
    if info is None:
        return None
    if seed is None:
        return int(info.seed) & (2**63 - 1)
    state = np.random.SeedSequence([int(seed) & (2**63 - 1), info.id]).generate_state(2)
    return (int(state[0]) << 31 ^ int(state[1])) & (2**63 - 1)


def sample_mesh_surface(
    verts: torch.Tensor, faces, n: int, generator: torch.Generator | None = None
) -> torch.Tensor:
    """Uniform (area-weighted) random points on a mesh, batched over shared topology.

    Convention:
        One uniform draw ``r (*, n, 3)`` from ``generator`` (in float64, C order, so a
        batch equals a loop over its items with the same generator). A face is picked
        by inverse CDF of the areas with ``r[..., 0]``, then a point with uniform
        barycentric density ``(1 - sqrt(r1), sqrt(r1) (1 - r2), sqrt(r1) r2)``. Polygons
        are fan-triangulated (module docstring).

    Args:
        verts: ``(*, V, 3)`` float, finite.
        faces: ``(F, 3)`` triangles or ``(F, K)`` padded polygons; each mesh needs a face
            of positive area.
        n: number of points per mesh.
        generator: a CPU ``torch.Generator`` (default: the global one).

    Returns:
        ``(*, n, 3)`` points, dtype and device of ``verts`` (differentiable w.r.t.
        ``verts``; float16/bfloat16 are computed in float32).

    Raises:
        ValueError: non-finite verts, an empty mesh, a mesh without area, bad ``n``.

    Example:
        >>> tri = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        >>> p = sample_mesh_surface(tri, torch.tensor([[0, 1, 2]]), 1000,
        ...                         torch.Generator().manual_seed(0))
        >>> bool((p[:, 2] == 0).all() and (p[:, 0] + p[:, 1] <= 1).all())
        True
    """
    tris = check_mesh(verts, faces, finite=True)
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise ValueError(f"n: expected a non-negative int, got {n!r}")
    corners = verts[..., tris, :]  # (*, T, 3, 3)
    with torch.no_grad():
        c64 = corners.detach().double().cpu()
        area = torch.linalg.cross(c64[..., 1, :] - c64[..., 0, :],
                                  c64[..., 2, :] - c64[..., 0, :]).norm(dim=-1)  # (*, T)
        if not bool((area.amax(-1) > 0).all()):
            raise ValueError("faces: expected at least one face with positive area per mesh")
        cdf = area.cumsum(-1)
        r = torch.rand(*verts.shape[:-2], n, 3, generator=generator, dtype=torch.float64)
        target = r[..., 0] * cdf[..., -1:]
        face = torch.searchsorted(cdf, target, right=True).clamp_max(tris.shape[0] - 1)
        s = r[..., 1].sqrt()
        w = torch.stack([1 - s, s * (1 - r[..., 2]), s * r[..., 2]], dim=-1)
    face = face.to(verts.device)
    picked = torch.gather(corners, -3, face[..., None, None].expand(*face.shape, 3, 3))
    picked = picked.to(working_dtype(verts.dtype))  # float16/bfloat16: in float32
    return cast_back((w.to(picked).unsqueeze(-1) * picked).sum(-2), verts.dtype)


def _parse_bounds(bounds) -> torch.Tensor:
    b = torch.as_tensor(bounds, dtype=torch.float64).cpu()
    if b.dim() == 1 and b.shape[0] == 2:  # (lo, hi) shared by all axes
        b = b[:, None].expand(2, 3)
    if b.shape[-2:] != (2, 3):
        raise ShapeError(f"bounds: expected (lo, hi) or shape (*, 2, 3), got {tuple(b.shape)}")
    if bool(~torch.isfinite(b).all()) or bool((b[..., 1, :] <= b[..., 0, :]).any()):
        raise ValueError(f"bounds: expected finite bounds with lo < hi per axis, got {b.tolist()}")
    return b


def _validate_options(variances, uniform_fraction, clamp) -> tuple[float, ...]:
    variances = tuple(float(v) for v in variances)
    if len(variances) == 0 or not all(math.isfinite(v) and v > 0 for v in variances):
        raise ValueError(f"variances: expected positive finite variances, got {variances}")
    if not 0.0 <= uniform_fraction <= 1.0:
        raise ValueError(f"uniform_fraction: expected a value in [0, 1], got {uniform_fraction}")
    if clamp is not None and not clamp > 0:
        raise ValueError(f"clamp: expected a positive number or None, got {clamp}")
    return variances


def _mesh_source(source):
    if isinstance(source, (tuple, list)) and len(source) == 2:
        verts, faces = source
    elif hasattr(source, "vertices") and hasattr(source, "faces"):
        verts, faces = source.vertices, source.faces
    elif hasattr(source, "verts") and hasattr(source, "faces"):
        verts, faces = source.verts, source.faces
    else:
        raise TypeError("source: expected an SDF callable, a (verts, faces) pair or "
                        f"a mesh object, got {type(source).__name__}")
    verts = verts if isinstance(verts, torch.Tensor) else torch.as_tensor(np.asarray(verts))
    if not isinstance(faces, torch.Tensor) and not isinstance(faces, list):
        faces = torch.as_tensor(np.asarray(faces))
    return verts, check_mesh(verts, faces, finite=True)


class SDFSampler:
    """Draws ``(points, sdf)`` with the DeepSDF distribution from an SDF or a mesh.

    Convention:
        See the module docstring; SDF negative inside. A batch of meshes sharing one
        topology gives ``(*, n, 3)`` samples, item ``b`` drawn from mesh ``b``.

    Args:
        source: an SDF callable ``(M, 3) -> (M,)`` (function or ``nn.Module``), or a
            mesh as ``(verts (*, V, 3), faces)`` (triangles or padded polygons, e.g. a
            :class:`~torchgeo_cg.mesh.io.Mesh` from ``load_mesh``) or any object with
            ``.vertices`` and ``.faces`` arrays (e.g. ``trimesh.Trimesh``).
        bounds: box for uniform samples, ``(lo, hi)``, ``((x0, y0, z0), (x1, y1, z1))`` or
            one box per mesh ``(*, 2, 3)``. Default: ``(-1, 1)`` for functions; for meshes
            each bounding box grown by 10% of its largest side on each side.
        variances: Gaussian variances of the near-surface perturbations; each surface
            point is perturbed once per variance; positive and finite.
        uniform_fraction: share of uniform samples in ``[0, 1]`` (default 0.06).
        balanced: return as many negative as positive samples (``n // 2`` negatives).
        clamp: clamp the returned SDF to ``[-clamp, clamp]`` (DeepSDF uses 0.1).
        generator: a CPU ``torch.Generator`` the samples are drawn from (``None``: a
            fresh, nondeterministically seeded one).
        sign: sign method passed to ``mesh_sdf`` for meshes.
        backend: search backend passed to ``mesh_sdf`` for meshes (``"auto"`` takes the
            compiled engine of the ``fast`` extra when installed, else ``"torch"``).
        device, dtype: of the returned samples (default: of the mesh, else CPU and
            the default dtype); float16/bfloat16 samples are computed in float32.

    Example:
        >>> from torchgeo_cg.sdf.primitives import sphere
        >>> s = SDFSampler(sphere, generator=torch.Generator().manual_seed(0)).sample(1000)
        >>> s.points.shape, s.sdf.shape
        (torch.Size([1000, 3]), torch.Size([1000]))
        >>> bool(torch.allclose(s.sdf, sphere(s.points)))
        True
    """

    def __init__(self, source, bounds=None, variances: Sequence[float] = (0.005, 0.0005),
                 uniform_fraction: float = 0.06, balanced: bool = False,
                 clamp: float | None = None, generator: torch.Generator | None = None,
                 sign: str = "auto",
                 backend: str = "auto", device=None, dtype=None):
        self.verts: torch.Tensor | None = None
        self.faces: torch.Tensor | None = None
        self.sdf_fn: Callable | None = None
        kind_dtype, kind_device = None, None
        if callable(source) and not hasattr(source, "faces"):
            self.sdf_fn = source
        else:
            self.verts, self.faces = _mesh_source(source)
            kind_dtype, kind_device = self.verts.dtype, self.verts.device
        self.dtype = dtype or kind_dtype or torch.get_default_dtype()
        self.device = torch.device(device) if device is not None else (
            kind_device or torch.device("cpu"))
        if bounds is None:
            bounds = (-1.0, 1.0) if self.verts is None else self._mesh_bounds()
        self.bounds = _parse_bounds(bounds)  # (*, 2, 3) float64 CPU
        if self.sdf_fn is not None and self.bounds.dim() != 2:
            raise ShapeError(f"bounds: expected one box (2, 3) for an SDF callable (one box "
                             f"per mesh needs a batch of meshes), got {tuple(self.bounds.shape)}")
        if check_broadcastable({"vertices": self.batch_shape,
                                "bounds": self.bounds.shape[:-2]}) != self.batch_shape:
            raise ShapeError(f"bounds: expected at most one box per mesh, got "
                             f"{tuple(self.bounds.shape)} for meshes {self.batch_shape}")
        self.variances = _validate_options(variances, uniform_fraction, clamp)
        self.uniform_fraction = float(uniform_fraction)
        self.balanced = bool(balanced)
        self.clamp = clamp
        self.sign = sign
        self.backend = resolve_backend(backend)  # checked now, not at the first sample
        self._worker: int | None = None
        self._seed = None if generator is None else check_generator(generator).initial_seed()
        if generator is None:
            generator = torch.Generator()
            generator.seed()
        self.generator = generator

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading batch dims of the mesh vertices (``()`` for functions)."""
        return () if self.verts is None else tuple(self.verts.shape[:-2])

    def _mesh_bounds(self) -> torch.Tensor:
        verts = self.verts.detach().double().cpu()
        lo, hi = verts.amin(-2), verts.amax(-2)
        pad = 0.1 * (hi - lo).amax(-1, keepdim=True)
        return torch.stack([lo - pad, hi + pad], dim=-2)

    def _check_worker(self) -> None:
        """Reseed once per DataLoader worker (see the module docstring)."""
        from torch.utils.data import get_worker_info

        info = get_worker_info()
        if info is not None and self._worker != info.id:
            self._worker = info.id
            self.generator.manual_seed(_worker_seed(self._seed))

    # ----------------------------------------------------------------- pieces
    def _uniform(self, n: int) -> torch.Tensor:
        r = torch.rand(*self.batch_shape, n, 3, generator=self.generator, dtype=torch.float64)
        lo, hi = self.bounds[..., 0:1, :], self.bounds[..., 1:2, :]
        return lo + r * (hi - lo)

    def _evaluate(self, points64: torch.Tensor, progress: bool = False) -> torch.Tensor:
        from tqdm.auto import tqdm

        pts = points64.to(self.device, self.dtype)
        chunk = 1 << 16
        starts = range(0, pts.shape[-2], chunk)
        out = []
        for s in tqdm(starts, disable=not progress, desc="SDFSampler", unit="chunk"):
            out.append(self._evaluate_chunk(pts[..., s : s + chunk, :]))  # loop over chunks
        return torch.cat(out, -1) if out else pts.new_zeros(pts.shape[:-1])

    def _evaluate_chunk(self, pts: torch.Tensor) -> torch.Tensor:
        if self.sdf_fn is not None:  # float16/bfloat16: evaluated in float32, cast back
            with torch.no_grad():
                values = self.sdf_fn(pts.to(working_dtype(self.dtype)))
            if not isinstance(values, torch.Tensor) or values.shape != pts.shape[:-1]:
                raise ValueError(f"source: expected the SDF to return shape "
                                 f"{tuple(pts.shape[:-1])}, got "
                                 f"{getattr(values, 'shape', type(values))}")
            return cast_back(values.to(working_dtype(self.dtype)), self.dtype)
        verts = self.verts.to(self.device, self.dtype)
        with torch.no_grad():
            return mesh_sdf(verts, self.faces.to(self.device), pts, sign=self.sign,
                            backend=self.backend).sdf

    def surface_points(self, n: int) -> torch.Tensor:
        """``(*, n, 3)`` float64 CPU points on the surface.

        Meshes: area-weighted uniform. Functions: uniform points in the bounds pushed
        onto the zero set by 8 Newton steps ``p <- p - f grad f / |grad f|^2``, keeping
        those that converged (``|f| < 1e-6`` times the bounds' size) inside the bounds.
        For an exact SDF one step lands on the closest surface point, so the density
        favours convex, exposed parts; it is not exactly area-uniform.
        """
        self._check_worker()
        if self.sdf_fn is None:
            verts = self.verts.detach().cpu().double()
            return sample_mesh_surface(verts, self.faces.cpu(), n, self.generator)
        return self._function_surface_points(n)

    def _function_surface_points(self, n: int) -> torch.Tensor:
        size = float((self.bounds[1] - self.bounds[0]).max())
        work = working_dtype(self.dtype)  # float16/bfloat16: projected in float32
        found: list[torch.Tensor] = []
        have = 0
        for _ in range(50):  # rounds of rejection, not a loop over points
            p = self._uniform(max(2 * (n - have), 64)).to(self.device, work)
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
            ok = (f.abs() < 1e-6 * size * (10 if work == torch.float32 else 1)) & (
                (p >= lo) & (p <= hi)).all(-1)
            found.append(p[ok].double().cpu())
            have += int(ok.sum())
            if have >= n:
                return torch.cat(found)[:n]
        raise RuntimeError(f"SDFSampler: found only {have} of {n} surface points in 50 rounds; "
                           "does the shape's zero set lie inside the bounds?")

    def _draw(self, n: int, progress: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        n_uniform = int(round(n * self.uniform_fraction))
        n_near = n - n_uniform
        k = len(self.variances)
        per = math.ceil(n_near / k) if n_near else 0
        blocks = []
        if per:
            surface = self.surface_points(per)
            for var in self.variances:
                noise = torch.randn(surface.shape, generator=self.generator, dtype=torch.float64)
                blocks.append(surface + math.sqrt(var) * noise)
        near = (torch.cat(blocks, -2)[..., :n_near, :] if blocks
                else torch.zeros(*self.batch_shape, 0, 3, dtype=torch.float64))
        points = torch.cat([near, self._uniform(n_uniform)], -2)
        return points.to(self.device, self.dtype), self._evaluate(points, progress)

    def _balanced(self, n: int, progress: bool) -> tuple[torch.Tensor, torch.Tensor]:
        """``n // 2`` negatives then the positives, per mesh (rounds until every mesh has them)."""
        n_neg, n_pos = n // 2, n - n // 2
        pts, sdfs = [], []
        for _ in range(50):  # rounds of rejection
            p, s = self._draw(max(n, 256), progress)
            pts.append(p)
            sdfs.append(s)
            inside = torch.cat(sdfs, -1) < 0
            got_neg, got_pos = inside.sum(-1), (~inside).sum(-1)
            if bool((got_neg >= n_neg).all() and (got_pos >= n_pos).all()):
                break
        else:
            raise RuntimeError(f"SDFSampler: cannot balance, found {int(got_neg.min())} negative "
                               f"and {int(got_pos.min())} positive samples in 50 rounds")
        points, sdf = torch.cat(pts, -2), torch.cat(sdfs, -1)
        inside = sdf < 0
        # stable sorts keep the draw order: positives first, then negatives
        pos = torch.sort(inside.to(torch.uint8), dim=-1, stable=True).indices[..., :n_pos]
        neg = torch.sort((~inside).to(torch.uint8), dim=-1, stable=True).indices[..., :n_neg]
        order = torch.cat([pos, neg], -1)
        return torch.gather(points, -2, order[..., None].expand(*order.shape, 3)), \
            torch.gather(sdf, -1, order)

    # ----------------------------------------------------------------- public
    def sample(self, n: int, progress: bool = False) -> SDFSamples:
        """Draw ``n`` samples ``(points (*, n, 3), sdf (*, n))``.

        With ``balanced=True`` exactly ``n // 2`` are negative and the rest positive
        (extra rounds are drawn as needed; an error if the source has no inside).

        Args:
            n: number of samples (per mesh).
            progress: show a tqdm bar over the SDF evaluation chunks (off by default, as
                in ``SolverOptions(progress=...)`` of
                :func:`~torchgeo_cg.transforms.fit_transform`).

        Example:
            >>> from torchgeo_cg.sdf.primitives import sphere
            >>> g = torch.Generator().manual_seed(1)
            >>> s = SDFSampler(sphere, balanced=True, clamp=0.1, generator=g).sample(100)
            >>> int((s.sdf < 0).sum()), round(float(s.sdf.abs().max()), 4)
            (50, 0.1)
        """
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"n: expected a positive int, got {n!r}")
        self._check_worker()
        if not self.balanced:
            points, sdf = self._draw(n, progress)
        else:
            points, sdf = self._balanced(n, progress)
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

    Rows are ``(x, y, z, sdf)``; ``pos`` holds ``sdf >= 0`` (and NaN), ``neg`` holds
    ``sdf < 0``. The arrays have the dtype of the samples; bfloat16 (which NumPy lacks)
    is stored as float32 (``load_samples(..., dtype=torch.bfloat16)`` restores it).

    Args:
        path: file path (``.npz`` is appended by NumPy if missing).
        samples: :class:`SDFSamples` with ``points (N, 3)`` and ``sdf (N,)``, float
            tensors of one dtype (a ``TypeError`` naming both otherwise).

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
    check_float(sdf, "sdf")
    check_shape(points, ["N", "3"], "points")
    check_shape(sdf, ["N"], "sdf", {"N": points.shape[0]})
    check_same_dtype({"points": points, "sdf": sdf})
    rows = torch.cat([points, sdf[:, None]], dim=1).detach().cpu()
    rows = (rows.float() if rows.dtype == torch.bfloat16 else rows).numpy()
    inside = rows[:, 3] < 0
    np.savez(path, pos=rows[~inside], neg=rows[inside])


def load_samples(path: str | Path, device=None, dtype=None) -> SDFSamples:
    """Load ``.npz`` samples written by :func:`save_samples` (or DeepSDF): ``pos`` then ``neg``.

    Args:
        path: the ``.npz`` file.
        device, dtype: of the result (default: CPU, the stored dtype; ``pos`` and
            ``neg`` of different float dtypes are promoted by NumPy's rules).

    Returns:
        :class:`SDFSamples` ``(points (N, 3), sdf (N,))``, positive rows first.

    Raises:
        ValueError: ``pos`` or ``neg`` missing.
        ShapeError: ``pos`` or ``neg`` not of shape ``(M, 4)``.
        TypeError: ``pos`` or ``neg`` not floating point.

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
        arrays = {name: data[name] for name in ("pos", "neg")}
    for name, array in arrays.items():
        if array.ndim != 2 or array.shape[1] != 4:
            raise ShapeError(f"{name}: expected shape (M, 4) in {path}, got {array.shape}")
        if array.dtype.kind != "f":
            raise TypeError(f"{name}: expected floating-point rows in {path}, "
                            f"got dtype {array.dtype}")
    rows = torch.from_numpy(np.concatenate([arrays["pos"], arrays["neg"]]))
    rows = rows.to(device=device, dtype=dtype or rows.dtype)
    return SDFSamples(rows[:, :3], rows[:, 3])
