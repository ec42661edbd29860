"""fit_transform in 3D: LM on se(3) against the closed forms, robust losses, gradients."""

import math

import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.transforms import (
    LossOptions,
    SolverOptions,
    find_euclidean,
    find_similarity,
    fit_transform,
    random_rotations,
    robust_loss,
    se3_exp,
    transform_points,
)

F64 = torch.float64


def _problem(b=6, n=40, scale=False, noise=1e-2, seed=0):
    g = torch.Generator().manual_seed(seed)
    src = 2 * torch.randn(b, n, 3, generator=g, dtype=F64)
    m = se3_exp(torch.cat([3 * torch.randn(b, 3, generator=g, dtype=F64),
                           torch.randn(b, 3, generator=g, dtype=F64)], -1))
    if scale:
        s = 0.5 + torch.rand(b, 1, 1, generator=g, dtype=F64)
        m = torch.cat([torch.cat([m[:, :3, :3] * s, m[:, :3, 3:]], -1), m[:, 3:]], -2)
    dst = transform_points(m, src) + noise * torch.randn(b, n, 3, generator=g, dtype=F64)
    return src, dst, m, g


@pytest.mark.parametrize("model, closed", [("euclidean", find_euclidean),
                                           ("similarity", find_similarity)])
@pytest.mark.parametrize("start", ["default", "identity"])
def test_l2_reaches_the_closed_form(model, closed, start):
    src, dst, _, g = _problem(scale=model == "similarity")
    w = 0.2 + torch.rand(src.shape[:-1], generator=g, dtype=F64)
    init = None if start == "default" else torch.eye(4, dtype=F64)
    fit = fit_transform(src, dst, model, init=init, weights=w, solver=SolverOptions(steps=50))
    want = closed(src, dst, w).matrix
    torch.testing.assert_close(fit.matrix, want, rtol=0, atol=1e-10)
    assert fit.params.shape == (6, 6 if model == "euclidean" else 7)
    r2 = (transform_points(want, src) - dst).square().sum(-1)
    torch.testing.assert_close(fit.loss, (w * r2).sum(-1) / w.sum(-1), rtol=1e-10, atol=0)
    assert (fit.history[-1] <= fit.history[0] * (1 + 1e-12)).all()


def test_large_rotations_from_the_identity():
    """Left steps on se(3) have no singularity: 170-degree motions converge from I."""
    g = torch.Generator().manual_seed(3)
    axis = torch.nn.functional.normalize(torch.randn(5, 3, generator=g, dtype=F64), dim=-1)
    m = se3_exp(torch.cat([torch.randn(5, 3, generator=g, dtype=F64),
                           math.radians(170) * axis], -1))
    src = torch.randn(5, 30, 3, generator=g, dtype=F64)
    dst = transform_points(m, src)
    fit = fit_transform(src, dst, "euclidean", init=torch.eye(4, dtype=F64),
                        solver=SolverOptions(steps=100))
    torch.testing.assert_close(fit.matrix, m, rtol=0, atol=1e-10)


def _with_outliers(fraction=0.3, seed=1):
    src, dst, m, g = _problem(b=8, n=100, noise=1e-3, seed=seed)
    k = int(fraction * src.shape[1])
    dst = dst.clone()
    dst[:, :k] += 2 * torch.randn(8, k, 3, generator=g, dtype=F64)
    return src, dst, m


@pytest.mark.parametrize("loss, bound", [("huber", 2e-2), ("cauchy", 2e-3), ("tukey", 2e-3)])
def test_robust_losses_reject_outliers(loss, bound):
    src, dst, m = _with_outliers()
    plain = fit_transform(src, dst, "euclidean")
    # Tukey's weights vanish beyond the scale: it needs a rough alignment (a Cauchy fit)
    init = (fit_transform(src, dst, "euclidean", solver=SolverOptions(steps=100),
                          loss=LossOptions("cauchy", scale=0.05)).matrix
            if loss == "tukey" else None)
    fit = fit_transform(src, dst, "euclidean", init=init, solver=SolverOptions(steps=100),
                        loss=LossOptions(loss, scale=0.05))
    if loss == "tukey":  # outliers beyond the scale get weight 0: the inliers' own fit
        inliers = find_euclidean(src[:, 30:], dst[:, 30:]).matrix
        torch.testing.assert_close(fit.matrix, inliers, rtol=0, atol=1e-6)
    err = (fit.matrix - m).abs().amax((-1, -2))
    err_l2 = (plain.matrix - m).abs().amax((-1, -2))
    assert (err < bound).all(), err
    assert (err < 0.2 * err_l2).all()
    # the result is a stationary point of the robust cost: no se(3) step lowers it
    xi = torch.zeros(8, 6, dtype=F64, requires_grad=True)
    moved = se3_exp(xi) @ fit.matrix.detach()
    cost = robust_loss((transform_points(moved, src) - dst).square().sum(-1), loss, 0.05)
    (grad,) = torch.autograd.grad(cost.mean(-1).sum(), xi)
    assert grad.abs().max() < 1e-7 * (1 + cost.mean(-1).max())


