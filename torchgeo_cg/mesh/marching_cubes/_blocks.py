"""Which blocks of cells can hold the surface: Lipschitz pruning or a narrow band.

A block is a cube of ``block`` cells per side, anchored at cell ``block * (bx, by, bz)``;
blocks at the far faces of the grid are partial. A block's closed region is the box
of its samples, ``origin + spacing * [i0, i1]`` (``i1 = min(i0 + block, X - 1)`` per axis).

Lipschitz pruning (coarse to fine): if ``|f(c) - iso| > L * h`` at the centre ``c`` of
a box of half-diagonal ``h``, every point of the box has ``f - iso`` of that sign, so
all its samples share one class and its cells make no triangle. The test is applied
to boxes of ``block * 2**k`` cells, from one box covering the grid down to the blocks;
only the children of boxes that pass the test are looked at. The field's own rounding
is covered by a slack of ``8 eps (|f(c)| + |iso| + L * extent)`` (``extent`` the largest
coordinate of the bounds), relative to the operands, so it has no unit.

Narrow band (no bound): the block corners are sampled, the blocks whose corners do not
all share one class are kept, and that set is dilated by ``band`` blocks.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from tqdm.auto import tqdm

from torchgeo_cg.mesh.marching_cubes._field import FieldEvaluator, Grid

__all__ = ["lipschitz_blocks", "band_blocks", "block_order"]


def _cells(grid: Grid) -> torch.Tensor:
    return torch.tensor(grid.sizes, device=grid.origin.device) - 1


def block_order(blocks: torch.Tensor, grid: Grid, block: int) -> torch.Tensor:
    """``blocks (M, 3)`` sorted by their flat block index (x-major), as the samples."""
    nb = (_cells(grid) + block - 1) // block
    flat = (blocks * torch.stack([nb[1] * nb[2], nb[2], torch.ones_like(nb[0])])).sum(1)
    return blocks[torch.argsort(flat)]


def _box_test(evaluate: FieldEvaluator, grid: Grid, blocks, size: int, iso: float, L: float):
    """``(M,)`` bool: boxes of ``size`` cells at ``blocks`` that may hold the surface."""
    ncell = _cells(grid)
    i0 = blocks * size
    i1 = torch.minimum(i0 + size, ncell)
    dtype = grid.origin.dtype
    centre = grid.origin + grid.spacing * ((i0 + i1).to(dtype) * 0.5)
    half_diag = torch.linalg.vector_norm(grid.spacing * (i1 - i0).to(dtype), dim=1) * 0.5
    f = evaluate(grid, centre)
    eps = torch.finfo(dtype).eps
    slack = 8 * eps * (f.abs() + abs(iso) + L * grid.extent)
    return (f - iso).abs() <= L * half_diag + slack


def lipschitz_blocks(evaluate: FieldEvaluator, grid: Grid, iso: float, L: float, block: int,
                     progress: bool = False) -> torch.Tensor:
    """``(M, 3)`` long block coordinates whose box may hold the surface, sorted.

    Example:
        >>> from torchgeo_cg.mesh.marching_cubes._field import make_grid
        >>> grid = make_grid((-1.0, 1.0), 33)
        >>> sphere = lambda p: p.norm(dim=1) - 0.5
        >>> lipschitz_blocks(FieldEvaluator(sphere, 4096, False), grid, 0.0, 1.0, 4).shape
        torch.Size([80, 3])
    """
    device = grid.origin.device
    ncell = _cells(grid)
    levels = max(0, math.ceil(math.log2(max(1.0, float(ncell.max()) / block))))
    offsets = torch.tensor([[(c >> 2) & 1, (c >> 1) & 1, c & 1] for c in range(8)],
                           device=device)
    blocks = torch.zeros(1, 3, dtype=torch.long, device=device)
    size = block << levels
    for level in tqdm(range(levels, -1, -1), disable=not progress, desc="blocks", unit="level"):
        blocks = blocks[_box_test(evaluate, grid, blocks, size, iso, L)]
        if level == 0:  # loop over levels, not over blocks
            break
        size //= 2
        blocks = (blocks[:, None, :] * 2 + offsets).view(-1, 3)
        blocks = blocks[(blocks * size < ncell).all(1)]
    return block_order(blocks, grid, block)


def band_blocks(evaluate: FieldEvaluator, grid: Grid, iso: float, block: int,
                band: int) -> torch.Tensor:
    """``(M, 3)`` long blocks whose corners change class, dilated by ``band`` blocks, sorted.

    Example:
        >>> from torchgeo_cg.mesh.marching_cubes._field import make_grid
        >>> grid = make_grid((-1.0, 1.0), 33)
        >>> sphere = lambda p: p.norm(dim=1) - 0.5
        >>> band_blocks(FieldEvaluator(sphere, 4096, False), grid, 0.0, 4, 0).shape
        torch.Size([56, 3])
    """
    ncell = _cells(grid)
    nb = ((ncell + block - 1) // block).tolist()
    axes = [torch.clamp_max(torch.arange(n + 1, device=ncell.device) * block, int(c))
            for n, c in zip(nb, ncell.tolist())]
    ijk = torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).view(-1, 3)
    inside = (evaluate(grid, ijk) < iso).view(1, 1, *(n + 1 for n in nb)).float()
    some_in = F.max_pool3d(inside, 2, stride=1)
    some_out = F.max_pool3d(1.0 - inside, 2, stride=1)
    mixed = some_in * some_out  # (1, 1, *nb)
    if band:
        mixed = F.max_pool3d(mixed, 2 * band + 1, stride=1, padding=band)
    return mixed[0, 0].nonzero()  # sorted x-major
