"""chamfer_distance against a formula written here and cKDTree; ragged, reductions, gradients."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from torchgeo_cg.points import ChamferDistance, chamfer_distance


def reference_chamfer(a, b):
    """Per-point squared nearest distances both ways, from the full distance matrix."""
    d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)
    return d2.min(1).values, d2.min(0).values


def test_matches_formula_ragged_and_reductions():
    gen = torch.Generator().manual_seed(0)
    a = torch.randn(3, 30, 3, generator=gen, dtype=torch.float64)
    b = torch.randn(3, 20, 3, generator=gen, dtype=torch.float64)
    al, bl = torch.tensor([30, 11, 5]), torch.tensor([20, 20, 3])
    res = chamfer_distance(a, b, al, bl, reduction="none")
    losses, total = [], 0.0
    for i in range(3):
        ab, ba = reference_chamfer(a[i, : al[i]], b[i, : bl[i]])
        torch.testing.assert_close(res.a_to_b[i, : al[i]], ab)
        torch.testing.assert_close(res.b_to_a[i, : bl[i]], ba)
        assert (res.a_to_b[i, al[i]:] == 0).all() and (res.b_to_a[i, bl[i]:] == 0).all()
        losses.append(ab.mean() + ba.mean())
        total += float(ab.sum() + ba.sum())
    torch.testing.assert_close(res.loss, torch.stack(losses))
    torch.testing.assert_close(chamfer_distance(a, b, al, bl).loss, torch.stack(losses).mean())
    torch.testing.assert_close(float(chamfer_distance(a, b, al, bl, reduction="sum").loss), total)


def test_equals_ckdtree_large_clouds_and_unsquared():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(3000, 3))
    b = rng.normal(size=(2500, 3)) / np.linalg.norm(rng.normal(size=(2500, 3)), axis=1,
                                                     keepdims=True)
    res = chamfer_distance(torch.from_numpy(a), torch.from_numpy(b), squared=False)
    np.testing.assert_allclose(res.a_to_b.numpy(), cKDTree(b).query(a)[0], rtol=1e-12)
    np.testing.assert_allclose(res.b_to_a.numpy(), cKDTree(a).query(b)[0], rtol=1e-12)
    expected = cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean()
    assert abs(float(res.loss) - expected) < 1e-12 * expected


@pytest.mark.grad
@pytest.mark.parametrize("squared", [True, False])
def test_gradcheck(squared):
    gen = torch.Generator().manual_seed(2)
    a = torch.randn(2, 9, 2, generator=gen, dtype=torch.float64, requires_grad=True)
    b = torch.randn(2, 7, 2, generator=gen, dtype=torch.float64, requires_grad=True)
    al, bl = torch.tensor([9, 4]), torch.tensor([7, 7])
    assert torch.autograd.gradcheck(
        lambda x, y: chamfer_distance(x, y, al, bl, squared=squared).loss, (a, b))


def test_zero_distance_has_finite_gradient_and_module_agrees():
    a = torch.tensor([[0.0, 0.0], [1.0, 0.0]], requires_grad=True)
    b = torch.tensor([[0.0, 0.0], [1.0, 1.0]])
    loss = chamfer_distance(a, b, squared=False).loss
    loss.backward()
    assert torch.isfinite(a.grad).all()
    module = ChamferDistance(reduction="sum", squared=False)
    assert torch.equal(module(a, b).loss, chamfer_distance(a, b, reduction="sum",
                                                           squared=False).loss)
    import inspect
    params = inspect.signature(chamfer_distance).parameters
    init = inspect.signature(ChamferDistance).parameters
    assert all(init[n].default == params[n].default for n in ("reduction", "squared"))


def test_empty_and_bad_reduction():
    res = chamfer_distance(torch.zeros(0, 3), torch.ones(4, 3))
    assert res.a_to_b.shape == (0,) and (res.b_to_a == 0).all() and float(res.loss) == 0.0
    with pytest.raises(ValueError, match="reduction"):
        chamfer_distance(torch.zeros(2, 3), torch.ones(4, 3), reduction="max")
    nan = chamfer_distance(torch.tensor([[float("nan"), 0.0]]), torch.ones(4, 2))
    assert torch.isnan(nan.loss)


@pytest.mark.parametrize("dtype, scale", [(torch.float64, 1e-170), (torch.float64, 1e160),
                                          (torch.float32, 1e-25), (torch.float32, 1e19)])
def test_unsquared_distances_at_extreme_scales(dtype, scale):
    # sqrt of the squared distance lost range (0 at 1e-170, inf at 1e160); the norm of
    # the difference does not
    gen = torch.Generator().manual_seed(4)
    a = torch.randn(2, 9, 3, generator=gen, dtype=torch.float64).to(dtype).double()
    b = torch.randn(2, 7, 3, generator=gen, dtype=torch.float64).to(dtype).double()
    res = chamfer_distance((a * scale).to(dtype), (b * scale).to(dtype), squared=False)
    for i in range(2):
        ab, ba = reference_chamfer(a[i], b[i])
        torch.testing.assert_close(res.a_to_b[i].double() / scale, ab.sqrt(), rtol=1e-5, atol=0)
        torch.testing.assert_close(res.b_to_a[i].double() / scale, ba.sqrt(), rtol=1e-5, atol=0)
    assert torch.isfinite(res.loss)


def test_low_precision_is_computed_in_float32():
    gen = torch.Generator().manual_seed(5)
    a, b = torch.randn(2, 9, 3, generator=gen), torch.randn(2, 7, 3, generator=gen)
    for low in (torch.float16, torch.bfloat16):
        res = chamfer_distance(a.to(low), b.to(low), squared=False)
        ref = chamfer_distance(a.to(low).float(), b.to(low).float(), squared=False)
        assert all(x.dtype == low for x in res)
        for x, y in zip(res, ref):
            assert torch.equal(x, y.to(low))