def test_similarity_with_outliers_recovers_the_scale():
    src, dst, _, g = _problem(b=4, n=80, scale=True, noise=1e-3, seed=5)
    truth = find_similarity(src, dst).matrix
    dst = dst.clone()
    dst[:, :20] += 3 * torch.randn(4, 20, 3, generator=g, dtype=F64)
    rough = fit_transform(src, dst, "similarity", solver=SolverOptions(steps=100),
                          loss=LossOptions("cauchy", scale=0.02))
    fit = fit_transform(src, dst, "similarity", init=rough.matrix, solver=SolverOptions(steps=100),
                        loss=LossOptions("tukey", scale=0.02))
    scale = torch.linalg.det(fit.matrix[:, :3, :3]).pow(1 / 3)
    torch.testing.assert_close(scale, torch.linalg.det(truth[:, :3, :3]).pow(1 / 3),
                               rtol=1e-4, atol=0)
    torch.testing.assert_close(fit.params[:, 6], scale.log(), rtol=0, atol=1e-12)


@pytest.mark.parametrize("s", [1e-6, 1e6])
def test_scale_invariance(s):
    src, dst, m = _with_outliers(seed=2)
    fit = fit_transform(src, dst, "similarity", solver=SolverOptions(steps=30),
                        loss=LossOptions("cauchy", scale=0.05))
    big = fit_transform(src * s, dst * s, "similarity", solver=SolverOptions(steps=30),
                        loss=LossOptions("cauchy", scale=0.05 * s))
    want = fit.matrix.clone()
    want[:, :3, 3] *= s
    torch.testing.assert_close(big.matrix, want, rtol=1e-9, atol=1e-9 * s)
    torch.testing.assert_close(big.loss, fit.loss * s * s, rtol=1e-8, atol=0)
    torch.testing.assert_close(big.params, fit.params, rtol=0, atol=1e-9)


def test_gradients_match_the_closed_form_at_the_optimum():
    """LM is unrolled: converged, its derivative is the closed form's (the same optimum)."""
    src, dst, _, _ = _problem(b=2, n=12)
    dst = dst.requires_grad_()
    direction = torch.randn(2, 4, 4, dtype=F64)
    fit = fit_transform(src, dst, "euclidean", init=torch.eye(4, dtype=F64),
                        solver=SolverOptions(steps=50))
    (grad,) = torch.autograd.grad((fit.matrix * direction).sum(), dst)
    (want,) = torch.autograd.grad((find_euclidean(src, dst).matrix * direction).sum(), dst)
    torch.testing.assert_close(grad, want, rtol=1e-7, atol=1e-9)


def test_gradcheck():
    src, dst, _, _ = _problem(b=2, n=8, scale=True, noise=0.1)
    dst = dst.requires_grad_()
    src = src.requires_grad_()

    def f(s, d):
        return fit_transform(s, d, "similarity", solver=SolverOptions(steps=3, tol=0.0),
                             loss=LossOptions("cauchy", scale=0.5)).matrix

    assert torch.autograd.gradcheck(f, (src, dst))


def test_degenerate_and_empty():
    src = torch.zeros(1, 5, 3, dtype=F64)
    src[0, :, 0] = torch.arange(5.0)  # collinear: the roll about the line is undefined
    dst = src + 1.0
    dst.requires_grad_()
    fit = fit_transform(src, dst, "euclidean")
    assert torch.isfinite(fit.matrix).all()
    torch.testing.assert_close(transform_points(fit.matrix, src), dst.detach())
    fit.matrix.sum().backward()
    assert torch.isfinite(dst.grad).all()
    same = torch.ones(1, 4, 3, dtype=F64)  # coincident points
    assert torch.isfinite(fit_transform(same, same + 2, "similarity").matrix).all()
    empty = fit_transform(torch.zeros(0, 5, 3), torch.zeros(0, 5, 3), "euclidean")
    assert empty.matrix.shape == (0, 4, 4) and empty.params.shape == (0, 6)
    half = fit_transform(torch.randn(7, 3, dtype=torch.float16),
                         torch.randn(7, 3, dtype=torch.float16), "similarity")
    assert half.matrix.dtype == torch.float16 and torch.isfinite(half.matrix).all()


def test_random_rotations_batch_against_find_euclidean():
    r = random_rotations(16, generator=torch.Generator().manual_seed(4), dtype=F64)
    src = torch.randn(16, 20, 3, dtype=F64)
    dst = src @ r.mT + torch.randn(16, 1, 3, dtype=F64) + 1e-3 * torch.randn(16, 20, 3,
                                                                               dtype=F64)
    fit = fit_transform(src, dst, "euclidean", init=torch.eye(4, dtype=F64),
                        solver=SolverOptions(steps=100))
    torch.testing.assert_close(fit.matrix, find_euclidean(src, dst).matrix, rtol=0, atol=1e-9)


def test_errors():
    src = torch.randn(6, 3)
    with pytest.raises(ValueError, match="model: 3D points"):
        fit_transform(src, src, "affine")
    with pytest.raises(ValueError, match="optimizer: 3D fits use 'lm'"):
        fit_transform(src, src, "euclidean", solver=SolverOptions("adam"))
    with pytest.raises(ValueError, match="symmetric"):
        fit_transform(src, src, "euclidean", loss=LossOptions(symmetric=True))
    with pytest.raises(ValueError, match="parametrization"):
        fit_transform(src, src, "euclidean", parametrization="sl3")
    with pytest.raises(ShapeError, match=r"init: expected shape \(\*, 4, 4\)"):
        fit_transform(src, src, "euclidean", init=torch.eye(3))
    with pytest.raises(ShapeError, match="src: expected shape"):
        fit_transform(torch.randn(6, 4), torch.randn(6, 4), "euclidean")
