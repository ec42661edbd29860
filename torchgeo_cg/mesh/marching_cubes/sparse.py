"""Marching cubes on a field (a callable), with memory that follows the surface.

:func:`sparse_marching_cubes` extracts the ``iso`` level set of a field ``(N, 3) ->
(N,)`` (an SDF, a network) on the grid of ``resolution`` samples over ``bounds``
without sampling the whole grid: only blocks of cells that can hold the surface are
sampled, and the mesh equals :func:`~torchgeo_cg.mesh.marching_cubes.marching_cubes` on
the fully sampled grid. :func:`lipschitz_bound` gives a provable bound for MLPs.

Convention:
    - The grid convention of ``sample_grid``: ``resolution`` samples per axis span
      ``bounds`` (both ends are samples), sample ``(i, j, k)`` at ``origin + spacing *
      (i, j, k)``, points made in the dtype and on the device of ``bounds``.
    - Inside is ``f < iso`` (negative-inside SDF; ``f == iso`` is outside), faces wound
      outward, as :func:`marching_cubes`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import torch
from torch import nn
from tqdm.auto import tqdm

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import check_choice
from torchgeo_cg.core.numerics import cast_back
from torchgeo_cg.engine import resolve_backend
from torchgeo_cg.mesh.marching_cubes._args import DEFAULT_AMBIGUITY
from torchgeo_cg.mesh.marching_cubes._blocks import band_blocks, lipschitz_blocks
from torchgeo_cg.mesh.marching_cubes._extract import assemble, extract_group
from torchgeo_cg.mesh.marching_cubes._field import (
    FieldEvaluator,
    Grid,
    check_lipschitz,
    check_positive_int,
    make_grid,
)
from torchgeo_cg.mesh.marching_cubes.dense import AMBIGUITY_RULES, MarchingCubesResult

__all__ = ["sparse_marching_cubes", "lipschitz_bound"]

#: Samples gathered per group of blocks (about): bounds the working memory.
_GROUP_SAMPLES = 1 << 21


def sparse_marching_cubes(
    field: Callable[[torch.Tensor], torch.Tensor],
    bounds: Sequence | torch.Tensor,
    resolution: int | Sequence[int],
    *,
    iso: float | torch.Tensor = 0.0,
    lipschitz: float | None = 1.0,
    band: int = 1,
    block: int = 8,
    max_points_per_call: int = 1 << 18,
    ambiguity: str = DEFAULT_AMBIGUITY,
    distributed: bool = False,
    progress: bool = False,
    backend: str = "auto",
) -> MarchingCubesResult:
    """The ``iso`` level set of ``field`` on a ``resolution`` grid, sampling near the surface only.

    How it extracts: the cells are grouped in blocks of ``block`` cells per side
    (partial at the far faces, so any resolution works). With a Lipschitz bound ``L``
    (``|f(x) - f(y)| <= L |x - y|``; 1 for an exact SDF), boxes of ``block * 2**k``
    cells are tested coarse to fine: a box whose centre value has ``|f(c) - iso| > L *
    half-diagonal`` (plus a slack for rounding, relative to the operands) holds no
    surface and is skipped with all its children. The samples of the remaining blocks
    go through the steps of :func:`marching_cubes` (classification, the
    ``ambiguity`` rule's decider, interpolation), and the vertices are welded across
    block seams by their global edge keys. The result equals :func:`marching_cubes` on
    the fully sampled grid: the same vertices in the same order (bit for bit, for a
    field that gives the same value for a point in any chunk), the same faces up to
    their order, watertight wherever the level set is closed inside the bounds.

    ``lipschitz=None`` (no known bound) is a narrow band: the block corners are
    sampled, blocks whose corners do not all share one class are refined, and so are
    those within ``band`` blocks of them. Every face it outputs is a face of the dense
    result, and every part of the surface within ``band`` blocks of a block with a
    coarse sign change is complete. It misses what passes between the block corners:
    a component smaller than a block (a droplet, a thin tube) farther than ``band``
    blocks from any coarse sign change, and a feature thinner than a block that
    crosses no block corner; such parts are absent or cut open at the band's edge.

    Differentiability: when autograd is on (``torch.is_grad_enabled()``) and the field's
    output requires grad (a network with parameters) or ``iso`` does, the samples the
    vertices read (the ends of each crossing edge and the normals' central differences)
    are evaluated again with autograd, and the vertices interpolate them exactly as
    :func:`marching_cubes` does, so the gradients equal those of the dense path
    (autograd through the sampled grid). The soft mode of :func:`marching_cubes`
    (``temperature``) is not offered: its weights need every cell's corner
    probabilities, also in the skipped blocks; ``face_weights`` are ones.

    ``distributed=True`` (under ``torchrun``, the default process group initialised by
    the caller): the points of every evaluation (each pruning level, each group of
    blocks) are split into one equal share per rank, each rank evaluates its share in
    chunks of at most ``max_points_per_call`` points, and the shares are all-gathered,
    so every rank evaluates about ``1 / world`` of the points and returns the same mesh,
    byte-identical to the single-process one.

    Memory: the field is evaluated under ``torch.no_grad()`` in chunks of at most
    ``max_points_per_call`` points, and blocks are processed in groups of about
    ``2**21`` samples, so the working memory grows with the active blocks (the
    surface), not with ``resolution**3``.

    Convention:
        The grid convention (``sample_grid``): world = ``origin + spacing * (i, j, k)``,
        ``origin = bounds[0]``, ``spacing = (bounds[1] - bounds[0]) / (resolution - 1)``;
        inside ``f < iso``; faces and normals outward; see :func:`marching_cubes`.

    Args:
        field: callable ``(N, 3) -> (N,)`` or ``(N, 1)``: a function, an ``nn.Module`` or
            an SDF of :mod:`torchgeo_cg.sdf`; it gets points of ``bounds``' dtype and
            device and must return values of the same dtype and device.
        bounds: ``(lo, hi)`` shared by the axes or ``((x0, y0, z0), (x1, y1, z1))``, a
            tensor (its dtype and device are the points') or numbers (default dtype).
        resolution: ``int`` or ``(X, Y, Z)`` samples, each at least 2.
        iso: the level (a number or a ``()`` tensor, differentiable).
        lipschitz: a bound ``L > 0`` of the field's slope, or ``None`` (narrow band).
        band: narrow-band dilation in blocks (``lipschitz=None`` only), ``>= 0``.
        block: cells per block side, ``>= 1``.
        max_points_per_call: the most points passed to ``field`` at once.
        ambiguity: one of :data:`AMBIGUITY_RULES`, as :func:`marching_cubes`.
        distributed: shard the evaluations over the ranks of the default process group.
        progress: tqdm bars over the levels and the groups of blocks.
        backend: ``"auto"`` | ``"torch"`` | ``"warp"``, as :func:`marching_cubes`:
            the blocks' cube cases, welded vertices and face lists from kernels; the
            mesh is identical.

    Returns:
        :class:`MarchingCubesResult` ``(verts (V, 3), faces (F, 3), normals (V, 3),
        face_weights (F,) ones, verts_per_mesh (1,), faces_per_mesh (1,))``; no surface
        gives empty tensors.

    Raises:
        TypeError: ``field`` is not callable or returns a non-tensor or another dtype;
            an argument has a wrong type.
        ShapeError: ``field`` returns a wrong shape, ``bounds`` a wrong shape.
        ValueError: ``field`` returns NaN or values on another device; ``bounds`` is not
            finite or empty; ``resolution`` < 2; ``lipschitz``, ``band``, ``block``,
            ``max_points_per_call``, ``ambiguity`` or ``backend`` out of range; ``iso`` NaN;
            ``distributed`` without an initialised process group.

    Example:
        >>> sphere = lambda p: p.norm(dim=1) - 0.5
        >>> mesh = sparse_marching_cubes(sphere, (-1.0, 1.0), 33, block=4)
        >>> mesh.verts.shape, mesh.faces.shape
        (torch.Size([1158, 3]), torch.Size([2312, 3]))
        >>> from torchgeo_cg.mesh import marching_cubes
        >>> x = torch.linspace(-1.0, 1.0, 33)
        >>> grid = torch.stack(torch.meshgrid(x, x, x, indexing="ij"), -1)
        >>> dense = marching_cubes(sphere(grid.view(-1, 3)).view(33, 33, 33),
        ...                        origin=(-1.0, -1.0, -1.0), spacing=(1 / 16,) * 3)
        >>> torch.equal(dense.verts, mesh.verts)
        True
    """
    grid, iso_t, L, evaluate = _parse(field, bounds, resolution, iso, lipschitz, band, block,
                                      max_points_per_call, ambiguity, distributed)
    backend = resolve_backend(backend, grid.origin.device)
    if L is None:
        blocks = band_blocks(evaluate, grid, float(iso_t), block, band)
    else:
        blocks = lipschitz_blocks(evaluate, grid, float(iso_t), L, block, progress)
    work = torch.float32 if grid.origin.dtype in (torch.float16, torch.bfloat16) else (
        grid.origin.dtype)
    grad = records_graph(iso_t, *_field_tensors(field, grid))
    per_group = max(1, max(_GROUP_SAMPLES, max_points_per_call) // (block + 1) ** 3)
    parts = []
    starts = range(0, blocks.shape[0], per_group)
    for s in tqdm(starts, disable=not progress, desc="sparse_marching_cubes", unit="group"):
        parts.append(extract_group(evaluate, grid, blocks[s:s + per_group], block, iso_t,
                                   ambiguity, work, place=not grad,
                                   backend=backend))  # loop over groups
    if not parts or all(p.keys.numel() == 0 for p in parts):
        return _empty(grid, work)
    lookup = _grad_lookup(evaluate, grid) if grad else None
    verts, normals, faces = assemble(parts, grid, work, lookup, iso_t.to(work))
    out = grid.origin.dtype
    counts = (torch.tensor([verts.shape[0]], device=faces.device),
              torch.tensor([faces.shape[0]], device=faces.device))
    return MarchingCubesResult(cast_back(verts, out), faces, cast_back(normals, out),
                               verts.new_ones(faces.shape[0]).to(out), *counts)


def _parse(field, bounds, resolution, iso, lipschitz, band, block, max_points_per_call,
           ambiguity, distributed):
    """Validated ``(grid, iso tensor, L, evaluator)``."""
    if not callable(field):
        raise TypeError(f"field: expected a callable (N, 3) -> (N,), got {type(field).__name__}")
    grid = make_grid(bounds, resolution)
    L = check_lipschitz(lipschitz)
    check_positive_int(band, "band", low=0)
    check_positive_int(block, "block")
    check_positive_int(max_points_per_call, "max_points_per_call")
    check_choice(ambiguity, AMBIGUITY_RULES, "ambiguity")
    if not isinstance(distributed, bool):
        raise TypeError(f"distributed: expected a bool, got {type(distributed).__name__}")
    if distributed and not (torch.distributed.is_available()
                            and torch.distributed.is_initialized()):
        raise ValueError("distributed: True needs an initialised default process group "
                         "(torch.distributed.init_process_group, e.g. under torchrun)")
    # a Python number takes the grid's dtype (never rounded through the default dtype)
    iso_t = torch.as_tensor(iso, device=grid.origin.device,
                            dtype=None if isinstance(iso, torch.Tensor) else grid.origin.dtype)
    if iso_t.numel() != 1:
        raise ValueError(f"iso: expected one number, got shape {tuple(iso_t.shape)}")
    iso_t = iso_t.reshape(()).to(grid.origin.dtype)
    if bool(torch.isnan(iso_t.detach())):
        raise ValueError("iso: expected a number, got nan")
    return grid, iso_t, L, FieldEvaluator(field, max_points_per_call, distributed)


def _field_tensors(field, grid: Grid) -> tuple:
    """The field's differentiable tensors: its parameters, or its output at one grid point."""
    if isinstance(field, nn.Module):
        return tuple(field.parameters())
    out = field(grid.points(torch.zeros(1, 3, dtype=torch.long, device=grid.origin.device)))
    return (out,) if isinstance(out, torch.Tensor) else ()


def _grad_lookup(evaluate: FieldEvaluator, grid: Grid):
    """Flat ids -> values with autograd, each distinct sample evaluated once."""
    def get(ids: torch.Tensor) -> torch.Tensor:
        uid, inverse = torch.unique(ids, return_inverse=True)
        return evaluate.with_grad(grid, grid.unflatten(uid))[inverse]
    return get


def _empty(grid: Grid, work) -> MarchingCubesResult:
    device, out = grid.origin.device, grid.origin.dtype
    counts = torch.zeros(1, dtype=torch.long, device=device)
    return MarchingCubesResult(torch.zeros(0, 3, dtype=out, device=device),
                               torch.zeros(0, 3, dtype=torch.long, device=device),
                               torch.zeros(0, 3, dtype=out, device=device),
                               torch.zeros(0, dtype=out, device=device), counts, counts.clone())


#: Activations whose slope is at most 1 everywhere.
_ONE_LIPSCHITZ = (nn.ReLU, nn.Softplus, nn.Tanh, nn.Sigmoid, nn.Identity, nn.Dropout,
                 nn.Hardtanh, nn.ReLU6, nn.Softsign, nn.Tanhshrink, nn.Hardsigmoid)


def lipschitz_bound(module: nn.Module) -> float:
    """A provable Lipschitz bound of an MLP: the product of its layers' spectral norms.

    Valid for an ``nn.Sequential`` (nested ones included) of ``nn.Linear`` layers and
    activations with slope at most 1 (ReLU, softplus, tanh, sigmoid, LeakyReLU and ELU
    with a parameter <= 1, ...): ``|f(x) - f(y)| <= L |x - y|`` in the Euclidean norm.
    The bound is loose for trained networks: on a network trained on a mesh SDF it can
    be 77 where the true slope is about 1.5, and then it prunes few blocks in
    :func:`sparse_marching_cubes`; use ``lipschitz=None`` (the narrow band) there, or a
    network built 1-Lipschitz.

    Args:
        module: the network (``nn.Linear`` or ``nn.Sequential``).

    Returns:
        ``L`` as a Python float.

    Raises:
        TypeError: ``module`` holds a layer not known to be 1-Lipschitz (its name given).

    Example:
        >>> net = nn.Sequential(nn.Linear(3, 4), nn.ReLU(), nn.Linear(4, 1))
        >>> with torch.no_grad():
        ...     _ = net[0].weight.copy_(2 * torch.eye(4, 3)); _ = net[2].weight.fill_(0.5)
        >>> lipschitz_bound(net)
        2.0
    """
    if not isinstance(module, nn.Module):
        raise TypeError(f"module: expected an nn.Module, got {type(module).__name__}")
    bound = 1.0
    for name, layer in _leaves(module, "module"):
        if isinstance(layer, nn.Linear):
            bound *= float(torch.linalg.matrix_norm(layer.weight.detach().double(), ord=2))
        elif isinstance(layer, (nn.LeakyReLU,)) and abs(layer.negative_slope) <= 1:
            continue
        elif isinstance(layer, nn.ELU) and 0 <= layer.alpha <= 1:
            continue
        elif isinstance(layer, nn.Softplus) or isinstance(layer, _ONE_LIPSCHITZ):
            continue
        else:
            raise TypeError(f"module: {name} is a {type(layer).__name__}, not known to be "
                            f"1-Lipschitz (expected Linear layers and activations such as "
                            f"ReLU, Softplus, Tanh)")
    return bound if math.isfinite(bound) else math.inf


def _leaves(module: nn.Module, name: str):
    """``(name, layer)`` of the layers of nested ``nn.Sequential`` in forward order."""
    if isinstance(module, nn.Sequential):
        for child_name, child in module.named_children():
            yield from _leaves(child, f"{name}.{child_name}")
    else:
        yield name, module
