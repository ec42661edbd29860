"""Marching squares: iso-lines of batched 2D fields as polylines, differentiable in the values.

Convention:
    - Fields are ``(*, H, W)`` with ``indexing="ij"``: array axis 0 is x and
      axis 1 is y, so ``field[..., i, j]`` is the value at the point
      ``origin + (i * spacing_x, j * spacing_y)``. Vertices come out as
      ``(x, y)``. With ``origin = (0, 0)`` and ``spacing = (1, 1)`` a vertex is
      exactly skimage's ``(row, col)``: ``skimage.measure.find_contours(f[b])``
      returns the same numbers (tested to 1e-6), with no axis swap, because
      skimage's row axis *is* our axis 0.
    - Tie rule, the one of :func:`torchgeo_cg.mesh.marching_cubes`: a corner is
      *low* (inside) when ``value < iso`` and *high* otherwise, so a sample exactly
      equal to ``iso`` is high. (scikit-image counts it differently, so results
      legitimately differ from ``find_contours`` where samples equal the level.)
    - The vertex on a crossing edge is the linear interpolation
      ``a + t (b - a)``, ``t = (iso - f_a) / (f_b - f_a)`` clamped to ``[delta, 1 -
      delta]``, ``delta = sqrt(finfo(dtype).eps)`` (a relative guard: no unit), so
      samples equal to ``iso`` never make two vertices coincide and no polyline is
      degenerate (zero length); where the clamp is active the gradient is zero.
    - Saddle cells (diagonal corners of one class): ``fully_connected="asymptotic"``
      (default) joins the low corners when the bilinear saddle value
      ``(f00 f11 - f01 f10) / (f00 + f11 - f01 - f10)`` is below ``iso``, decided
      exactly as the sign of ``g00 g11 - g01 g10`` with ``g = f - iso`` (no unit, no
      epsilon; a saddle exactly at ``iso`` is high, like a sample). ``"low"`` /
      ``"high"`` are scikit-image's fixed rules (join the low / high corners).
    - Orientation follows skimage (``positive_orientation="low"``): polylines keep
      values below ``iso`` on their left in (row, col) index space.
    - Closed polylines repeat their first vertex at the end, like skimage.
    - Cells with a NaN corner produce nothing (skimage skips them too); a NaN ``iso``
      raises ``ValueError``.
    - dtype: vertices have ``field``'s dtype; ``origin`` and ``spacing`` tensors are
      cast to it. float16/bfloat16 fields are computed in float32 (``delta`` of
      float32) and the vertices cast back.

Topology (which edges cross and how segments chain into polylines) is computed
without gradients, from a 16-case table (``_marching_squares_tables.py``);
vertex positions are gathered from the field, so they are differentiable with
respect to the field values (and origin and spacing). Segments are chained by
pointer jumping (``O(log V)`` vectorised rounds), never by a loop over vertices.
"""

from __future__ import annotations

import math
import numbers
from typing import NamedTuple

import numpy as np
import torch

from torchgeo_cg.core.check import ShapeError, check_choice, check_float, check_shape
from torchgeo_cg.core.grid import Volume, edge_fraction
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.curves._marching_squares_tables import SEGMENTS

__all__ = ["MarchingSquaresResult", "marching_squares", "SADDLE_RULES"]


class MarchingSquaresResult(NamedTuple):
    """Polylines of all fields, packed.

    Attributes:
        verts: ``(V, 2)`` polyline vertices ``(x, y)``, polyline after polyline.
        lengths: ``(P,)`` long, vertices per polyline (closed ones include the repeat).
        batch: ``(P,)`` long, the flat index of the field each polyline comes from.
        closed: ``(P,)`` bool, whether the polyline is a closed loop.

    Example:
        >>> fields = torch.tensor([[[1.0, -1.0], [1.0, -1.0]], [[1.0, 1.0], [1.0, 1.0]]])
        >>> result = marching_squares(fields)  # the second field has no crossing
        >>> result.polylines(), result.batch
        ([tensor([[0.0000, 0.5000],
                [1.0000, 0.5000]])], tensor([0]))
    """

    verts: torch.Tensor
    lengths: torch.Tensor
    batch: torch.Tensor
    closed: torch.Tensor

    def polylines(self) -> list[torch.Tensor]:
        """The polylines as a list of ``(L_p, 2)`` tensors (views of ``vertices``)."""
        return list(self.verts.split(self.lengths.tolist()))


