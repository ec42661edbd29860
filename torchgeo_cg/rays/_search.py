"""The decision of a ray-mesh query: which face each ray hits first, or how many it crosses.

Runs without a graph on the exactly scaled float64 copy of the query
(:mod:`~torchgeo_cg.rays._prepare`). Candidates come from the torch grid walk
(:mod:`~torchgeo_cg.rays._grid`); every reported hit is decided by the float64
watertight test, and the first hit's ``t`` is refined in double-double where needed
(:func:`~torchgeo_cg.rays._evaluate.plane_t`).
"""

from __future__ import annotations

import torch

from torchgeo_cg.engine import resolve_backend
from torchgeo_cg.rays._evaluate import plane_t
from torchgeo_cg.rays._grid import build_grid, grid_hits
from torchgeo_cg.rays._prepare import RayProblem
from torchgeo_cg.rays._walk_warp import warp_first_faces

__all__: list[str] = []


def scaled_query(prob: RayProblem, t_min: float, t_max: float):
    """Flat float64 scaled data of the valid rays: ``(tri (B, T, 3, 3), rows, o, d, item,
    t_lo, t_hi, shift)``, ``rows`` the flat indices ``b * R + r`` of the valid rays; far
    origins are moved along their rays by ``shift`` (see ``_pull_in``).

    Example:
        >>> from torchgeo_cg.rays._prepare import prepare
        >>> p = prepare(torch.eye(3), torch.tensor([[0, 1, 2]]), torch.zeros(2, 3),
        ...             torch.tensor([[1.0, 1, 1], [0, 0, 0]]))
        >>> scaled_query(p, 0.0, 1.0)[1]  # the zero direction is not a ray
        tensor([0])
    """
    B, R = prob.origins.shape[:2]
    s, sd = prob.scale, prob.dscale
    v = prob.verts.detach().double() / s
    tri = v[:, prob.tris]  # (B, T, 3, 3)
    rows = prob.valid.reshape(-1).nonzero().squeeze(1)
    o = (prob.origins.detach().double() / s).reshape(B * R, 3).index_select(0, rows)
    d = (prob.directions.detach().double() / sd).reshape(B * R, 3).index_select(0, rows)
    ratio = (sd / s).reshape(B * R).index_select(0, rows)  # t' = t * ratio in scaled units
    item = torch.arange(B, device=v.device).repeat_interleave(R).index_select(0, rows)
    o, shift = _pull_in(o, d)
    return tri, rows, o, d, item, t_min * ratio - shift, t_max * ratio - shift, shift


def _pull_in(o: torch.Tensor, d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Origins beyond ``2**20`` (the scaled mesh lies in ``[-1, 1]``), moved along their ray
    to ``2 sqrt 3`` before its closest approach to the mesh's box: ``(o', shift)`` with
    ``o' = o + shift d`` (``shift = 0`` for the others).

    From so far, the rounding of ``o`` alone exceeds the grid's margin: the walk's cell
    arithmetic, and the corners relative to the origin, would lose the mesh's detail.
    No point of the mesh lies between the two origins, so the first hit is the same
    ray's, decided for the moved origin (within ``|o| eps`` of the given one).
    """
    far = o.abs().amax(-1) > 2.0**20
    if not bool(far.any()):
        return o, torch.zeros_like(o[:, 0])
    dd = (d * d).sum(-1)
    t_c = -(o * d).sum(-1) / dd
    shift = torch.where(far, (t_c - 2 * 3**0.5 / dd.sqrt()).clamp_min(0.0), 0.0)
    return o + shift[:, None] * d, shift


def first_hits(prob: RayProblem, t_min: float, t_max: float, backend: str
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """``(face (B, R) long, -1 where no hit; t (B, R) float64 in scaled units)``.

    Example:
        >>> from torchgeo_cg.rays._prepare import prepare
        >>> p = prepare(torch.eye(3), torch.tensor([[0, 1, 2]]), torch.zeros(1, 3),
        ...             torch.ones(1, 3))
        >>> first_hits(p, 0.0, float("inf"), "torch")
        (tensor([[0]]), tensor([[0.3333]], dtype=torch.float64))
    """
    B, R = prob.origins.shape[:2]
    T = prob.tris.shape[0]
    face = torch.full((B * R,), -1, dtype=torch.long, device=prob.origins.device)
    t_out = torch.zeros(B * R, dtype=torch.float64, device=face.device)
    with torch.no_grad():
        tri, rows, o, d, item, lo, hi, shift = scaled_query(prob, t_min, t_max)
        if rows.numel():
            grid = build_grid(tri)
            if resolve_backend(backend, o.device) == "warp":
                f = warp_first_faces(grid, o, d, item, lo, hi)
            else:
                _, f = grid_hits(grid, o, d, item, lo, hi, first=True)
            hit = (f >= 0).nonzero().squeeze(1)
            fh = f.index_select(0, hit)
            t_out[rows[hit]] = plane_t(tri.reshape(-1, 3, 3).index_select(0, fh),
                                        o.index_select(0, hit), d.index_select(0, hit)
                                        ) + shift.index_select(0, hit)
            face[rows[hit]] = fh - item.index_select(0, hit) * T
    return face.reshape(B, R), t_out.reshape(B, R)


def crossings(prob: RayProblem, t_min: float, t_max: float) -> torch.Tensor:
    """``(B, R)`` long: faces crossed by each ray in ``[t_min, t_max]`` (0 for non-rays).

    Example:
        >>> from torchgeo_cg.rays._prepare import prepare
        >>> p = prepare(torch.eye(3), torch.tensor([[0, 1, 2]]), torch.zeros(1, 3),
        ...             torch.ones(1, 3))
        >>> crossings(p, 0.0, float("inf"))
        tensor([[1]])
    """
    B, R = prob.origins.shape[:2]
    out = torch.zeros(B * R, dtype=torch.long, device=prob.origins.device)
    with torch.no_grad():
        tri, rows, o, d, item, lo, hi, shift = scaled_query(prob, t_min, t_max)
        if rows.numel():
            out[rows] = grid_hits(build_grid(tri), o, d, item, lo, hi, first=False)
    return out.reshape(B, R)
