"""find_transform_ransac on 3D points: known transforms among outliers, batched."""

import math

import pytest
import torch

from torchgeo_cg.transforms import (
    find_affine,
    find_euclidean,
    find_similarity,
    find_transform_ransac,
    se3_exp,
    transform_points,
)
from torchgeo_cg.transforms.ransac import SAMPLE_SIZES_3D

F64 = torch.float64
CLOSED = {"euclidean": find_euclidean, "similarity": find_similarity, "affine": find_affine}


def _truth(model: str, b: int, g: torch.Generator) -> torch.Tensor:
    m = se3_exp(torch.cat([5 * torch.randn(b, 3, generator=g, dtype=F64),
                           2 * torch.randn(b, 3, generator=g, dtype=F64)], -1))
    if model == "similarity":
        m[:, :3, :3] *= (0.3 + 2 * torch.rand(b, 1, 1, generator=g, dtype=F64))
    if model == "affine":
        m[:, :3, :3] += 0.3 * torch.randn(b, 3, 3, generator=g, dtype=F64)
    return m


def _problems(model, b=16, n=150, outliers=0.5, noise=1e-3, seed=0):
    g = torch.Generator().manual_seed(seed)
    m = _truth(model, b, g)
    src = torch.randn(b, n, 3, generator=g, dtype=F64)
    dst = transform_points(m, src) + noise * torch.randn(b, n, 3, generator=g, dtype=F64)
    k = int(outliers * n)
    dst[:, :k] = 4 * torch.randn(b, k, 3, generator=g, dtype=F64)
    return src, dst, m, k, g


@pytest.mark.parametrize("model", ["euclidean", "similarity", "affine"])
def test_known_transform_among_half_outliers(model):
    src, dst, m, k, g = _problems(model)
    fit = find_transform_ransac(src, dst, model, threshold=0.01, generator=g)
    assert fit.matrix.shape == (16, 4, 4)
    assert fit.rank_ok.all()
    assert fit.inliers[:, k:].all()  # every true inlier found (noise 1e-3, threshold 1e-2)
    assert (fit.inliers[:, :k].sum(-1) <= 2).all()  # gross outliers fall within by chance
    # the final refit is the closed form on the inliers it reports
    refit = CLOSED[model](src, dst, fit.inliers.to(F64)).matrix
    torch.testing.assert_close(fit.matrix, refit, rtol=0, atol=1e-9)
    torch.testing.assert_close(fit.matrix, m, rtol=0, atol=2e-3)
    torch.testing.assert_close(fit.matrix[:, 3], torch.tensor([0.0, 0, 0, 1], dtype=F64)
                               .expand(16, 4), rtol=0, atol=0)


def test_scale_invariance():
    src, dst, _, _, _ = _problems("similarity", b=4, seed=1)
    fits = [find_transform_ransac(src * s, dst * s, "similarity", threshold=0.01 * s,
                                  generator=torch.Generator().manual_seed(0))
            for s in (1.0, 1e-6, 1e6)]
    for s, fit in zip((1e-6, 1e6), fits[1:]):
        assert torch.equal(fit.inliers, fits[0].inliers)
        want = fits[0].matrix.clone()
        want[:, :3, 3] *= s
        torch.testing.assert_close(fit.matrix, want, rtol=1e-8, atol=1e-8 * s)


def test_weights_nan_and_degenerate():
    src, dst, _, k, g = _problems("euclidean", b=2, n=60, seed=2)
    w = torch.ones(2, 60, dtype=F64)
    w[:, -5:] = 0.0
    src = src.clone()
    src[:, k] = math.nan  # a non-finite point is an outlier, not a NaN result
    fit = find_transform_ransac(src, dst, "euclidean", threshold=0.01, weights=w, generator=g)
    assert torch.isfinite(fit.matrix).all() and fit.rank_ok.all()
    assert not fit.inliers[:, -5:].any() and not fit.inliers[:, k].any()
    assert fit.inliers[:, k + 1:-5].all()
    # collinear points: no rigid motion is determined, rank_ok False and a finite matrix
    line = torch.zeros(1, 30, 3, dtype=F64)
    line[0, :, 0] = torch.linspace(0, 1, 30, dtype=F64)
    fit = find_transform_ransac(line, line + 1.0, "euclidean", threshold=0.01, generator=g)
    assert not fit.rank_ok.any() and torch.isfinite(fit.matrix).all()
    # too few points
    few = find_transform_ransac(src[:, :2], dst[:, :2], "similarity", threshold=0.1)
    assert not few.rank_ok.any() and few.matrix.shape == (2, 4, 4)


def test_low_precision_and_errors():
    src, dst, m, _, g = _problems("euclidean", b=2, n=80, outliers=0.3, seed=3)
    fit = find_transform_ransac(src.float(), dst.float(), "euclidean", threshold=0.01,
                                generator=g)
    assert fit.matrix.dtype == torch.float32
    torch.testing.assert_close(fit.matrix.double(), m, rtol=0, atol=5e-3)
    with pytest.raises(ValueError, match="model"):
        find_transform_ransac(src, dst, "homography")
    assert SAMPLE_SIZES_3D == {"affine": 4, "similarity": 3, "euclidean": 3}