def _pair(value, like: torch.Tensor, name: str) -> torch.Tensor:
    """One number, two numbers (sequence, numpy) or a ``(2,)`` tensor -> ``(2,)`` like ``like``."""
    if isinstance(value, torch.Tensor):
        check_float(value, name)
        out = value.to(device=like.device, dtype=like.dtype)
    else:
        if isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name}: expected two numbers or a (2,) tensor, got {value!r}")
        if isinstance(value, (numbers.Real, np.generic)) or np.ndim(value) == 0:
            value = (value, value)
        try:
            array = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise TypeError(f"{name}: expected two numbers or a (2,) tensor, "
                            f"got {value!r}") from err
        out = torch.as_tensor(array, device=like.device).to(like.dtype)
    check_shape(out, ["2"], name)
    return out


def _frame(field, origin, spacing):
    """Values, origin and spacing of a plain tensor or of a 2D (or one-slice 3D) Volume."""
    if not isinstance(field, Volume):
        return field, (0.0, 0.0) if origin is None else origin, (
            (1.0, 1.0) if spacing is None else spacing)
    for name, value in (("origin", origin), ("spacing", spacing)):
        if value is not None:
            raise TypeError(f"{name}: given with a Volume, which carries its own {name}")
    values, origin, spacing = field
    if origin.shape == (3,) and spacing.shape == (3,):
        if values.shape[-1] != 1:
            raise ShapeError(f"field: a 3D Volume must have one z sample, (*, H, W, 1), "
                             f"got {tuple(values.shape)}")
        return values[..., 0], origin[:2], spacing[:2]
    return values, origin, spacing


def _segment_table(fully_connected: str, device) -> torch.Tensor:
    return torch.tensor(SEGMENTS[fully_connected], dtype=torch.long, device=device)  # (16, 2, 2)


def _cell_segments(f, iso: float, b, i, j, case, rule: str) -> torch.Tensor:
    """``(N, 2, 2)`` directed segments of the active cells under the saddle ``rule``.

    Asymptotic decider: the low corners of a saddle cell are joined when its bilinear
    saddle value is below ``iso``, i.e. when ``g_ul g_lr - g_ur g_ll`` (``g = f - iso``,
    float64) is positive with ``ul`` low, or negative with ``ur`` low.
    """
    if rule != "asymptotic":
        return _segment_table(rule, f.device)[case]
    low_table, high_table = _segment_table("low", f.device), _segment_table("high", f.device)
    g = f.double() - iso
    ul, ur, ll, lr = g[b, i, j], g[b, i, j + 1], g[b, i + 1, j], g[b, i + 1, j + 1]
    det = ul * lr - ur * ll
    join_low = ((ul < 0) & (det > 0)) | ((ur < 0) & (det < 0))
    return torch.where(join_low[:, None, None], low_table[case], high_table[case])


