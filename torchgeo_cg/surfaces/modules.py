"""Patches as modules with learnable control grids (and weights): Bezier, B-spline, NURBS.

Convention:
    ``forward(u, v)`` is the matching function of :mod:`torchgeo_cg.surfaces.patches`
    (paired parameters ``(*, N)`` -> points ``(*, N, D)``); ``derivatives(u, v)`` its
    ``*_derivatives`` sibling; ``domain`` the parameter rectangle
    ``(u_min, u_max, v_min, v_max)`` that :func:`~torchgeo_cg.surfaces.surface_mesh`
    samples. Knots are non-learnable buffers (``None``: the default clamped knots).
"""

from __future__ import annotations

import torch
from torch import nn

from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.surfaces._degree import check_surface_degree
from torchgeo_cg.surfaces.patches import (
    SurfaceDerivatives,
    bezier_surface,
    bezier_surface_derivatives,
    bspline_surface,
    bspline_surface_derivatives,
    nurbs_surface,
    nurbs_surface_derivatives,
)

__all__ = ["BezierSurface", "BSplineSurface", "NURBSSurface"]


def _store(module: nn.Module, name: str, value: torch.Tensor, learnable: bool) -> None:
    if learnable:
        setattr(module, name, nn.Parameter(value.detach().clone()))
    else:
        module.register_buffer(name, value, persistent=False)


def _ends(knots, count: int, degree: int) -> tuple[float, float]:
    if knots is None:
        return 0.0, 1.0
    return float(knots[..., degree].min()), float(knots[..., count].max())


