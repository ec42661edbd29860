"""The Warp backend returns exactly the torch backend's hits (same float64 decisions)."""

from __future__ import annotations

import pytest
import torch

from tests.rays._meshes import MESHES, adversarial_rays
from torchgeo_cg.engine import warp_status
from torchgeo_cg.rays import ray_mesh_intersect

pytestmark = [pytest.mark.usefixtures("one_thread"),
              pytest.mark.skipif(warp_status()[0] != "ok", reason="Warp is not available")]
F64 = torch.float64


@pytest.mark.parametrize("name", list(MESHES))
def test_warp_and_torch_give_identical_hits(name):
    verts, faces = MESHES[name]()
    g = torch.Generator().manual_seed(11)
    o, d, _ = adversarial_rays(verts, faces, g)
    c = verts.mean(0)
    o2 = c + 3 * torch.randn(500, 3, generator=g, dtype=F64)
    d2 = c + 0.3 * torch.randn(500, 3, generator=g, dtype=F64) - o2
    o, d = torch.cat([o, o2, c.expand(50, 3)]), torch.cat([d, d2, d2[:50]])
    a = ray_mesh_intersect(verts, faces, o, d, backend="torch")
    b = ray_mesh_intersect(verts, faces, o, d, backend="warp")
    assert torch.equal(a.face, b.face) and torch.equal(a.t, b.t)
    assert torch.equal(a.points, b.points) and torch.equal(a.normals, b.normals)


def test_warp_batch_and_limits():
    verts, faces = MESHES["icosphere"]()
    g = torch.Generator().manual_seed(12)
    batch = verts * (1 + 0.2 * torch.rand(8, 1, 3, generator=g, dtype=F64))
    o = 3 * torch.randn(8, 40, 3, generator=g, dtype=F64)
    d = 0.3 * torch.randn(8, 40, 3, generator=g, dtype=F64) - o
    for kwargs in ({}, {"t_min": 0.9}, {"t_max": 0.8}):
        a = ray_mesh_intersect(batch, faces, o, d, backend="torch", **kwargs)
        b = ray_mesh_intersect(batch, faces, o, d, backend="warp", **kwargs)
        assert torch.equal(a.face, b.face) and torch.equal(a.t, b.t)
