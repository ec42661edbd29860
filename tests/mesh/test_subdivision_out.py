"""``out=`` of apply_operator, apply_stencils and the subdivision modules' forward.

The reference is the dense product ``S @ V`` written in the test (and the fresh result,
which must be bitwise the same: the same kernels run).
"""

from __future__ import annotations

import pytest
import torch

from torchgeo_cg.core import ShapeError
from torchgeo_cg.mesh.subdivision import (
    CatmullClark,
    FaceVaryingSubdivision,
    LoopSubdivision,
    apply_operator,
    apply_stencils,
    catmull_clark_operator,
    limit_stencils,
)

CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
OCTA_F = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5],
          [0, 3, 5]]


def _data(*shape, dtype=torch.float64):
    return torch.randn(*shape, generator=torch.Generator().manual_seed(0), dtype=dtype)


def _dense_reference(op, verts):
    return torch.einsum("rc,...cd->...rd", op.stencils.dense().to(verts.dtype), verts)


@pytest.mark.parametrize("batch", [(), (1,), (3,), (2, 9)])  # 18 items: several chunks
def test_apply_operator_out_equals_fresh_and_dense(batch):
    op = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64)
    verts = _data(*batch, 8, 3)
    out = torch.full((*batch, op.num_vertices_out, 3), float("nan"), dtype=torch.float64)
    got = apply_operator(op, verts, out=out)
    assert got is out
    assert torch.equal(out, apply_operator(op, verts))
    torch.testing.assert_close(out, _dense_reference(op, verts), rtol=1e-13, atol=0)


def test_out_non_contiguous_and_half_precision():
    op = catmull_clark_operator(CUBE_F, 8)
    verts = _data(4, 8, 5, dtype=torch.float32)
    out = torch.full((op.num_vertices_out, 4, 5), float("nan")).transpose(0, 1)  # strided
    apply_operator(op, verts, out=out)
    assert torch.equal(out, apply_operator(op, verts))
    half = verts.half()
    out_h = torch.empty(4, op.num_vertices_out, 5, dtype=torch.float16)
    apply_operator(op, half, out=out_h)
    assert torch.equal(out_h, apply_operator(op, half))


def test_modules_forward_out():
    cc = CatmullClark(CUBE_F, 8, levels=2, dtype=torch.float64)
    verts = _data(3, 8, 3)
    out = torch.full((3, cc.num_vertices_out, 3), float("nan"), dtype=torch.float64)
    assert cc(verts, out=out) is out
    ref = _dense_reference(cc.operator(1), _dense_reference(cc.operator(0), verts))
    torch.testing.assert_close(out, ref, rtol=1e-13, atol=1e-15)
    assert torch.equal(out, cc(verts))
    loop = LoopSubdivision(OCTA_F, 6, levels=1, dtype=torch.float64)
    verts6 = _data(6, 3)
    out6 = torch.empty(loop.num_vertices_out, 3, dtype=torch.float64)
    loop(verts6, out=out6)
    torch.testing.assert_close(out6, _dense_reference(loop.operator(0), verts6), rtol=1e-13,
                               atol=0)
    identity = CatmullClark(CUBE_F, 8, levels=0, dtype=torch.float64)
    out0 = torch.empty(3, 8, 3, dtype=torch.float64)
    assert identity(verts, out=out0) is out0 and torch.equal(out0, verts)


def test_face_varying_forward_out():
    """Two levels into a buffer against the dense products of its own stencils; levels 0
    copies; a buffer of the wrong size names ``out``."""
    fv = FaceVaryingSubdivision(CUBE_F, CUBE_F, 8, 8, levels=2, dtype=torch.float64)
    uvs = _data(3, 8, 2)
    out = torch.full((3, fv.num_uvs_out, 2), float("nan"), dtype=torch.float64)
    assert fv(uvs, out=out) is out
    ref = uvs
    for level in range(2):
        dense = torch.sparse_csr_tensor(getattr(fv, f"crow_{level}"), getattr(fv, f"col_{level}"),
                                        getattr(fv, f"weights_{level}")).to_dense()
        ref = torch.einsum("rc,...cd->...rd", dense, ref)
    torch.testing.assert_close(out, ref, rtol=1e-13, atol=1e-15)
    assert torch.equal(out, fv(uvs))
    identity = FaceVaryingSubdivision(CUBE_F, CUBE_F, 8, 8, levels=0, dtype=torch.float64)
    out0 = torch.empty(3, 8, 2, dtype=torch.float64)
    assert identity(uvs, out=out0) is out0 and torch.equal(out0, uvs)
    with pytest.raises(ShapeError, match="out: expected shape"):
        fv(uvs, out=torch.empty(3, fv.num_uvs_out + 1, 2, dtype=torch.float64))


def test_apply_stencils_out_on_limit_stencils():
    op = catmull_clark_operator(CUBE_F, 8, dtype=torch.float64)
    g = torch.Generator().manual_seed(1)
    st = limit_stencils(op, torch.randint(0, 6, (50,), generator=g),
                        torch.rand(50, 2, generator=g, dtype=torch.float64))
    verts = _data(2, 8, 3)
    out = torch.empty(2, 50, 3, dtype=torch.float64)
    apply_stencils(st.positions, verts, out=out)
    torch.testing.assert_close(out, st.positions.dense() @ verts, rtol=1e-13, atol=1e-15)


def test_out_bad_buffers_raise_naming_out():
    op = catmull_clark_operator(CUBE_F, 8)
    verts = _data(2, 8, 3, dtype=torch.float32)
    with pytest.raises(ShapeError, match="out: expected shape"):
        apply_operator(op, verts, out=torch.empty(2, op.num_vertices_out + 1, 3))
    with pytest.raises(ShapeError, match="out: expected shape"):
        apply_operator(op, verts, out=torch.empty(op.num_vertices_out, 3))  # batch missing
    with pytest.raises(TypeError, match="out: expected dtype"):
        apply_operator(op, verts, out=torch.empty(2, op.num_vertices_out, 3,
                                                  dtype=torch.float64))
    with pytest.raises(ValueError, match="out: expected device"):
        apply_operator(op, verts, out=torch.empty(2, op.num_vertices_out, 3, device="meta"))
    with pytest.raises(TypeError, match="out"):
        apply_operator(op, verts, out=[[0.0]])
    with pytest.raises(ShapeError, match="out: expected shape"):
        CatmullClark(CUBE_F, 8, levels=2)(verts, out=torch.empty(2, 26, 3))  # level 1 size


def test_out_is_outside_autograd():
    """Like torch's ``out=``: an error where grad mode is on and an input or out requires
    grad; allowed (and correct) under ``torch.no_grad()``; rejected under ``vmap``."""
    op = catmull_clark_operator(CUBE_F, 8)
    verts = _data(2, 8, 3, dtype=torch.float32).requires_grad_(True)
    out = torch.empty(2, op.num_vertices_out, 3)
    with pytest.raises(ValueError, match="out: .*autograd"):
        apply_operator(op, verts, out=out)
    with pytest.raises(ValueError, match="out: .*autograd"):
        apply_operator(op, verts.detach(), out=out.clone().requires_grad_(True))
    with torch.no_grad():
        apply_operator(op, verts, out=out)
    assert torch.equal(out, apply_operator(op, verts).detach())
    with pytest.raises(ValueError, match="out: not supported under"):
        torch.func.vmap(lambda v: apply_operator(op, v, out=torch.empty(26, 3)))(
            verts.detach())
