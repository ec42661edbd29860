"""Closed test meshes and adversarial rays (aimed at vertices and edge midpoints)."""

from __future__ import annotations

import torch
import trimesh

from torchgeo_cg.mesh import marching_cubes
from torchgeo_cg.mesh.data import rabbit
from torchgeo_cg.mesh.faces import check_mesh
from torchgeo_cg.rays import ray_mesh_crossings

F64 = torch.float64

QUAD_CUBE_V = torch.tensor([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0)
                            for z in (0.0, 1.0)], dtype=F64)
QUAD_CUBE_F = torch.tensor([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6],
                            [0, 2, 6, 4], [1, 5, 7, 3]])


def icosphere(level: int = 3):
    ico = trimesh.creation.icosphere(level)
    return torch.tensor(ico.vertices, dtype=F64), torch.tensor(ico.faces)


def rabbit_mesh():
    m = rabbit(dtype=F64)
    return m.verts, m.faces


def marching_cubes_mesh():
    """A rounded box whose flat sides pass exactly through grid samples: marching cubes
    gives degenerate (zero-area) faces and many exactly coplanar ones."""
    g = torch.linspace(-1.0, 1.0, 17, dtype=F64)
    x, y, z = torch.meshgrid(g, g, g, indexing="ij")
    field = torch.stack([x.abs(), y.abs(), z.abs()]).amax(0) - 0.5
    field = torch.maximum(field, (x * x + y * y + z * z).sqrt() - 0.8)
    r = marching_cubes(field, 0.0, origin=(-1.0, -1.0, -1.0), spacing=(0.125,) * 3)
    return r.verts, r.faces


MESHES = {"icosphere": icosphere, "rabbit": rabbit_mesh, "marching_cubes": marching_cubes_mesh,
          "quad_cube": lambda: (QUAD_CUBE_V, QUAD_CUBE_F)}
CONVEX = ("icosphere", "quad_cube")


def vertex_normals(verts: torch.Tensor, tris: torch.Tensor) -> torch.Tensor:
    """Area-weighted vertex normals (not normalised)."""
    a, b, c = verts[tris].unbind(-2)
    n = torch.linalg.cross(b - a, c - a, dim=-1)
    return torch.zeros_like(verts).index_add_(0, tris.reshape(-1), n.repeat_interleave(3, 0))


def adversarial_rays(verts, faces, generator: torch.Generator, spread: float = 0.1):
    """Rays from outside the bounding sphere aimed exactly at every (used) vertex and
    every edge midpoint, arriving roughly against the surface normal there.

    Returns ``(origins, directions, targets)``: ``origins + 1 * directions == targets``
    up to rounding of the subtraction.
    """
    tris = check_mesh(verts, faces)
    normals = vertex_normals(verts, tris)
    edges = torch.cat([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    edges = edges.sort(1).values.unique(dim=0)
    used = tris.unique()
    targets = torch.cat([verts[used], (verts[edges[:, 0]] + verts[edges[:, 1]]) / 2])
    n = torch.cat([normals[used], normals[edges[:, 0]] + normals[edges[:, 1]]])
    n = n / n.norm(dim=-1, keepdim=True)
    n = n + spread * torch.randn(n.shape, generator=generator, dtype=F64)
    n = n / n.norm(dim=-1, keepdim=True)
    centre = verts[used].mean(0)
    radius = float((verts[used] - centre).norm(dim=-1).max())
    origins = targets + 3 * radius * n
    return origins, targets - origins, targets


def crossing_at_target(verts, faces, origins, directions, generator, tries: int = 4):
    """Mask of the rays that really cross the surface at their target (``t = 1``): every
    generic perturbation of the ray (origin moved by ``1e-7`` of the mesh size) crosses
    an odd number of times within ``t`` in ``1 +- 1e-4``; the others only touch there."""
    size = float((verts.amax(0) - verts.amin(0)).max())
    keep = torch.ones(origins.shape[0], dtype=torch.bool)
    for _ in range(tries):
        moved = origins + 1e-7 * size * torch.randn(origins.shape, generator=generator, dtype=F64)
        before = ray_mesh_crossings(verts, faces, moved, directions, t_max=1 - 1e-4)
        after = ray_mesh_crossings(verts, faces, moved, directions, t_max=1 + 1e-4)
        keep &= (after - before) % 2 == 1
    return keep