class BezierSurface(nn.Module):
    """Bezier patch(es) with a learnable control grid; ``forward`` is :func:`bezier_surface`.

    Args:
        control_grid: ``(*, m + 1, n + 1, D)``.
        learnable: store the grid as an ``nn.Parameter`` (else a buffer).

    Example:
        >>> grid = torch.tensor([[[0.0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 1]]])
        >>> patch = BezierSurface(grid)
        >>> patch(torch.tensor([0.5]), torch.tensor([0.5])).detach(), patch.domain
        (tensor([[0.5000, 0.5000, 0.2500]]), (0.0, 1.0, 0.0, 1.0))
    """

    control_grid: torch.Tensor

    def __init__(self, control_grid: torch.Tensor, learnable: bool = True) -> None:
        super().__init__()
        bezier_surface(control_grid, control_grid.new_zeros(1), control_grid.new_zeros(1))
        self.learnable = learnable
        _store(self, "control_grid", control_grid, learnable)

    @property
    def domain(self) -> tuple[float, float, float, float]:
        """``(0, 1, 0, 1)``."""
        return 0.0, 1.0, 0.0, 1.0

    def forward(self, u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """``(*, N)`` paired parameters -> ``(*, N, D)`` points."""
        check_module_dtype(self, u, "u")
        check_module_dtype(self, v, "v")
        return bezier_surface(self.control_grid, u, v)

    def derivatives(self, u: torch.Tensor, v: torch.Tensor) -> SurfaceDerivatives:
        """See :func:`bezier_surface_derivatives`."""
        return bezier_surface_derivatives(self.control_grid, u, v)


class BSplineSurface(nn.Module):
    """B-spline patch(es) with a learnable control grid; ``forward`` is :func:`bspline_surface`.

    Args:
        control_grid: ``(*, m + 1, n + 1, D)``.
        degree: ``p`` or ``(p, q)``.
        knots_u, knots_v: full knot vectors or ``None``.
        learnable: store the grid as an ``nn.Parameter`` (else a buffer).

    Example:
        >>> grid = torch.stack(torch.meshgrid(torch.arange(4.0), torch.arange(3.0),
        ...                                   indexing="ij"), -1)
        >>> BSplineSurface(grid, (2, 1))(torch.tensor([0.5]), torch.tensor([0.5])).detach()
        tensor([[1.5000, 1.0000]])
    """

    control_grid: torch.Tensor
    knots_u: torch.Tensor | None
    knots_v: torch.Tensor | None

    def __init__(self, control_grid: torch.Tensor, degree, knots_u: torch.Tensor | None = None,
                 knots_v: torch.Tensor | None = None, learnable: bool = True) -> None:
        super().__init__()
        zero = control_grid.new_zeros(1)
        bspline_surface(control_grid, zero, zero, degree, knots_u, knots_v)
        self.degree, self.learnable = check_surface_degree(degree), learnable
        _store(self, "control_grid", control_grid, learnable)
        self.register_buffer("knots_u", None if knots_u is None else knots_u.detach().clone())
        self.register_buffer("knots_v", None if knots_v is None else knots_v.detach().clone())

    @property
    def domain(self) -> tuple[float, float, float, float]:
        """``(u_p, u_{m+1}, v_q, v_{n+1})`` of the knots."""
        rows, cols = self.control_grid.shape[-3:-1]
        return (*_ends(self.knots_u, rows, self.degree[0]),
                *_ends(self.knots_v, cols, self.degree[1]))

    def forward(self, u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """``(*, N)`` paired parameters -> ``(*, N, D)`` points."""
        check_module_dtype(self, u, "u")
        check_module_dtype(self, v, "v")
        return bspline_surface(self.control_grid, u, v, self.degree, self.knots_u, self.knots_v)

    def derivatives(self, u: torch.Tensor, v: torch.Tensor) -> SurfaceDerivatives:
        """See :func:`bspline_surface_derivatives`."""
        return bspline_surface_derivatives(self.control_grid, u, v, self.degree, self.knots_u,
                                           self.knots_v)


class NURBSSurface(BSplineSurface):
    """NURBS patches with learnable control grid and weights; ``forward`` is :func:`nurbs_surface`.

    Convention:
        The weights are a parameter the optimiser may move; keep them positive
        (:func:`nurbs_surface` rejects non-positive weights).

    Args:
        control_grid: ``(*, m + 1, n + 1, D)``.
        weights: ``(*, m + 1, n + 1)`` positive.
        degree: ``p`` or ``(p, q)``.
        knots_u, knots_v: full knot vectors or ``None``.
        learnable: store grid and weights as ``nn.Parameter`` (else buffers).

    Example:
        >>> arc = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        >>> grid = torch.stack([torch.cat([arc, torch.zeros(3, 1)], -1),
        ...                     torch.cat([arc, torch.ones(3, 1)], -1)], 1)
        >>> w = torch.tensor([1.0, 0.5 ** 0.5, 1.0])[:, None].expand(3, 2)
        >>> NURBSSurface(grid, w, (2, 1))(torch.tensor([0.5]), torch.tensor([1.0])).detach()
        tensor([[0.7071, 0.7071, 1.0000]])
    """

    weights: torch.Tensor

    def __init__(self, control_grid: torch.Tensor, weights: torch.Tensor, degree,
                 knots_u: torch.Tensor | None = None, knots_v: torch.Tensor | None = None,
                 learnable: bool = True) -> None:
        zero = control_grid.new_zeros(1)
        nurbs_surface(control_grid, weights, zero, zero, degree, knots_u, knots_v)
        super().__init__(control_grid, degree, knots_u, knots_v, learnable)
        _store(self, "weights", weights.to(control_grid.dtype), learnable)

    def forward(self, u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """``(*, N)`` paired parameters -> ``(*, N, D)`` points."""
        check_module_dtype(self, u, "u")
        check_module_dtype(self, v, "v")
        return nurbs_surface(self.control_grid, self.weights, u, v, self.degree, self.knots_u,
                             self.knots_v)

    def derivatives(self, u: torch.Tensor, v: torch.Tensor) -> SurfaceDerivatives:
        """See :func:`nurbs_surface_derivatives`."""
        return nurbs_surface_derivatives(self.control_grid, self.weights, u, v, self.degree,
                                         self.knots_u, self.knots_v)
