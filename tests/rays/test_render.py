"""render_depth dispatch, the guide page's tour and the gallery figure."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import torch

from tests.rays._meshes import icosphere
from torchgeo_cg.rays import ray_mesh_intersect, render_depth, sphere_trace
from torchgeo_cg.sdf import sphere

pytestmark = pytest.mark.usefixtures("one_thread")
F64 = torch.float64
GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide" / "rays.md"


def _bundle(n=9, half=0.3):
    u = torch.linspace(-half, half, n, dtype=F64)
    y, x = torch.meshgrid(-u, u, indexing="ij")
    return torch.stack([x, y, -torch.ones_like(x)], -1)


def test_mesh_and_sdf_dispatch_keep_the_bundle_shape():
    verts, faces = icosphere(3)
    eye = torch.tensor([0.0, 0.0, 3.0], dtype=F64)
    rays = _bundle()
    mesh = render_depth((verts, faces), eye, rays)
    field = render_depth(lambda p: sphere(p, 1.0), eye, rays, t_max=10.0)
    assert mesh.depth.shape == (9, 9) and mesh.normals.shape == (9, 9, 3)
    ref = ray_mesh_intersect(verts, faces, eye.expand(9, 9, 3), rays)
    assert torch.equal(mesh.depth, ref.t) and torch.equal(mesh.mask, ref.hit)
    st = sphere_trace(lambda p: sphere(p, 1.0), eye, rays, t_max=10.0)
    assert torch.equal(field.depth, st.t)
    # the polyhedron lies inside the sphere: it is hit later, and by fewer rays
    assert bool((mesh.mask <= field.mask).all())
    both = mesh.mask & field.mask
    assert bool((mesh.depth[both] >= field.depth[both] - 1e-12).all())
    assert (mesh.depth[both] - field.depth[both]).abs().max() < 0.02


def test_bad_scene_and_missing_t_max():
    eye, rays = torch.zeros(3, dtype=F64), _bundle(2)
    with pytest.raises(TypeError, match="scene"):
        render_depth(3.0, eye, rays)
    with pytest.raises(ValueError, match="t_max"):
        render_depth(lambda p: sphere(p, 1.0), eye, rays)


def test_guide_page_blocks_run_in_order():
    blocks = re.findall(r"```python\n(.*?)```", GUIDE.read_text(encoding="utf-8"), re.S)
    assert len(blocks) >= 3
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(GUIDE), "exec"), namespace)  # noqa: S102
    assert namespace["image"].depth.shape == (32, 32)


def test_gallery_figure_renders(tmp_path):
    pytest.importorskip("matplotlib")
    from torchgeo_cg.viz import rays as figures  # noqa: F401 - registers the figure
    from torchgeo_cg.viz.registry import registered_figures

    (fig,) = [f for f in registered_figures() if f.filename == "rays_depth_normals.png"]
    fig.render(tmp_path / fig.filename)
    assert (tmp_path / fig.filename).stat().st_size > 10_000