def _chain(next_vertex: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Order vertices along chains given successors (``-1`` at ends).

    Every vertex has at most one successor and one predecessor, so the graph is a
    set of paths and cycles. Returns ``(order, chain_of_sorted, closed_tail)``:
    the vertex order along chains, the chain key of each ordered vertex (its
    tail), and per vertex whether it is the tail of a cut cycle.
    """
    count = next_vertex.shape[0]
    ids = torch.arange(count, device=next_vertex.device)
    rounds = max(1, math.ceil(math.log2(count + 1)) + 1)
    # 1. Find cycles: jump with tails looping onto themselves.
    ptr = torch.where(next_vertex >= 0, next_vertex, ids)
    least = ids.clone()
    for _ in range(rounds):
        least = torch.minimum(least, least[ptr])
        ptr = ptr[ptr]
    in_cycle = next_vertex[ptr] >= 0
    # 2. Cut each cycle in front of its smallest vertex; that vertex becomes the head.
    cut = in_cycle & (next_vertex == least)
    succ = torch.where(cut, torch.full_like(next_vertex, -1), next_vertex)
    # 3. List ranking: distance to the tail and the tail itself.
    ptr = torch.where(succ >= 0, succ, ids)
    dist = (succ >= 0).long()
    for _ in range(rounds):
        dist = dist + dist[ptr]
        ptr = ptr[ptr]
    tail = ptr
    order = torch.argsort(tail * (count + 1) + (count - dist), stable=True)
    return order, tail[order], cut


#: The saddle rules of :func:`marching_squares`.
SADDLE_RULES = ("asymptotic", "low", "high")


def _parse_arguments(field, iso, origin, spacing, fully_connected):
    """Validated ``(field, values (B, H, W) in the working dtype, iso, origin (2,),
    spacing (2,))`` of :func:`marching_squares` (its Raises section)."""
    field, origin, spacing = _frame(field, origin, spacing)
    if not isinstance(field, torch.Tensor):
        raise TypeError(f"field: expected a float tensor or a Volume, got {type(field).__name__}")
    check_float(field, "field")
    sizes = check_shape(field, ["*", "H", "W"], "field")
    height, width = sizes["H"], sizes["W"]
    if height < 2 or width < 2:
        raise ShapeError(
            f"field: expected H, W >= 2, got shape {tuple(field.shape)}")
    check_choice(fully_connected, SADDLE_RULES, "fully_connected")
    if isinstance(iso, torch.Tensor):
        iso = float(iso)
    if isinstance(iso, bool) or not isinstance(iso, (numbers.Real, np.generic)):
        raise TypeError(f"iso: expected a number, got {type(iso).__name__}")
    iso = float(iso)
    if math.isnan(iso):
        raise ValueError("iso: expected a number, got NaN")
    values = field.reshape(-1, height, width).to(working_dtype(field.dtype))  # (B, H, W)
    origin = _pair(origin, values, "origin")
    spacing = _pair(spacing, values, "spacing")
    if not bool((torch.isfinite(spacing) & (spacing > 0)).all()):
        raise ValueError(f"spacing: expected finite positive values, got {spacing.tolist()}")
    return field, values, iso, origin, spacing


def marching_squares(
    field: torch.Tensor | Volume,
    iso: float = 0.0,
    origin=None,
    spacing=None,
    fully_connected: str = "asymptotic",
) -> MarchingSquaresResult:
    """Extract the ``iso`` level lines of ``(*, H, W)`` fields as polylines.

    Convention:
        See the module docstring: ``indexing="ij"`` (axis 0 is x), vertices
        ``origin + index * spacing`` in ``(x, y)``; a sample equal to ``iso`` is
        high (as in marching cubes); saddles by the asymptotic decider; skimage's
        orientation; closed polylines repeat their first vertex.

    Args:
        field: ``(*, H, W)`` float values, ``H, W >= 2``, or a
            :class:`~torchgeo_cg.core.grid.Volume` with ``(2,)`` origin and spacing (or
            a one-slice 3D Volume, values ``(*, H, W, 1)``): origin and spacing then
            come from it and must not be given.
        iso: the level (a number, not NaN).
        origin: position of ``field[..., 0, 0]``: two numbers or a ``(2,)`` tensor
            (cast to ``field``'s dtype); default ``(0, 0)``.
        spacing: finite positive grid step along axis 0 (x) and axis 1 (y): two
            numbers, one number or a ``(2,)`` tensor (cast to ``field``'s dtype);
            default ``(1, 1)``.
        fully_connected: the saddle rule, one of :data:`SADDLE_RULES`.

    Returns:
        :class:`MarchingSquaresResult` ``(vertices (V, 2), lengths (P,), batch (P,),
        closed (P,))``; ``vertices`` is differentiable with respect to ``field``.

    Raises:
        TypeError: ``field`` is not a float tensor or Volume, or a bad argument type.
        ShapeError: ``field`` is not at least 2D with ``H, W >= 2``, or ``origin`` /
            ``spacing`` do not have two entries.
        ValueError: unknown ``fully_connected``, ``spacing`` not finite and positive, or
            ``iso`` NaN.

    Example:
        >>> f = torch.tensor([[1.0, 1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, 1.0]])
        >>> result = marching_squares(f)
        >>> result.verts
        tensor([[1.0000, 0.5000],
                [1.5000, 1.0000],
                [1.0000, 1.5000],
                [0.5000, 1.0000],
                [1.0000, 0.5000]])
        >>> result.lengths, result.closed
        (tensor([5]), tensor([True]))
    """
    field, values, iso, origin, spacing = _parse_arguments(field, iso, origin, spacing,
                                                           fully_connected)
    height, width = values.shape[-2:]
    n_h = height * (width - 1)  # edges along axis 1 ("horizontal" in index space)
    n_edges = n_h + (height - 1) * width
    with torch.no_grad():
        f = values.detach()
        above = ~(f < iso)  # the tie rule: equal to iso is high
        case = (above[:, :-1, :-1].long() + 2 * above[:, :-1, 1:].long()
                + 4 * above[:, 1:, :-1].long() + 8 * above[:, 1:, 1:].long())  # (B, H-1, W-1)
        nan = f.isnan()
        nan_cell = nan[:, :-1, :-1] | nan[:, :-1, 1:] | nan[:, 1:, :-1] | nan[:, 1:, 1:]
        case = torch.where(nan_cell, torch.zeros_like(case), case)
        b, i, j = ((case > 0) & (case < 15)).nonzero(as_tuple=True)  # active cells
        segments = _cell_segments(f, iso, b, i, j, case[b, i, j], fully_connected)
        valid = segments[..., 0] >= 0  # (N, 2)
        cell, slot = valid.nonzero(as_tuple=True)
        ends = segments[cell, slot]  # (S, 2) edge codes
        b, i, j = b[cell, None], i[cell, None], j[cell, None]
        # Global edge ids: top/bottom are axis-1 edges, left/right axis-0 edges.
        horizontal = b * n_edges + (i + (ends == 2).long()) * (width - 1) + j
        vertical = b * n_edges + n_h + i * width + j + (ends == 1).long()
        edge_id = torch.where((ends == 0) | (ends == 2), horizontal, vertical)  # (S, 2)
        unique_id, inverse = torch.unique(edge_id.reshape(-1), return_inverse=True)
        inverse = inverse.reshape(-1, 2)
        next_vertex = torch.full_like(unique_id, -1)
        next_vertex[inverse[:, 0]] = inverse[:, 1]
        order, chain, cut = _chain(next_vertex)
        # Chains: consecutive runs of equal keys; closed if its tail was a cut.
        _, counts = torch.unique_consecutive(chain, return_counts=True)
        starts = counts.cumsum(0) - counts
        closed = cut[chain[starts]] if counts.numel() else counts.bool()
        out_len = counts + closed.long()
        out_start = out_len.cumsum(0) - out_len
        chain_index = torch.repeat_interleave(torch.arange(counts.numel(), device=f.device),
                                              counts)
        rank = torch.arange(order.numel(), device=f.device) - starts[chain_index]
        gather = torch.empty(int(out_len.sum()), dtype=torch.long, device=f.device)
        gather[out_start[chain_index] + rank] = order
        gather[(out_start + counts)[closed]] = order[starts[closed]]
        # Decode each used edge id into its two grid corners.
        batch_of = unique_id // n_edges
        local = unique_id % n_edges
        is_h = local < n_h
        local_v = local - n_h
        i0 = torch.where(is_h, local // (width - 1), local_v // width)
        j0 = torch.where(is_h, local % (width - 1), local_v % width)
        i1 = i0 + (~is_h).long()
        j1 = j0 + is_h.long()
        polyline_batch = batch_of[order[starts]] if counts.numel() else counts
    fa = values[batch_of, i0, j0]  # differentiable gathers
    fb = values[batch_of, i1, j1]
    delta = math.sqrt(torch.finfo(values.dtype).eps)
    fraction = edge_fraction(fa, fb, fa.new_tensor(iso).expand_as(fa), delta)
    along_i = (~is_h).to(values.dtype)  # 1 on axis-0 edges: the fraction moves i
    index_xy = torch.stack([i0.to(values.dtype) + along_i * fraction,
                            j0.to(values.dtype) + (1 - along_i) * fraction], dim=-1)
    points = origin + index_xy * spacing  # (U, 2)
    vertices = cast_back(points[gather], field.dtype)
    return MarchingSquaresResult(vertices, out_len, polyline_batch, closed)
