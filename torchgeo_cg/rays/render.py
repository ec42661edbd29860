"""Depth and normal images of a mesh or an SDF through any ray bundle.

``render_depth`` dispatches a mesh ``(verts, faces)`` to
:func:`~torchgeo_cg.rays.ray_mesh_intersect` and a callable SDF to
:func:`~torchgeo_cg.rays.sphere_trace`, and returns the images in the shape of the
bundle: an ``(H, W, 3)`` bundle gives ``(H, W)`` depth and ``(H, W, 3)`` normals.

Convention:
    ``depth`` is the ray parameter ``t`` (a distance along the ray for unit
    directions, *not* the camera-space z), ``inf`` where the ray misses, NaN for a NaN
    ray. ``normals`` are unit world-space normals, 0 where the ray misses: for a mesh
    the faces' winding normals (outward for an outward-wound closed mesh, not flipped
    toward the ray), for an SDF the normalised gradient (outward).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torchgeo_cg.rays.mesh_intersect import ray_mesh_intersect
from torchgeo_cg.rays.sphere_tracing import sphere_trace

__all__ = ["RenderResult", "render_depth"]


class RenderResult(NamedTuple):
    """Images of :func:`~torchgeo_cg.rays.render_depth`, in the shape ``(*)`` of the ray bundle.

    Attributes:
        depth: ``(*)`` ray parameter of the first hit (``inf`` without hit).
        normals: ``(*, 3)`` unit normals at the hits (0 without hit).
        mask: ``(*)`` bool, where a ray hit.
    """

    depth: torch.Tensor
    normals: torch.Tensor
    mask: torch.Tensor


def render_depth(scene, origins: torch.Tensor, directions: torch.Tensor, *,
                 t_max: float | None = None, lipschitz: float | None = 1.0,
                 backend: str = "auto") -> RenderResult:
    """Render depth, normals and a hit mask of a mesh or an SDF through a ray bundle.

    Convention:
        See :mod:`torchgeo_cg.rays.render`: depth is ``t`` along the ray; normals are
        the mesh's winding normals or the SDF's normalised gradient.

    Args:
        scene: ``(verts, faces)`` (``verts (V, 3)``, ``faces (F, K)``) or a callable
            SDF ``(N, 3) -> (N,)``.
        origins: ``(*, 3)`` ray origins (broadcast with ``directions``), e.g. one camera
            centre ``(3,)``.
        directions: ``(*, 3)`` ray directions, e.g. an ``(H, W, 3)`` pixel bundle.
        t_max: the farthest ``t``: optional for a mesh (default ``inf``), required for
            an SDF.
        lipschitz: the SDF's Lipschitz bound (see :func:`~torchgeo_cg.rays.sphere_trace`).
        backend: the mesh search (see :func:`~torchgeo_cg.rays.ray_mesh_intersect`).

    Returns:
        :class:`~torchgeo_cg.rays.RenderResult` ``(depth (*), normals (*, 3), mask (*))``,
        differentiable like the function it dispatches to.

    Raises:
        TypeError: ``scene`` is neither a ``(verts, faces)`` pair nor callable.
        ValueError: an SDF without ``t_max``.

    Example:
        >>> from torchgeo_cg.sdf import sphere
        >>> u = torch.linspace(-0.3, 0.3, 3)
        >>> y, x = torch.meshgrid(u, u, indexing="ij")
        >>> rays = torch.stack([x, y, -torch.ones_like(x)], -1)  # (3, 3, 3) pinhole bundle
        >>> eye = torch.tensor([0.0, 0.0, 3.0])
        >>> image = render_depth(lambda p: sphere(p, 1.0), eye, rays, t_max=10.0)
        >>> image.mask
        tensor([[False,  True, False],
                [ True,  True,  True],
                [False,  True, False]])
        >>> image.depth[1, 1]
        tensor(2.)
    """
    if callable(scene) and not isinstance(scene, (tuple, list)):
        if t_max is None:
            raise ValueError("t_max: an SDF scene needs a finite t_max, got None")
        hits = sphere_trace(scene, origins, directions, lipschitz=lipschitz, t_max=t_max)
    elif isinstance(scene, (tuple, list)) and len(scene) == 2:
        verts, faces = scene
        hits = ray_mesh_intersect(verts, faces, origins, directions,
                                  t_max=math.inf if t_max is None else t_max, backend=backend)
    else:
        raise TypeError("scene: expected a (verts, faces) pair or a callable SDF, got "
                        f"{type(scene).__name__}")
    return RenderResult(hits.t, hits.normals, hits.hit)
