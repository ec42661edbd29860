"""Rays: exact ray casting on meshes and sphere tracing of a network SDF.

Targets, 1 thread, ratios measured side by side in one process:

- First hit on an 81,920-face icosphere (trimesh level 6), 200,000 random rays (origins
  on a sphere of radius 2.5, aimed at random points of a box around the mesh; ~95% hit):
  ``ray_mesh_intersect`` with the default backend (Warp, float64 decisions) <= 3x Open3D
  (``RaycastingScene`` scene build + ``cast_rays``, float32, 1 thread); with
  ``backend="torch"`` <= 20x.
- ``sphere_trace`` of an 8-layer MLP SDF (a sphere plus an MLP of width 64) at 256 x 256
  rays, ``lipschitz=None``: <= 1.5x the time of the same field evaluations (the same
  numbers of points per call, replayed) without the march; the backward pass of ``t``
  <= 2x one forward evaluation of the field at the hits.

The notes of the first row log, side by side, how Open3D, Warp's bare float32
``mesh_query_ray`` and ours do on rays aimed exactly at the vertices and edge midpoints
of closed meshes (an icosphere, the shipped rabbit, a marching-cubes output, a cube of
quads, and rays exact in float32 through vertices, edges and diagonals): each should hit
every ray that crosses the surface there, and count an even number of crossings from
outside (Open3D's ``count_intersections`` counts a crossing at an edge twice).
"""

from __future__ import annotations

import time

import numpy as np
import torch
from torch import nn

from benchmarks.harness import Case
from torchgeo_cg.engine import load_warp, warp_status
from torchgeo_cg.mesh import marching_cubes
from torchgeo_cg.mesh.data import rabbit
from torchgeo_cg.mesh.faces import check_mesh
from torchgeo_cg.rays import ray_mesh_crossings, ray_mesh_intersect, sphere_trace

F64 = torch.float64


def _icosphere(level: int):
    import trimesh

    ico = trimesh.creation.icosphere(level)
    return torch.tensor(ico.vertices, dtype=F64), torch.tensor(ico.faces)


def _random_rays(n: int, gen: torch.Generator):
    o = 2.5 * torch.nn.functional.normalize(torch.randn(n, 3, generator=gen, dtype=F64), dim=-1)
    d = 0.8 * (2 * torch.rand(n, 3, generator=gen, dtype=F64) - 1) - o
    return o, d


def _open3d_first_hit(verts, tris, o, d):
    import open3d as o3d

    v32 = o3d.core.Tensor(verts.float().numpy())
    f32 = o3d.core.Tensor(tris.numpy().astype(np.uint32))
    rays = o3d.core.Tensor(torch.cat([o, d], 1).float().numpy())

    def run():
        scene = o3d.t.geometry.RaycastingScene(nthreads=1)
        scene.add_triangles(v32, f32)
        return scene.cast_rays(rays, nthreads=1)

    return run


# ----------------------------------------------------------------------------- parity


