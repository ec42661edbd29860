"""Shared internals of the neighbour searches: argument checks, the exact scale of the
search, and the choice of search (brute force, the torch grid, the Warp kernel).

Convention:
    See :mod:`torchgeo_cg.points.nearest_neighbors`.
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.numerics import power_of_two_scale
from torchgeo_cg.engine import kernel_ready
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
    if backend == "warp" and D in (2, 3) and kernel_ready(query_bnd, reference_bmd):
        return warp_knn_indices(query_bnd, reference_bmd, k, ql_b, rl_b)
    M = reference_bmd.shape[1]
    small = B * N * M <= BRUTE_FORCE_PAIRS
    if query_bnd.device.type != "cpu" or D > 3 or small:
        idx = brute_knn_indices(query_bnd, reference_bmd, k, rl_b)
        padded = torch.arange(N, device=query_bnd.device) >= ql_b[:, None]
        return idx.masked_fill(padded[..., None], -1)
    return grid_knn_indices(query_bnd, reference_bmd, k, ql_b, rl_b)


def check_positive(value, name: str, integer: bool = False) -> float:
    """``value`` as a float (an int when ``integer``), raising ``ValueError`` naming
    ``name`` unless it is a finite number ``> 0`` (``>= 1`` for an integer).

    Example:
        >>> check_positive(0.5, "radius")
        0.5
        >>> check_positive(0, "radius")
        Traceback (most recent call last):
        ...
        ValueError: radius: expected a finite number > 0, got 0
    """
    if isinstance(value, torch.Tensor) and value.numel() == 1 and not integer:
        value = value.item()
    if integer:
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name}: expected an int >= 1, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: expected a finite number > 0, got {value!r}")
    return float(value)


def gather_d2(q_bnd: torch.Tensor, r_bmd: torch.Tensor, idx_bnk: torch.Tensor) -> torch.Tensor:
    """Squared distances ``(B, N, k)`` from each query to its references ``idx`` (any value
    where ``idx < 0``), summed coordinate by coordinate as the searches (and the kernels)
    sum them, so the decisions made on them agree. No gradient (values that decide).

    Example:
        >>> q = torch.tensor([[[0.0, 0.0]]])
        >>> r = torch.tensor([[[3.0, 4.0], [1.0, 0.0]]])
        >>> gather_d2(q, r, torch.tensor([[[1, 0, -1]]]))
        tensor([[[ 1., 25., 25.]]])
    """
    B, N, k = idx_bnk.shape
    D = q_bnd.shape[-1]
    if r_bmd.shape[1] == 0:
        return q_bnd.new_zeros(B, N, k)
    flat = idx_bnk.reshape(B, N * k)
    if N * k and int(flat.min()) < 0:
        flat = flat.clamp_min(0)
    with torch.no_grad():  # in place: two buffers of (B, N, k), not one per operation
        d2 = torch.gather(r_bmd[..., 0], 1, flat).view(B, N, k)
        d2.sub_(q_bnd[..., 0, None])
        d2.mul_(d2)
        diff = torch.empty_like(flat, dtype=d2.dtype) if D > 1 else None
        for a in range(1, D):  # loop over coordinates
            torch.gather(r_bmd[..., a], 1, flat, out=diff)
            step = diff.view(B, N, k).sub_(q_bnd[..., a, None])
            d2.add_(step.mul_(step))
    return d2


def compact_finite(r_bmd: torch.Tensor, rl_b: torch.Tensor):
    """The valid finite rows of every item moved to the front ``(B, M, D)`` (zeros after
    them), their count ``(B,)`` and their original row ``(B, M)``: a stable compaction,
    so the order (and the tie rule on it) is kept.

    Example:
        >>> r = torch.tensor([[[0.0], [float("nan")], [2.0]]])
        >>> packed, count, order = compact_finite(r, torch.tensor([3]))
        >>> packed.flatten().tolist(), count.tolist(), order.tolist()
        ([0.0, 2.0, 0.0], [2], [[0, 2, 1]])
    """
    B, M, D = r_bmd.shape
    valid = torch.isfinite(r_bmd).all(-1) & (torch.arange(M, device=r_bmd.device)
                                             < rl_b[:, None])
    order = torch.sort((~valid).to(torch.int8), dim=1, stable=True).indices
    packed = torch.gather(r_bmd, 1, order[..., None].expand(-1, -1, D))
    count = valid.sum(-1)
    keep = torch.arange(M, device=r_bmd.device) < count[:, None]
    return torch.where(keep[..., None], packed, 0.0), count, order


def self_knn(p_bnd: torch.Tensor, len_b: torch.Tensor, k: int, backend: str):
    """The ``k`` nearest finite points of every finite point of its own cloud (itself
    included), as original row indices ``(B, N, k)`` (``-1`` where none, and for
    non-finite or padded rows), and the cloud scaled by its exact search scale."""
    B, N, D = p_bnd.shape
    packed, count, order = compact_finite(p_bnd, len_b)
    scale = search_scale(packed, packed, count, count)
    ok = torch.isfinite(p_bnd).all(-1) & (torch.arange(N, device=p_bnd.device)
                                          < len_b[:, None])
    q = torch.where(ok[..., None], p_bnd, 0.0) / scale
    idx = find_neighbours(q, packed / scale, k, len_b, count, backend)
    if bool((count == len_b).all()):  # every valid row finite: the packing is the identity
        return idx, ok  # (and rows past the lengths are -1 already)
    idx = torch.where(idx >= 0, order.gather(1, idx.clamp_min(0).flatten(1)).view_as(idx), -1)
    return idx.masked_fill(~ok[..., None], -1), ok
