"""Shared internals of the neighbour searches: argument checks, the exact scale of the
search, and the choice of search (brute force, the torch grid, the Warp kernel).

Convention:
    See :mod:`torchgeo_cg.points.nearest_neighbors`.
"""

from __future__ import annotations

import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.numerics import power_of_two_scale
from torchgeo_cg.points._knn_kernels import warp_knn_indices
from torchgeo_cg.points._search_brute import brute_knn_indices
from torchgeo_cg.points._search_grid import grid_knn_indices

__all__: list[str] = []

#: Below this many (query, reference) pairs the brute-force search is used on the CPU.
BRUTE_FORCE_PAIRS = 1 << 18


def check_lengths(lengths, batch: tuple, size: int, name: str, device) -> torch.Tensor:
    """Validate ``lengths (*,)`` (or ``None`` = all ``size``) and return them as long.

    Example:
        >>> check_lengths(None, (2,), 5, "query_lengths", "cpu")
        tensor([5, 5])
        >>> check_lengths(torch.tensor([6, 1]), (2,), 5, "query_lengths", "cpu")
        Traceback (most recent call last):
        ...
        ValueError: query_lengths: expected values in [0, 5], got min 1 and max 6
    """
    if lengths is None:
        return torch.full(batch, size, dtype=torch.long, device=device)
    if not isinstance(lengths, torch.Tensor):
        lengths = torch.as_tensor(lengths, device=device)
    if lengths.is_floating_point() or lengths.is_complex() or lengths.dtype == torch.bool:
        raise TypeError(f"{name}: expected an integer tensor, got dtype {lengths.dtype}")
    if tuple(lengths.shape) != tuple(batch):
        raise ShapeError(f"{name}: expected shape {tuple(batch)} (the batch dims), "
                         f"got {tuple(lengths.shape)}")
    lengths = lengths.to(device=device, dtype=torch.long)
    if lengths.numel() and (int(lengths.min()) < 0 or int(lengths.max()) > size):
        raise ValueError(f"{name}: expected values in [0, {size}], got min "
                         f"{int(lengths.min())} and max {int(lengths.max())}")
    return lengths


def search_scale(query_bnd: torch.Tensor, reference_bmd: torch.Tensor, ql_b: torch.Tensor,
                 rl_b: torch.Tensor) -> torch.Tensor:
    """Per batch item, :func:`~torchgeo_cg.core.numerics.power_of_two_scale` of the largest
    valid coordinate: ``(B, 1, 1)``, 1 where there is none.

    Dividing by it is exact and brings the coordinates into ``[-1, 1]``, so the squared
    distances of the search neither overflow nor underflow at any scale.

    Example:
        >>> search_scale(torch.tensor([[[3.0, 0.0]]]), torch.tensor([[[0.0, -1e-3]]]),
        ...              torch.tensor([1]), torch.tensor([1])).flatten()
        tensor([4.])
    """
    B, N, _ = query_bnd.shape
    M = reference_bmd.shape[1]
    q_valid = (torch.arange(N, device=ql_b.device) < ql_b[:, None])[..., None]
    r_valid = (torch.arange(M, device=rl_b.device) < rl_b[:, None])[..., None]
    big = torch.cat([query_bnd.abs().masked_fill(~q_valid, 0).flatten(1),
                     reference_bmd.abs().masked_fill(~r_valid, 0).flatten(1),
                     query_bnd.new_zeros(B, 1)], dim=1).amax(1)
    return power_of_two_scale(big)[:, None, None]


def find_neighbours(query_bnd, reference_bmd, k, ql_b, rl_b, backend: str = "torch"
                    ) -> torch.Tensor:
    """Exact indices ``(B, N, k)`` (``-1`` where none) on finite-masked inputs, with a
    resolved ``backend`` (the Warp kernel runs for ``D`` in {2, 3}; other ``D`` search
    in torch)."""
    B, N, D = query_bnd.shape
    if backend == "warp" and D in (2, 3):
        return warp_knn_indices(query_bnd, reference_bmd, k, ql_b, rl_b)
    M = reference_bmd.shape[1]
    small = B * N * M <= BRUTE_FORCE_PAIRS
    if query_bnd.device.type != "cpu" or D > 3 or small:
        idx = brute_knn_indices(query_bnd, reference_bmd, k, rl_b)
        padded = torch.arange(N, device=query_bnd.device) >= ql_b[:, None]
        return idx.masked_fill(padded[..., None], -1)
    return grid_knn_indices(query_bnd, reference_bmd, k, ql_b, rl_b)