def _adversarial(verts, faces, gen):
    """Rays from outside aimed at every vertex and edge midpoint against the normal there,
    and the mask of those that really cross at their target (generic perturbations)."""
    tris = check_mesh(verts, faces)
    a, b, c = verts[tris].unbind(-2)
    fn = torch.linalg.cross(b - a, c - a, dim=-1)
    vn = torch.zeros_like(verts).index_add_(0, tris.reshape(-1), fn.repeat_interleave(3, 0))
    edges = torch.cat([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    edges = edges.sort(1).values.unique(dim=0)
    used = tris.unique()
    target = torch.cat([verts[used], (verts[edges[:, 0]] + verts[edges[:, 1]]) / 2])
    n = torch.nn.functional.normalize(torch.cat([vn[used], vn[edges[:, 0]] + vn[edges[:, 1]]]))
    n = torch.nn.functional.normalize(n + 0.1 * torch.randn(n.shape, generator=gen, dtype=F64))
    radius = float((verts[used] - verts[used].mean(0)).norm(dim=-1).max())
    o = target + 3 * radius * n
    d = target - o
    size = float((verts.amax(0) - verts.amin(0)).max())
    crossing = torch.ones(o.shape[0], dtype=torch.bool)
    for _ in range(4):
        moved = o + 1e-7 * size * torch.randn(o.shape, generator=gen, dtype=F64)
        before = ray_mesh_crossings(verts, faces, moved, d, t_max=1 - 1e-4)
        after = ray_mesh_crossings(verts, faces, moved, d, t_max=1 + 1e-4)
        crossing &= (after - before) % 2 == 1
    return tris, o[crossing], d[crossing]


def _warp_bare_hits(verts, tris, o, d) -> torch.Tensor:
    """Warp's own float32 ``mesh_query_ray`` (the peer a Warp user has)."""
    wp = load_warp()

    @wp.kernel
    def cast(mesh: wp.uint64, o: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3),
             hit: wp.array(dtype=wp.int32)):
        i = wp.tid()
        q = wp.mesh_query_ray(mesh, o[i], d[i], 1.0e30)
        if q.result:
            hit[i] = 1

    points = wp.array(verts.float().numpy(), dtype=wp.vec3)
    mesh = wp.Mesh(points=points, indices=wp.array(tris.int().reshape(-1).numpy(),
                                                   dtype=wp.int32))
    out = wp.zeros(o.shape[0], dtype=wp.int32)
    wp.launch(cast, o.shape[0], inputs=[mesh.id, wp.array(o.float().numpy(), dtype=wp.vec3),
                                        wp.array(d.float().numpy(), dtype=wp.vec3), out])
    return torch.from_numpy(out.numpy()).bool()


def _exact_axis_rays(verts):
    """Rays exact in float32 too: from ``4 v`` toward the origin through each vertex ``v``
    (radial), for a convex mesh centred at 0 whose vertices are float32 numbers."""
    return 4 * verts, -2 * verts


def _grid_rays(lo: float, hi: float, step: float, z: float):
    """Rays along -z through the grid points ``(x, y)`` of ``[lo, hi]^2`` (exact)."""
    g = torch.arange(lo, hi + step / 2, step, dtype=F64)
    x, y = torch.meshgrid(g, g, indexing="ij")
    o = torch.stack([x.reshape(-1), y.reshape(-1), torch.full((x.numel(),), z, dtype=F64)], -1)
    return o, torch.tensor([0.0, 0.0, -1.0], dtype=F64).expand_as(o)


def _count_hits(verts, faces, tris, o, d) -> str:
    import open3d as o3d

    ours = int(ray_mesh_intersect(verts, faces, o, d).hit.sum())
    scene = o3d.t.geometry.RaycastingScene(nthreads=1)
    scene.add_triangles(o3d.core.Tensor(verts.float().numpy()),
                        o3d.core.Tensor(tris.numpy().astype(np.uint32)))
    rays = o3d.core.Tensor(torch.cat([o, d], 1).float().numpy())
    o3d_hits = int(np.isfinite(scene.cast_rays(rays)["t_hit"].numpy()).sum())
    bare = int(_warp_bare_hits(verts, tris, o, d).sum()) if warp_status()[0] == "ok" else None
    # parity from outside: an odd count is wrong
    odd_ours = int((ray_mesh_crossings(verts, faces, o, d) % 2).sum())
    odd_o3d = int((scene.count_intersections(rays).numpy() % 2).sum())
    return (f"{o.shape[0]} crossing rays hit: ours {ours}, open3d {o3d_hits}, warp_f32 "
            f"{bare}; odd crossing counts from outside: ours {odd_ours}, open3d {odd_o3d}")


def _parity_notes() -> dict:

    gen = torch.Generator().manual_seed(0)
    g = torch.linspace(-1.0, 1.0, 17, dtype=F64)
    x, y, z = torch.meshgrid(g, g, g, indexing="ij")
    field = torch.maximum(torch.stack([x.abs(), y.abs(), z.abs()]).amax(0) - 0.5,
                          (x * x + y * y + z * z).sqrt() - 0.8)
    mc = marching_cubes(field, 0.0, origin=(-1.0,) * 3, spacing=(0.125,) * 3)
    cube_v = torch.tensor([[a, b, c] for a in (0.0, 1.0) for b in (0.0, 1.0)
                           for c in (0.0, 1.0)], dtype=F64)
    cube_f = torch.tensor([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6],
                           [0, 2, 6, 4], [1, 5, 7, 3]])
    rb = rabbit(dtype=F64)
    meshes = {"icosphere": _icosphere(3), "rabbit": (rb.verts, rb.faces),
              "marching_cubes": (mc.verts, mc.faces), "quad_cube": (cube_v, cube_f)}
    notes = {}
    for name, (verts, faces) in meshes.items():
        tris, o, d = _adversarial(verts, faces, gen)
        notes[f"parity_{name}"] = _count_hits(verts, faces, tris, o, d)
    # rays exactly through vertices, edges and diagonals in float32 as well
    ico_v, ico_f = _icosphere(3)
    ico_v = ico_v.float().double()
    notes["parity_icosphere_radial_f32_exact"] = _count_hits(ico_v, ico_f, ico_f,
                                                             *_exact_axis_rays(ico_v))
    cube_t = check_mesh(cube_v, cube_f)
    notes["parity_quad_cube_axis_grid"] = _count_hits(cube_v, cube_f, cube_t,
                                                      *_grid_rays(0.125, 0.875, 0.125, 3.0))
    notes["parity_marching_cubes_axis_grid"] = _count_hits(
        mc.verts, mc.faces, mc.faces, *_grid_rays(-0.375, 0.375, 0.125, 3.0))
    return notes


