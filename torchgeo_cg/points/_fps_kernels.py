"""Warp kernels of farthest point sampling: one thread per cloud runs the greedy picks,
with the arithmetic and the tie rule of the torch loop
(:func:`torchgeo_cg.points.farthest_point_sampling`): squared distances summed
coordinate by coordinate without fused multiply-adds, the pick the first largest value.
Clouds are finite here (the caller sends a cloud with NaN to the torch loop); ``D`` in
{2, 3}.

Convention:
    No ``from __future__ import annotations``: Warp reads the annotations of the builder.
"""

from typing import Any

import torch

from torchgeo_cg.engine import launch, load_warp, register_kernels, to_warp

__all__: list[str] = []


def _build(wp):
    """The sampling kernels for 2D and 3D points, with float32 and float64 overloads."""

    @wp.kernel
    def fps3(points: wp.array2d(dtype=Any), lengths: wp.array(dtype=wp.int64), k: int,
             start: int, best: wp.array2d(dtype=Any), out: wp.array2d(dtype=wp.int64)):
        b = wp.tid()
        n_valid = int(lengths[b])
        inf = type(best[b, 0])(wp.inf)
        for n in range(n_valid):
            best[b, n] = inf
        pick = int(start)
        for i in range(wp.min(k, n_valid)):
            out[b, i] = wp.int64(pick)
            last = points[b, pick]
            top = int(0)  # noqa: UP018  a dynamic variable for Warp
            top_value = -inf
            for n in range(n_valid):
                d = points[b, n] - last
                d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
                value = best[b, n]
                if d2 < value:
                    value = d2
                if n == pick:
                    value = type(value)(-1.0)
                best[b, n] = value
                if value > top_value:
                    top = n
                    top_value = value
            pick = top

    @wp.kernel
    def fps2(points: wp.array2d(dtype=Any), lengths: wp.array(dtype=wp.int64), k: int,
             start: int, best: wp.array2d(dtype=Any), out: wp.array2d(dtype=wp.int64)):
        b = wp.tid()
        n_valid = int(lengths[b])
        inf = type(best[b, 0])(wp.inf)
        for n in range(n_valid):
            best[b, n] = inf
        pick = int(start)
        for i in range(wp.min(k, n_valid)):
            out[b, i] = wp.int64(pick)
            last = points[b, pick]
            top = int(0)  # noqa: UP018
            top_value = -inf
            for n in range(n_valid):
                d = points[b, n] - last
                d2 = d[0] * d[0] + d[1] * d[1]
                value = best[b, n]
                if d2 < value:
                    value = d2
                if n == pick:
                    value = type(value)(-1.0)
                best[b, n] = value
                if value > top_value:
                    top = n
                    top_value = value
            pick = top

    for scalar, v2, v3 in ((wp.float32, wp.vec2f, wp.vec3f), (wp.float64, wp.vec2d, wp.vec3d)):
        wp.overload(fps3, {"points": wp.array2d(dtype=v3), "best": wp.array2d(dtype=scalar)})
        wp.overload(fps2, {"points": wp.array2d(dtype=v2), "best": wp.array2d(dtype=scalar)})
    return fps2, fps3


_kernels = register_kernels(_build)


def warp_fps(p_bnd: torch.Tensor, len_b: torch.Tensor, k: int, start: int) -> torch.Tensor:
    """Greedy picks ``(B, k)`` (``-1`` past the valid points), as the torch loop.

    Example:
        >>> from torchgeo_cg.engine import warp_status
        >>> p = torch.tensor([[[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [3.0, 1.0]]])
        >>> if warp_status()[0] == "ok":
        ...     print(warp_fps(p, torch.tensor([4]), 3, 0).tolist())
        ... else:
        ...     print([[0, 3, 1]])
        [[0, 3, 1]]
    """
    B, N, D = p_bnd.shape
    out = torch.full((B, k), -1, dtype=torch.long, device=p_bnd.device)
    best = torch.empty(B, max(N, 1), dtype=p_bnd.dtype, device=p_bnd.device)
    wp = load_warp()
    vec = {(2, torch.float32): wp.vec2f, (3, torch.float32): wp.vec3f,
           (2, torch.float64): wp.vec2d, (3, torch.float64): wp.vec3d}[(D, p_bnd.dtype)]
    kernel = _kernels()[D - 2]
    launch(kernel, B, [to_warp(p_bnd, vec), to_warp(len_b.long()), k, start, to_warp(best),
                       to_warp(out)], p_bnd.device)
    return out
