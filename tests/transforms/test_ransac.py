"""Tests for torchgeo_cg.transforms.ransac: batched LO-RANSAC."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import torchgeo_cg.transforms.ransac as ransac
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.transforms import (
    LossOptions,
    SolverOptions,
    find_transform_ransac,
    fit_transform,
    parameters_to_matrix,
    transform_points,
)

SIZE = (640.0, 480.0)


@pytest.fixture(autouse=True)
def one_thread():
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def corners():
    w, h = SIZE
    return torch.tensor([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]], dtype=torch.float64)


def corner_error(estimate, truth):
    """Mean distance (px) between the image corners mapped by two transforms, (B,)."""
    c = corners().expand(*truth.shape[:-2], 4, 2)
    return (transform_points(estimate.double(), c) - transform_points(truth.double(), c)).norm(
        dim=-1).mean(-1)


def random_transforms(b, model, gen):
    """Random ``model`` transforms moving the image corners by up to ~32 px."""
    c = corners()
    if model == "homography":
        moved = c + 32 * (torch.rand(b, 4, 2, generator=gen, dtype=torch.float64) * 2 - 1)
        a = []  # solve the 8x8 system of the 4 correspondences (reference, not our code)
        for i in range(4):
            (x, y), (u, v) = c[i].tolist(), moved[:, i].T
            a.append(torch.stack([torch.full_like(u, x), torch.full_like(u, y), torch.ones_like(u),
                                  0 * u, 0 * u, 0 * u, -u * x, -u * y], -1))
            a.append(torch.stack([0 * u, 0 * u, 0 * u, torch.full_like(u, x), torch.full_like(u, y),
                                  torch.ones_like(u), -v * x, -v * y], -1))
        rhs = moved.reshape(b, 8)
        sol = torch.linalg.solve(torch.stack(a, 1), rhs)
        return torch.cat([sol, torch.ones(b, 1, dtype=torch.float64)], -1).reshape(b, 3, 3)
    angle = (torch.rand(b, generator=gen, dtype=torch.float64) - 0.5) * 0.1
    shift = (torch.rand(b, 2, generator=gen, dtype=torch.float64) - 0.5) * 40
    params = {"euclidean": torch.cat([angle[:, None], shift], -1),
              "similarity": torch.cat([0.05 * (torch.rand(b, 1, generator=gen,
                                                           dtype=torch.float64) - 0.5),
                                       angle[:, None], shift], -1),
              "affine": torch.cat([0.05 * (torch.rand(b, 2, generator=gen,
                                                      dtype=torch.float64) - 0.5),
                                   shift[:, :1], 0.05 * (torch.rand(b, 2, generator=gen,
                                                                    dtype=torch.float64) - 0.5),
                                   shift[:, 1:]], -1)}[model]
    return parameters_to_matrix(params, model)


def problems(b, n, outliers, noise, gen, model="homography", dtype=torch.float64):
    """src uniform in the image, dst = M src + noise, the first ``outliers * n`` replaced."""
    m = random_transforms(b, model, gen)
    scale = torch.tensor(SIZE, dtype=torch.float64)
    src = torch.rand(b, n, 2, generator=gen, dtype=torch.float64) * scale
    dst = transform_points(m, src) + noise * torch.randn(b, n, 2, generator=gen,
                                                         dtype=torch.float64)
    k = int(round(outliers * n))
    dst[:, :k] = torch.rand(b, k, 2, generator=gen, dtype=torch.float64) * scale
    return src.to(dtype), dst.to(dtype), m, k


def test_public_surface():
    assert set(ransac.__all__) == {"RobustFit", "SAMPLE_SIZES", "SAMPLE_SIZES_3D",
                                   "find_transform_ransac"}
    assert ransac.RobustFit._fields == ("matrix", "inliers", "num_inliers", "rank_ok")


@pytest.mark.slow
def test_homography_at_50_percent_outliers_recovers_99_percent_of_problems():
    gen = torch.Generator().manual_seed(0)
    src, dst, truth, k = problems(300, 200, 0.5, 1.0, gen, dtype=torch.float32)
    fit = find_transform_ransac(src, dst, generator=torch.Generator().manual_seed(1))
    err = corner_error(fit.matrix, truth)
    assert (err < 2.0).float().mean() >= 0.99  # below twice the noise level
    assert fit.rank_ok.float().mean() >= 0.99
    # inliers: the true inliers are found, the planted outliers are not
    assert fit.inliers[:, k:].float().mean() > 0.98
    assert fit.inliers[:, :k].float().mean() < 0.01
    assert (fit.num_inliers == fit.inliers.sum(-1)).all()


@pytest.mark.parametrize("model", ["affine", "similarity", "euclidean"])
def test_other_models_recover_their_transform(model):
    gen = torch.Generator().manual_seed(2)
    src, dst, truth, _ = problems(64, 100, 0.5, 1.0, gen, model=model)
    fit = find_transform_ransac(src, dst, model=model, generator=torch.Generator().manual_seed(3))
    assert (corner_error(fit.matrix, truth) < 2.0).float().mean() >= 0.98
    assert fit.rank_ok.all()
    assert torch.allclose(fit.matrix[:, 2], torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))


def test_matches_opencv_magsac_accuracy_live():
    cv2 = pytest.importorskip("cv2")
    gen = torch.Generator().manual_seed(4)
    src, dst, truth, _ = problems(64, 200, 0.4, 1.0, gen, dtype=torch.float32)
    fit = find_transform_ransac(src, dst, generator=torch.Generator().manual_seed(5))
    cv = np.stack([cv2.findHomography(s, d, cv2.USAC_MAGSAC, 3.0)[0]
                   for s, d in zip(src.numpy(), dst.numpy())])
    ours = corner_error(fit.matrix, truth).median()
    theirs = corner_error(torch.from_numpy(cv), truth).median()
    assert ours <= 1.05 * theirs


def test_reproducible_with_a_generator():
    gen = torch.Generator().manual_seed(6)
    src, dst, _, _ = problems(8, 60, 0.5, 1.0, gen)
    a = find_transform_ransac(src, dst, generator=torch.Generator().manual_seed(7))
    b = find_transform_ransac(src, dst, generator=torch.Generator().manual_seed(7))
    for x, y in zip(a, b):
        assert torch.equal(x, y)


def test_all_outliers_and_too_few_points_are_flagged_never_nan():
    gen = torch.Generator().manual_seed(8)
    scale = torch.tensor(SIZE, dtype=torch.float64)
    src = torch.rand(16, 100, 2, generator=gen, dtype=torch.float64) * scale
    dst = torch.rand(16, 100, 2, generator=gen, dtype=torch.float64) * scale
    for model in ransac.SAMPLE_SIZES:
        fit = find_transform_ransac(src, dst, model=model, generator=gen)
        assert not fit.rank_ok.any(), model
        assert torch.isfinite(fit.matrix).all()
    few = find_transform_ransac(src[:, :3], dst[:, :3], generator=gen)
    assert not few.rank_ok.any() and torch.isfinite(few.matrix).all()
    assert (few.num_inliers == few.inliers.sum(-1)).all()
    # zero weights make points unusable: too few left
    w = torch.zeros(16, 100, dtype=torch.float64)
    w[:, :3] = 1
    fit = find_transform_ransac(src, dst, weights=w, generator=gen)
    assert not fit.rank_ok.any() and torch.isfinite(fit.matrix).all()
    assert not fit.inliers[:, 3:].any()


def test_degenerate_minimal_samples_are_rejected():
    p = torch.tensor([[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.0]],  # 3 collinear
                      [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],  # a square
                      [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [1.0, 1.0]]],  # duplicate
                     dtype=torch.float64)
    q = p.clone()
    q[1, 2] = torch.tensor([0.5, -0.5], dtype=torch.float64)  # flips one triangle: no homography
    h, valid = ransac._homography_4pt(p, p)
    assert valid.tolist() == [False, True, False]
    assert torch.allclose(h[1] / h[1, 2, 2], torch.eye(3, dtype=torch.float64))
    assert ransac._homography_4pt(p, q)[1].tolist() == [False, False, False]


def test_weights_nan_points_batch_shape_and_dtype():
    gen = torch.Generator().manual_seed(9)
    src, dst, truth, k = problems(6, 80, 0.3, 0.5, gen)
    src, dst, truth = src.reshape(2, 3, 80, 2), dst.reshape(2, 3, 80, 2), truth.reshape(2, 3, 3, 3)
    dst[0, 0, 50] = float("nan")  # a NaN point is an outlier, nothing else changes
    fit = find_transform_ransac(src, dst, generator=torch.Generator().manual_seed(1))
    assert fit.matrix.shape == (2, 3, 3, 3) and fit.inliers.shape == (2, 3, 80)
    assert fit.matrix.dtype == torch.float64 and fit.num_inliers.dtype == torch.int64
    assert not fit.inliers[0, 0, 50] and fit.rank_ok.all()
    assert (corner_error(fit.matrix, truth) < 2.0).all()
    w = torch.ones(2, 3, 80, dtype=torch.float64)
    w[1, 2, 5] = float("nan")
    fit = find_transform_ransac(src, dst, weights=w, generator=torch.Generator().manual_seed(1))
    assert torch.isnan(fit.matrix[1, 2]).all() and not fit.rank_ok[1, 2]
    assert torch.isfinite(fit.matrix[0]).all()
    f32 = find_transform_ransac(src.float(), dst.float(), generator=gen)
    assert f32.matrix.dtype == torch.float32


@pytest.mark.slow
def test_robust_losses_from_a_ransac_start_match_the_inlier_only_fit():
    gen = torch.Generator().manual_seed(10)
    src, dst, truth, k = problems(64, 150, 0.3, 1.0, gen)  # 30% gross outliers
    start = find_transform_ransac(src, dst, generator=gen).matrix
    inlier_w = torch.ones(64, 150, dtype=torch.float64)
    inlier_w[:, :k] = 0
    ref = fit_transform(src, dst, weights=inlier_w, solver=SolverOptions(steps=20)).matrix
    l2 = fit_transform(src, dst, init=start, solver=SolverOptions(steps=20)).matrix
    assert corner_error(l2, ref).median() > 5.0  # plain least squares is dragged away
    ref_err = corner_error(ref, truth).median()
    # the usual 95%-efficiency scales for unit noise: Cauchy 2.385, Tukey 4.685
    for loss, scale in (("cauchy", 2.385), ("tukey", 4.685)):
        for optimizer, steps, lr in (("lm", 30, None), ("adam", 300, 1e-3)):
            fit = fit_transform(src, dst, init=start,
                                solver=SolverOptions(steps=steps, optimizer=optimizer, lr=lr),
                                loss=LossOptions(loss, scale=scale)).matrix
            # equal to the inlier-only fit well within the noise (1 px), and as accurate
            assert corner_error(fit, ref).median() < 0.15, (loss, optimizer)
            assert corner_error(fit, truth).median() < 1.05 * ref_err, (loss, optimizer)
    huber = fit_transform(src, dst, init=start, solver=SolverOptions(steps=30),
                          loss=LossOptions("huber", scale=3.0)).matrix
    assert corner_error(huber, truth).median() < corner_error(l2, truth).median()


def test_errors_name_the_argument():
    pts = torch.rand(10, 2)
    with pytest.raises(ValueError, match="model"):
        find_transform_ransac(pts, pts, model="projective")
    with pytest.raises(ValueError, match="threshold"):
        find_transform_ransac(pts, pts, threshold=0.0)
    with pytest.raises(ValueError, match="confidence"):
        find_transform_ransac(pts, pts, confidence=1.0)
    with pytest.raises(ValueError, match="max_iterations"):
        find_transform_ransac(pts, pts, max_iterations=0)
    with pytest.raises(ShapeError, match="dst"):
        find_transform_ransac(pts, torch.rand(9, 2))
    with pytest.raises(ShapeError, match="src"):
        find_transform_ransac(torch.rand(0, 2), torch.rand(0, 2))
    with pytest.raises(TypeError, match="src"):
        find_transform_ransac(pts.long(), pts.long())


def test_empty_batch_gives_empty_results():
    fit = find_transform_ransac(torch.zeros(0, 10, 2), torch.zeros(0, 10, 2))
    assert fit.matrix.shape == (0, 3, 3) and fit.inliers.shape == (0, 10)
    assert fit.num_inliers.shape == (0,) and fit.rank_ok.shape == (0,)


# ------------------------------------------------------------------ contract regressions -----


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16], ids=["float16", "bfloat16"])
def test_low_precision_is_solved_in_float32(low):
    # raised (LU has no float16 kernel; 1e-12 guards overflow float16): now solved in
    # float32 from the same rounded points, the matrix returned in the input dtype
    gen = torch.Generator().manual_seed(22)
    src, dst, m, _ = problems(2, 60, 0.3, 0.5, gen, "affine")
    src, dst = src.to(low), dst.to(low)
    fit = find_transform_ransac(src, dst, "affine", threshold=8.0,
                                generator=torch.Generator().manual_seed(0))
    ref = find_transform_ransac(src.float(), dst.float(), "affine", threshold=8.0,
                                generator=torch.Generator().manual_seed(0))
    assert fit.matrix.dtype == low and torch.equal(fit.inliers, ref.inliers)
    assert torch.equal(fit.matrix, ref.matrix.to(low))
    assert bool(fit.rank_ok.all()) and bool((corner_error(fit.matrix, m) < 8).all())