# ----------------------------------------------------------------------------- sphere trace


class _MLPSDF(nn.Module):
    """A sphere of radius 0.8 plus a small 8-layer MLP (width ``w``, softplus)."""

    def __init__(self, w: int):
        super().__init__()
        layers: list[nn.Module] = [nn.Linear(3, w), nn.Softplus(beta=10)]
        for _ in range(6):
            layers += [nn.Linear(w, w), nn.Softplus(beta=10)]
        layers.append(nn.Linear(w, 1))
        self.mlp = nn.Sequential(*layers)

    def forward(self, p):
        return p.norm(dim=-1) - 0.8 + 0.02 * torch.tanh(self.mlp(p).squeeze(-1))


def _trace_cases(size: int, width: int) -> list[Case]:
    torch.manual_seed(0)
    net = _MLPSDF(width)
    u = torch.linspace(-0.45, 0.45, size)
    yy, xx = torch.meshgrid(-u, u, indexing="ij")
    d = torch.stack([xx, yy, -torch.ones_like(xx)], -1)
    o = torch.tensor([0.0, 0.0, 2.5])
    sizes: list[int] = []

    def counted(p):
        sizes.append(p.shape[0])
        return net(p)

    with torch.no_grad():
        hits = sphere_trace(counted, o, d, t_max=10.0, lipschitz=None)
    march_sizes = list(sizes[:-1])  # the last call is the evaluation at the hits
    gen = torch.Generator().manual_seed(1)
    replay = [torch.randn(n, 3, generator=gen) for n in march_sizes]

    def ours():
        with torch.no_grad():
            sphere_trace(net, o, d, t_max=10.0, lipschitz=None)

    def evaluations():
        with torch.no_grad():
            for p in replay:
                net(p)

    params = list(net.parameters())
    t = sphere_trace(net, o, d, t_max=10.0, lipschitz=None).t
    loss = torch.where(torch.isfinite(t), t, 0.0).sum()
    at_hits = hits.points[hits.hit].clone()

    def backward():
        torch.autograd.grad(loss, params, retain_graph=True)

    def one_forward():
        net(at_hits)

    extra = {"rays": size * size, "hits": int(hits.hit.sum()),
             "field_evaluations": sum(march_sizes), "calls": len(march_sizes)}
    name = f"sphere_trace 8-layer MLP (w={width}) {size}x{size} rays"
    return [Case(f"{name}, lipschitz=None", ours, evaluations,
                 "the same field evaluations, no march", target=1.5, threads=(1,),
                 extra=extra),
            Case(f"{name}: backward of t", backward, one_forward,
                 "one forward of the field at the hits", target=2.0, threads=(1,))]


def cases(quick: bool = False) -> list[Case]:
    gen = torch.Generator().manual_seed(0)
    verts, tris = _icosphere(4 if quick else 6)
    n = 20_000 if quick else 200_000
    o, d = _random_rays(n, gen)
    peer = _open3d_first_hit(verts, tris, o, d)
    label = f"first hit, icosphere {tris.shape[0]:,} faces, {n:,} rays"
    t0 = time.perf_counter()
    notes = _parity_notes()
    notes["parity_seconds"] = round(time.perf_counter() - t0, 1)
    ray_mesh_intersect(verts, tris, o[:10], d[:10])  # compile the kernel outside the timing
    out = [
        Case(f"ray_mesh_intersect {label}, backend=auto",
             lambda: ray_mesh_intersect(verts, tris, o, d), peer,
             "open3d RaycastingScene (build + cast_rays)", target=3.0, threads=(1,),
             extra=notes),
        Case(f"ray_mesh_intersect {label}, backend=torch",
             lambda: ray_mesh_intersect(verts, tris, o, d, backend="torch"), peer,
             "open3d RaycastingScene (build + cast_rays)", target=20.0, threads=(1,)),
    ]
    return out + _trace_cases(64 if quick else 256, 32 if quick else 64)
