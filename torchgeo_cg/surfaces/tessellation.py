"""A (u, v) grid mesh of a surface, for losses and files that take triangle meshes.

Convention:
    - ``resolution`` samples per direction (an int or ``(R_u, R_v)``, each ``>= 2``)
      span the surface's domain, ends included. Vertex ``i R_v + j`` is the sample
      ``(u_i, v_j)``.
    - Each grid cell ``(i, j)`` gives two triangles ``(a, b, c)``, ``(a, c, d)`` with
      ``a = (i, j)``, ``b = (i + 1, j)``, ``c = (i + 1, j + 1)``, ``d = (i, j + 1)``:
      counter-clockwise in the ``(u, v)`` plane, so face normals point along
      ``du x dv`` (the surfaces' normals). Faces are shared by the batch.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from torchgeo_cg.curves.bernstein import check_degree

__all__ = ["SurfaceMesh", "surface_mesh"]


class SurfaceMesh(NamedTuple):
    """Result of :func:`surface_mesh`.

    Attributes:
        verts: ``(*, R_u R_v, D)`` vertex positions.
        faces: ``(2 (R_u - 1)(R_v - 1), 3)`` int64 triangles.

    Example:
        >>> _grid_faces(2, 2)
        tensor([[0, 2, 3],
                [0, 3, 1]])
    """

    verts: torch.Tensor
    faces: torch.Tensor


def _grid_faces(rows: int, cols: int, device=None) -> torch.Tensor:
    """Triangles ``(2 (rows - 1)(cols - 1), 3)`` of a ``rows x cols`` vertex grid (see above).

    Example:
        >>> _grid_faces(2, 3).shape
        torch.Size([4, 3])
    """
    i = torch.arange(rows - 1, device=device)[:, None]
    j = torch.arange(cols - 1, device=device)[None, :]
    a = (i * cols + j).reshape(-1)
    b, c, d = a + cols, a + cols + 1, a + 1
    return torch.stack([torch.stack([a, b, c], -1), torch.stack([a, c, d], -1)], 1).reshape(-1, 3)


def _resolution(resolution) -> tuple[int, int]:
    pair = resolution if isinstance(resolution, (tuple, list)) else (resolution, resolution)
    if len(pair) != 2:
        raise ValueError(f"resolution: expected an int or a pair, got {resolution!r}")
    out = tuple(check_degree(r, "resolution") for r in pair)
    if min(out) < 2:
        raise ValueError(f"resolution: expected at least 2 samples per direction, got {resolution}")
    return out


def surface_mesh(surface, resolution, *, dtype=None, device=None) -> SurfaceMesh:
    """Tessellate a surface into a ``(u, v)`` grid mesh wound along ``du x dv``.

    Convention:
        See the module docstring. The result feeds ``mesh_sdf``, ``chamfer_distance``
        and ``save_mesh``; it is differentiable with respect to the surface's control
        points.

    Args:
        surface: a surface module (:class:`~torchgeo_cg.surfaces.BezierSurface`,
            :class:`~torchgeo_cg.surfaces.BSplineSurface`,
            :class:`~torchgeo_cg.surfaces.NURBSSurface`) or any callable
            ``f(u (N,), v (N,)) -> (*, N, D)``; its ``domain`` attribute
            ``(u0, u1, v0, v1)`` is used when present, else ``[0, 1]^2``.
        resolution: samples per direction, an int or ``(R_u, R_v)``, each ``>= 2``.
        dtype, device: of the parameters (default: the module's first parameter or
            buffer, else torch's defaults).

    Returns:
        :class:`SurfaceMesh` ``(verts (*, R_u R_v, D), faces (F, 3))``.

    Example:
        >>> from torchgeo_cg.surfaces import BezierSurface
        >>> grid = torch.tensor([[[0.0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 0]]])
        >>> mesh = surface_mesh(BezierSurface(grid), 3)
        >>> mesh.verts.shape, mesh.faces.shape
        (torch.Size([9, 3]), torch.Size([8, 3]))
        >>> a, b, c = mesh.verts.detach()[mesh.faces[0]]
        >>> torch.linalg.cross(b - a, c - a)  # along du x dv = +z
        tensor([0.0000, 0.0000, 0.2500])
    """
    rows, cols = _resolution(resolution)
    if dtype is None or device is None:
        tensors = list(surface.parameters()) + list(surface.buffers()) if hasattr(
            surface, "parameters") else []
        like = next((x for x in tensors if x is not None and x.is_floating_point()), None)
        dtype = dtype or (like.dtype if like is not None else torch.get_default_dtype())
        device = device or (like.device if like is not None else None)
    u0, u1, v0, v1 = getattr(surface, "domain", (0.0, 1.0, 0.0, 1.0))
    u = torch.linspace(u0, u1, rows, dtype=dtype, device=device)
    v = torch.linspace(v0, v1, cols, dtype=dtype, device=device)
    uu, vv = torch.meshgrid(u, v, indexing="ij")
    verts = surface(uu.reshape(-1), vv.reshape(-1))
    return SurfaceMesh(verts, _grid_faces(rows, cols, device=verts.device))
