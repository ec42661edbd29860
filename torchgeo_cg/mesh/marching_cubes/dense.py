"""Marching cubes: vectorized, batched, differentiable, watertight (report section 1.4).

A thin public function over private steps (as scikit-image separates its wrapper
from its implementation): argument parsing (:mod:`._args`), then
classify, weld, triangulate, interpolate and soft weights
(``_steps``; ``_slabs`` schedules large volumes slab by slab), with the tables
generated in code (``_tables``). No Python loop over cells; the batch is stacked
along x, so one call costs one pass over all the volumes.

Positions are interpolated along the crossing edges with
``t = (iso - f1) / (f2 - f1)`` (report section 1.4), which is where gradients
flow to ``volume`` and ``iso``.

Convention:
    - Volumes are indexed ``indexing="ij"``: array axis 0 is x, 1 is y, 2 is z.
      Sample ``(i, j, k)`` sits at world ``origin + spacing * (i, j, k)``, computed by
      :func:`torchgeo_cg.core.grid.index_to_world` (the one grid convention); a
      :class:`~torchgeo_cg.core.grid.Volume` carries its own origin and spacing.
    - Negative inside (an SDF): a sample is *inside* when ``f < iso``; a sample
      exactly equal to ``iso`` is outside. This one rule classifies degenerate data.
    - Faces are wound counter-clockwise seen from the outside, so the right-hand
      normal ``(v1 - v0) x (v2 - v0)`` points towards increasing field values;
      ``normals`` (the unit field gradient) point the same way: along the edge the
      slope of the interpolant, across it central differences (one-sided at the
      border) blended with ``t``, in world units; unit at any gradient magnitude, and
      exactly zero where the gradient is zero.
    - ``ambiguity="asymptotic"`` (default): an ambiguous face (corners alternating in
      class) joins its inside corners when its bilinear saddle value
      ``(f00 f11 - f01 f10) / (f00 + f11 - f01 - f10)`` is below ``iso``, decided as the
      sign of ``g00 g11 - g01 g10`` (``g = f - iso``, float64, no epsilon; a saddle exactly
      at ``iso`` is outside, like a sample); both cells sharing the face compute it from
      the same samples, so the surface is closed and edge-manifold by construction.
      Where two loops of a cell could be joined by a tube, Marching Cubes 33's interior
      test decides (see :mod:`._decider`). Per-cell outlines then equal
      scikit-image's Lewiner method outside exact-iso ties; the triangles inside a cell
      may differ (diagonals, tube strips; a nine-edge loop is fanned around a vertex at
      the mean of its vertices, as Lewiner et al. fan around the cell centre).
    - ``ambiguity="separate"``: ambiguous cube faces separate the inside corners (see
      the tables module). The rule reads only the face's corners' classes, so the
      surface is closed and edge-manifold wherever it stays inside the volume.
    - Interpolation guard, scale-free: for a crossing edge ``f2 - f1`` is never zero
      (it is only replaced by one where it is exactly zero, i.e. for NaN data), and
      ``t`` is clamped to ``[delta, 1 - delta]`` with ``delta = sqrt(finfo.eps)`` of the
      working dtype (3.5e-4 in float32, 1.5e-8 in float64), so samples equal to ``iso``
      give neither duplicate vertices nor zero-area faces. Multiplying the field (and
      ``iso``) by any ``s > 0`` leaves vertices and faces unchanged (up to the rounding
      of the scaled samples), over the whole finite range of the dtype: decisions and
      samples near overflow are rescaled by powers of two, and normals depend on the
      ratios of the spacings only. Where the clamp is active the gradient is zero; the
      derivatives of ``t`` are formed with one division each, so they stay finite at
      any scale.
    - NaN: a NaN sample is neither inside nor outside, so it raises ``ValueError``
      (also under a ``mask``), as does a NaN ``iso``; a NaN ``origin`` gives NaN
      positions. Tensor ``iso``/``origin``/``spacing``/``temperature`` of another float
      dtype or device follow the volume's (cast; float32 for a half volume).
    - Half precision: float16/bfloat16 volumes are classified as they are (no copy
      of the volume) and interpolated in float32; positions, normals and weights are
      returned rounded to the input dtype (saturating at its largest finite value, as
      :func:`~torchgeo_cg.core.cast_back`). The no-duplicate/no-zero-area guarantee
      holds for the float32 positions; after rounding to the half type, vertices
      closer than the half type's resolution to a sample (or to each other) can
      coincide, so it is not guaranteed there (faces and topology are unchanged).
    - Batches are returned packed: ``faces`` index the packed ``verts``;
      :meth:`MarchingCubesResult.split` gives one mesh per volume.
    - Memory: a volume with more than ``2 * 2**15`` active cells, in hard mode
      without a ``mask`` and with no gradient recorded, is extracted slab by slab along
      the stacked x (the result is identical bit for bit), so the working buffers follow
      a slab of about ``2**15`` active cells, not the volume; under autograd (or
      with ``temperature`` or ``mask``) it runs in one go (``_slabs``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import torch
from torch import nn

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import check_choice
from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.core.grid import Volume
from torchgeo_cg.core.numerics import cast_back
from torchgeo_cg.engine import BACKENDS, resolve_backend
from torchgeo_cg.mesh.marching_cubes._args import DEFAULT_AMBIGUITY, parse_arguments, world_map
from torchgeo_cg.mesh.marching_cubes._decider import cell_rows
from torchgeo_cg.mesh.marching_cubes._kernels import kernel_backend
from torchgeo_cg.mesh.marching_cubes._slabs import extract_slabbed, wants_slabs
from torchgeo_cg.mesh.marching_cubes._steps import (
    Welded,
    any_centre,
    classify,
    find_centres,
    idiv,
    interpolate,
    place_centres,
    soft_weights,
    take,
    triangulate,
    weld,
)
from torchgeo_cg.mesh.marching_cubes._tables import AMBIGUOUS

__all__ = ["MarchingCubesResult", "marching_cubes", "MarchingCubes", "AMBIGUITY_RULES",
           "AMBIGUOUS_CASES"]

#: The accepted values of ``ambiguity``.
AMBIGUITY_RULES = ("asymptotic", "separate")
#: ``AMBIGUOUS_CASES[case]`` (256 bools): whether the topology of cube case ``case`` is a
#: choice, i.e. its inside or its outside corners are not connected along cube edges
#: (128 cases); there the ``ambiguity`` rule decides, and tools may differ. Bit ``c`` of
#: ``case`` is set when corner ``c = 4 dx + 2 dy + dz`` of the cell (offset ``(dx, dy,
#: dz)`` from its lower corner) is inside (``f < iso``).
AMBIGUOUS_CASES: tuple[bool, ...] = AMBIGUOUS


class MarchingCubesResult(NamedTuple):
    """The packed output of :func:`marching_cubes`.

    Attributes:
        verts: ``(V, 3)`` world positions, dtype of the volume.
        faces: ``(F, 3)`` long indices into ``verts`` (packed over the batch),
            wound outward.
        normals: ``(V, 3)`` unit field gradients at the vertices (outward).
        face_weights: ``(F,)`` probability of each face's cell configuration
            (soft mode), or ones when ``temperature=None``.
        verts_per_mesh: ``(B,)`` long, vertices of each volume (``B = 1`` unbatched).
        faces_per_mesh: ``(B,)`` long, faces of each volume.
    """

    verts: torch.Tensor
    faces: torch.Tensor
    normals: torch.Tensor
    face_weights: torch.Tensor
    verts_per_mesh: torch.Tensor
    faces_per_mesh: torch.Tensor

    def split(self) -> list[MarchingCubesResult]:
        """One result per volume, with ``faces`` re-indexed into that mesh's own ``verts``.

        Returns:
            A list of ``B`` results; each has ``verts_per_mesh`` and
            ``faces_per_mesh`` of shape ``(1,)``.

        Example:
            >>> x = torch.linspace(-1, 1, 8)
            >>> r2 = (torch.stack(torch.meshgrid(x, x, x, indexing="ij")) ** 2).sum(0)
            >>> result = marching_cubes(torch.stack([r2 - 0.5, r2 - 0.8]))
            >>> result.verts_per_mesh, result.faces_per_mesh
            (tensor([ 96, 192]), tensor([188, 380]))
            >>> [(m.verts.shape[0], int(m.faces.max())) for m in result.split()]
            [(96, 95), (192, 191)]
        """
        vcounts = self.verts_per_mesh.tolist()
        fcounts = self.faces_per_mesh.tolist()
        voffsets = [0]
        for n in vcounts[:-1]:
            voffsets.append(voffsets[-1] + n)
        parts = zip(
            self.verts.split(vcounts),
            self.faces.split(fcounts),
            self.normals.split(vcounts),
            self.face_weights.split(fcounts),
            self.verts_per_mesh.split(1),
            self.faces_per_mesh.split(1),
            voffsets,
        )
        return [
            MarchingCubesResult(v, f - off, n, w, vc, fc) for v, f, n, w, vc, fc, off in parts
        ]


def marching_cubes(
    volume: torch.Tensor | Volume,
    iso: float | torch.Tensor = 0.0,
    origin: Sequence[float] | torch.Tensor | None = None,
    spacing: Sequence[float] | torch.Tensor | None = None,
    temperature: float | torch.Tensor | None = None,
    mask: torch.Tensor | None = None,
    ambiguity: str = DEFAULT_AMBIGUITY,
    backend: str = "auto",
) -> MarchingCubesResult:
    """Extract the ``iso`` level set of one or a batch of volumes as welded triangle meshes.

    Convention:
        ``indexing="ij"`` (axis 0 is x), world = ``origin + spacing * index``;
        inside is ``f < iso`` (negative-inside SDF; ``f == iso`` is outside); faces
        wound outward (towards increasing values), normals likewise; closed level
        sets give watertight meshes with either ``ambiguity`` rule; ``t`` clamped to
        ``[delta, 1 - delta]``, ``delta = sqrt(finfo.eps)``. ``mask``: cell ``(i, j,
        k)`` (corners ``(i..i+1, j..j+1, k..k+1)``) makes triangles only when
        ``mask[i+1, j+1, k+1]`` (its far corner, corner 7) is True, which is what
        scikit-image's ``mask`` does. See the module docstring.

    Args:
        volume: ``(X, Y, Z)`` or ``(B, X, Y, Z)`` float samples, each of X, Y, Z >= 2,
            or a :class:`~torchgeo_cg.core.grid.Volume` (then ``origin`` and ``spacing``
            come from it and must not be given).
        iso: the level: a number, numpy scalar, or ``()`` / ``(B,)`` tensor or array
            (differentiable when a tensor).
        origin: world position of sample ``(0, 0, 0)``: 3 numbers, or a ``(3,)`` /
            ``(B, 3)`` tensor or array; default ``(0, 0, 0)``.
        spacing: finite positive sample spacing per axis, as ``origin``; default
            ``(1, 1, 1)``.
        temperature: ``None`` (hard mode, weights 1) or a positive number / ``()`` /
            ``(B,)`` tensor ``tau``: soft mode, where each corner is inside with
            probability ``p = sigmoid((iso - f) / tau)`` and every face of a cell gets
            the probability of its cell's configuration under independent corners
            (Liao et al. 2018, Deep Marching Cubes).
        mask: ``None`` or a bool ``(X, Y, Z)`` (shared by the batch) / ``(B, X, Y, Z)``
            tensor or array: only cells whose far corner is True make triangles;
            vertices no face uses are dropped.
        ambiguity: the rule for ambiguous faces and cells, one of
            :data:`AMBIGUITY_RULES` (see the module docstring).
        backend: ``"auto"`` | ``"torch"`` | ``"warp"``, resolved by
            :func:`torchgeo_cg.engine.resolve_backend`: with ``"warp"`` the cube cases,
            the welded vertices and the face lists come from compiled kernels (integers
            only; positions, normals and weights stay torch). The result is identical
            on both.

    Returns:
        :class:`MarchingCubesResult` ``(verts (V, 3), faces (F, 3) long, normals
        (V, 3), face_weights (F,), verts_per_mesh (B,), faces_per_mesh (B,))``,
        packed over the batch (``B = 1`` for an unbatched volume). No surface, or an
        empty batch (``B = 0``), gives empty tensors of the right shapes and dtypes.

    Raises:
        TypeError: ``volume`` is not a float tensor or Volume, an argument has a wrong
            type, or ``origin``/``spacing`` are given with a Volume.
        ShapeError: ``volume`` is not 3D/4D, has a spatial size < 2, or an argument
            has a wrong shape (or length).
        ValueError: ``spacing`` is not finite and positive, ``temperature`` is not
            positive, ``ambiguity`` or ``backend`` is unknown, ``iso`` is NaN, or a sample
            of ``volume`` is NaN (neither inside nor outside; also under a ``mask``).
        ImportError: ``backend="warp"`` and Warp cannot be loaded.

    Example:
        >>> x = torch.linspace(-1.0, 1.0, 5)
        >>> r2 = (torch.stack(torch.meshgrid(x, x, x, indexing="ij")) ** 2).sum(0)
        >>> mesh = marching_cubes(r2 - 0.36, origin=(-1.0, -1.0, -1.0), spacing=(0.5, 0.5, 0.5))
        >>> mesh.verts.shape, mesh.faces.shape, mesh.verts_per_mesh
        (torch.Size([30, 3]), torch.Size([56, 3]), tensor([30]))
        >>> mesh.verts[:2]
        tensor([[-0.5733,  0.0000,  0.0000],
                [-0.2200, -0.5000,  0.0000]])
        >>> mesh.normals[:2]
        tensor([[-1.0000,  0.0000,  0.0000],
                [-0.4472, -0.8944,  0.0000]])
        >>> mesh.faces[:2]
        tensor([[0, 4, 2],
                [0, 2, 6]])
        >>> soft = marching_cubes(r2 - 0.36, temperature=0.1)
        >>> soft.face_weights[:3]
        tensor([0.4723, 0.4723, 0.4723])
    """
    args = parse_arguments(volume, iso, origin, spacing, temperature, mask)
    check_choice(ambiguity, AMBIGUITY_RULES, "ambiguity")
    vol = args.vol
    backend = kernel_backend(resolve_backend(backend, vol.device), vol)
    B, X, Y, Z = vol.shape
    if B == 0:
        return _empty_result(vol)
    with torch.no_grad():
        cell_id, cases_a = classify(vol.detach(), args.iso.detach(), backend)
    if wants_slabs(cell_id.shape[0], args, _needs_grad(args)):
        verts, faces, normals, counts = extract_slabbed(vol, args, ambiguity, cell_id, cases_a,
                                                        backend)
        out = vol.dtype
        return MarchingCubesResult(cast_back(verts, out), faces, cast_back(normals, out),
                                   cast_back(verts.new_ones(faces.shape[0]), out), *counts)
    with torch.no_grad():
        welded = weld(cell_id, cases_a, (X, Y, Z), backend)
        rows, n_tri, tri_table, centre = cell_rows(vol.detach(), args.iso.detach(), args.mask,
                                                   cell_id, cases_a, ambiguity)
        has_centre = any_centre(rows, centre)
        faces, cell_of_face, centre_slot = triangulate(
            cell_id, rows, n_tri, tri_table, welded.key, (X, Y, Z), B, backend=backend,
            centres=has_centre)  # centre entries 0, filled by find_centres
        b_a = idiv(cell_id, X * Y * Z) if B > 1 else None  # (A,) volume of each active cell
        b_v = take(b_a, welded.cell) if B > 1 else None
        if args.mask is not None:  # drop the vertices only unmasked cells used
            welded, b_v, faces = _drop_unused(welded, b_v, faces, centre_slot)
        centres = None
        if has_centre:
            centres = find_centres(cell_id, rows, *centre, welded.key, cell_of_face,
                                   centre_slot, faces, (X, Y, Z))
    verts, normals = interpolate(vol, welded, b_v, args, world_map(args), backend)
    if centres is not None:
        verts, normals = place_centres(verts, normals, centres)
        if B > 1:  # keep the vertices grouped by volume
            with torch.no_grad():
                b_v = torch.cat([b_v, centres.b])
                order = torch.argsort(b_v, stable=True)
                new_id = torch.empty_like(order)
                new_id[order] = torch.arange(order.shape[0], device=order.device)
                faces = take(new_id, faces.view(-1)).view(-1, 3)
                b_v = take(b_v, order)
            verts, normals = take(verts, order), take(normals, order)
    with torch.no_grad():
        counts = _counts(b_v, take(b_a, cell_of_face) if B > 1 else None, verts, faces, B)
    if args.tau is None:
        face_weights = verts.new_ones(faces.shape[0])
    else:
        face_weights = soft_weights(vol, cell_id, cases_a, cell_of_face, args)
    out = vol.dtype  # half types saturate (a position beyond 65504 is not inf)
    return MarchingCubesResult(cast_back(verts, out), faces, cast_back(normals, out),
                               cast_back(face_weights, out), *counts)

def _needs_grad(args) -> bool:
    """Whether autograd records the call (a differentiable input under grad mode)."""
    return records_graph(args.vol, args.iso, args.origin, args.spacing)


def _empty_result(vol: torch.Tensor) -> MarchingCubesResult:
    """The result of an empty batch: no vertices, no faces, no meshes."""
    counts = torch.zeros(0, dtype=torch.long, device=vol.device)
    faces = torch.zeros(0, 3, dtype=torch.long, device=vol.device)
    return MarchingCubesResult(vol.new_zeros(0, 3), faces, vol.new_zeros(0, 3), vol.new_zeros(0),
                               counts, counts.clone())


def _drop_unused(welded: Welded, b_v, faces, centre_slot):
    """Keep only the vertices some face uses (after masking), re-indexing ``faces``
    (centre entries are filled later)."""
    used = torch.zeros(welded.key.shape[0], dtype=torch.bool, device=faces.device)
    used[faces.view(-1) if centre_slot is None else faces[~centre_slot]] = True
    new_id = used.long().cumsum(0) - 1
    keep = used.nonzero().squeeze(1)
    welded = Welded(*(take(x, keep) for x in welded))
    faces = take(new_id, faces.view(-1)).view(-1, 3)
    return welded, None if b_v is None else take(b_v, keep), faces


def _counts(b_v, b_f, verts, faces, batch):
    """``(verts_per_mesh (B,), faces_per_mesh (B,))``."""
    device = faces.device
    if batch == 1:
        return (torch.tensor([verts.shape[0]], device=device),
                torch.tensor([faces.shape[0]], device=device))
    return torch.bincount(b_v, minlength=batch), torch.bincount(b_f, minlength=batch)


class MarchingCubes(nn.Module):
    """Module form of :func:`marching_cubes`, with the same defaults.

    Tensor arguments (``iso``, ``origin``, ``spacing``, ``temperature``, ``mask``) are
    registered as non-persistent buffers, so ``.to()`` moves them; numbers are kept as
    numbers.

    Convention:
        As :func:`marching_cubes`: ``indexing="ij"``, world = ``origin + spacing *
        index``, inside ``f < iso``, faces and normals outward.

    Args:
        iso, origin, spacing, temperature, mask, ambiguity, backend: as in
            :func:`marching_cubes`.

    Shapes:
        ``forward(volume (X, Y, Z) or (B, X, Y, Z) or Volume) -> MarchingCubesResult``.

    Example:
        >>> x = torch.linspace(-1.0, 1.0, 5)
        >>> r2 = (torch.stack(torch.meshgrid(x, x, x, indexing="ij")) ** 2).sum(0)
        >>> MarchingCubes(iso=0.36)(r2).faces.shape
        torch.Size([56, 3])
    """

    def __init__(
        self,
        iso: float | torch.Tensor = 0.0,
        origin: Sequence[float] | torch.Tensor | None = None,
        spacing: Sequence[float] | torch.Tensor | None = None,
        temperature: float | torch.Tensor | None = None,
        mask: torch.Tensor | None = None,
        ambiguity: str = DEFAULT_AMBIGUITY,
        backend: str = "auto",
    ) -> None:
        super().__init__()
        check_choice(ambiguity, AMBIGUITY_RULES, "ambiguity")
        check_choice(backend, BACKENDS, "backend")
        self.ambiguity, self.backend = ambiguity, backend
        for name, value in (("iso", iso), ("origin", origin), ("spacing", spacing),
                            ("temperature", temperature), ("mask", mask)):
            if isinstance(value, torch.Tensor):
                self.register_buffer(name, value, persistent=False)
            else:
                setattr(self, name, value)

    def forward(self, volume: torch.Tensor | Volume) -> MarchingCubesResult:
        check_module_dtype(self, volume.values if isinstance(volume, Volume) else volume,
                           "volume")
        return marching_cubes(volume, self.iso, self.origin, self.spacing, self.temperature,
                              self.mask, self.ambiguity, self.backend)
