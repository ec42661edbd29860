"""Tests for torchgeo_cg.transforms.estimation: DLT and closed-form solvers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

import torchgeo_cg.transforms.estimation as est
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.transforms import (
    find_affine,
    find_euclidean,
    find_homography_dlt,
    find_similarity,
    find_translation,
    hartley_normalize,
    report_shapes,
    reprojection_error,
    transform_points,
)

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


def _matrix_of(fn):
    def call(*args, **kwargs):
        return fn(*args, **kwargs).matrix

    call.__name__ = fn.__name__
    return call


CLOSED_FORMS = [_matrix_of(f) for f in (find_translation, find_affine, find_similarity,
                                       find_euclidean)]


def random_homographies(batch, gen, dtype=torch.float64, scale=200.0):
    """Well-conditioned random homographies for points in [0, scale]^2."""
    h = torch.eye(3, dtype=dtype) + 0.1 * torch.randn(batch, 3, 3, generator=gen, dtype=dtype)
    h[:, 2, :2] *= 0.6 / scale  # |perspective| up to ~10% of w over the points
    h[:, :2, 2] *= scale / 2
    return h / h[:, 2:, 2:]


def random_problem(batch, n, gen, noise=0.0, dtype=torch.float64):
    src = torch.rand(batch, n, 2, generator=gen, dtype=dtype) * 200
    h = random_homographies(batch, gen, dtype)
    dst = transform_points(h, src)
    if noise:
        dst = dst + noise * torch.randn(dst.shape, generator=gen, dtype=dtype)
    return src, dst, h


def rel_err(a, b):
    return (a - b).flatten(-2).norm(dim=-1) / b.flatten(-2).norm(dim=-1)


# ------------------------------------------------------------------ DLT, noise free


@pytest.mark.parametrize("n", [4, 5, 8, 30])
def test_dlt_recovers_random_homographies_exactly(n):
    gen = torch.Generator().manual_seed(n)
    src, dst, h = random_problem(512, n, gen)
    fit = find_homography_dlt(src, dst)
    assert fit.rank_ok.all()
    # random 4-point sets can be nearly collinear; the error grows like eps * condition²
    good = fit.condition < 300
    assert good.float().mean() > 0.85
    err = rel_err(fit.matrix, h)
    assert err[good].max() < 1e-10
    assert (err <= 1e-13 * fit.condition**2).all()


def test_dlt_recovers_report_h_exactly():
    shapes = report_shapes(dtype=torch.float64)
    fit = find_homography_dlt(shapes.start, shapes.targets[7])
    assert fit.rank_ok
    hand = torch.tensor([[0.27, 0, -0.85], [-0.25, -0.2, 5.65], [-0.02, -0.09, 1]],
                        dtype=torch.float64)
    assert_close(fit.matrix, hand, rtol=0, atol=1e-12)
    # every Table 3 transform, batched
    fits = find_homography_dlt(shapes.start.expand(8, -1, -1), shapes.targets)
    assert_close(fits.matrix, shapes.matrices, rtol=0, atol=1e-11)


def test_dlt_batch_shapes_dtype_device(device, dtype):
    gen = torch.Generator().manual_seed(0)
    src, dst, h = random_problem(6, 9, gen)
    src, dst = src.reshape(2, 3, 9, 2), dst.reshape(2, 3, 9, 2)
    fit = find_homography_dlt(src.to(device, dtype), dst.to(device, dtype))
    assert fit.matrix.shape == (2, 3, 3, 3) and fit.rank_ok.shape == (2, 3)
    assert fit.condition.shape == (2, 3)
    assert fit.matrix.dtype == dtype and fit.matrix.device.type == device.type
    tol = 1e-9 if dtype == torch.float64 else 1e-4  # float64 inside, rounded to dtype
    assert rel_err(fit.matrix.cpu().double().reshape(6, 3, 3), h).max() < tol


def test_dlt_single_precision_inside_when_asked():
    gen = torch.Generator().manual_seed(1)
    src, dst, h = random_problem(64, 8, gen, dtype=torch.float32)
    fit64 = find_homography_dlt(src, dst)
    fit32 = find_homography_dlt(src, dst, double=False)
    assert rel_err(fit64.matrix, h).max() < 1e-4  # the float32 data themselves are rounded
    assert rel_err(fit32.matrix, h).max() < 1e-2
    assert fit32.matrix.dtype == torch.float32


# ------------------------------------------------------------------ DLT with noise vs peers


def test_dlt_matches_kornia_live():
    kornia_h = pytest.importorskip("kornia.geometry.homography")
    gen = torch.Generator().manual_seed(2)
    src, dst, _ = random_problem(256, 8, gen, noise=0.5)
    ours = find_homography_dlt(src, dst).matrix
    # kornia's svd solver solves the same algebraic problem: same matrix
    k_svd = kornia_h.find_homography_dlt(src, dst, solver="svd")
    assert_close(ours, k_svd, rtol=0, atol=1e-8)
    # its default (lu, h33 = 1) is a different least-squares problem: errors within 1%
    k_lu = kornia_h.find_homography_dlt(src, dst)
    e_ours, e_lu = reprojection_error(ours, src, dst), reprojection_error(k_lu, src, dst)
    assert abs(e_ours.mean() / e_lu.mean() - 1) < 0.01
    assert ((e_ours / e_lu - 1).abs() < 0.01).float().mean() >= 0.99


def test_dlt_weights_match_kornia_live():
    kornia_h = pytest.importorskip("kornia.geometry.homography")
    gen = torch.Generator().manual_seed(3)
    src, dst, _ = random_problem(64, 10, gen, noise=0.5)
    w = torch.rand(64, 10, generator=gen, dtype=torch.float64) + 0.1
    ours = find_homography_dlt(src, dst, weights=w).matrix
    theirs = kornia_h.find_homography_dlt(src, dst, weights=w, solver="svd")
    assert_close(ours, theirs, rtol=0, atol=1e-8)
    # a zero weight removes the point
    w0 = w.clone()
    w0[:, 3] = 0
    keep = [i for i in range(10) if i != 3]
    assert_close(find_homography_dlt(src, dst, weights=w0).matrix,
                 find_homography_dlt(src[:, keep], dst[:, keep], weights=w[:, keep]).matrix)


def test_dlt_matches_opencv_live():
    cv2 = pytest.importorskip("cv2")
    gen = torch.Generator().manual_seed(4)
    src, dst, _ = random_problem(128, 8, gen, noise=0.5)
    ours = reprojection_error(find_homography_dlt(src, dst).matrix, src, dst)
    cv = torch.stack([
        torch.from_numpy(cv2.findHomography(s.numpy(), d.numpy(), 0)[0])
        for s, d in zip(src, dst)
    ])
    theirs = reprojection_error(cv, src, dst)
    # OpenCV refines the DLT with LM: its error is at most ours, and within 1%
    assert abs(ours.mean() / theirs.mean() - 1) < 0.01
    assert (ours >= theirs * (1 - 1e-6)).float().mean() > 0.95


# ------------------------------------------------------------------ degenerate input


def degenerate_batch(dtype=torch.float64):
    gen = torch.Generator().manual_seed(5)
    src, dst, _ = random_problem(5, 6, gen, dtype=dtype)
    src = src.clone()
    src[1, :, 1] = 0.5 * src[1, :, 0] + 3.0  # all collinear
    src[2] = src[2, :1]  # all coincident
    src[3, 3:] = src[3, :3]  # only 3 distinct correspondences
    dst = dst.clone()
    dst[3, 3:] = dst[3, :3]
    dst[1] = dst[1, :, :1] * torch.tensor([1.0, -2.0], dtype=dtype) + 1  # collinear too
    return src, dst


def test_degenerate_problems_are_flagged_without_nan():
    src, dst = degenerate_batch()
    src.requires_grad_(True)
    dst.requires_grad_(True)
    fit = find_homography_dlt(src, dst)
    assert fit.rank_ok.tolist() == [True, False, False, False, True]
    assert torch.isfinite(fit.matrix).all() and torch.isfinite(fit.condition).all()
    assert (fit.condition[[1, 2, 3]] > 1e6).all() and (fit.condition[[0, 4]] < 1e4).all()
    fit.matrix.sum().backward()
    assert torch.isfinite(src.grad).all() and torch.isfinite(dst.grad).all()
    # the good problems of the batch are unaffected
    alone = find_homography_dlt(src[[0, 4]].detach(), dst[[0, 4]].detach()).matrix
    assert_close(fit.matrix[[0, 4]].detach(), alone)


def test_too_few_points_and_zero_weights_are_flagged():
    gen = torch.Generator().manual_seed(6)
    src, dst, _ = random_problem(1, 3, gen)
    fit = find_homography_dlt(src, dst)
    assert not fit.rank_ok.any() and torch.isfinite(fit.matrix).all()
    src, dst, _ = random_problem(2, 6, gen)
    w = torch.ones(2, 6, dtype=torch.float64)
    w[0, 3:] = 0
    assert find_homography_dlt(src, dst, weights=w).rank_ok.tolist() == [False, True]
    w[1] = 0  # all-zero weights count every point, but no point is "effective"
    fit = find_homography_dlt(src, dst, weights=w)
    assert not fit.rank_ok[1] and torch.isfinite(fit.matrix).all()


def test_dlt_gradcheck():
    gen = torch.Generator().manual_seed(7)
    src, dst, _ = random_problem(2, 6, gen, noise=0.3)
    src.requires_grad_(True)
    dst.requires_grad_(True)
    w = (torch.rand(2, 6, generator=gen, dtype=torch.float64) + 0.5).requires_grad_(True)

    def fn(s, d, w_):
        return find_homography_dlt(s, d, weights=w_, iters=20).matrix

    assert torch.autograd.gradcheck(fn, (src, dst, w), eps=1e-6, atol=1e-6, rtol=1e-4)


def test_dlt_gradient_matches_kornia_svd():
    kornia_h = pytest.importorskip("kornia.geometry.homography")
    gen = torch.Generator().manual_seed(8)
    src, dst, _ = random_problem(4, 8, gen, noise=0.5)
    dst1 = dst.clone().requires_grad_(True)
    dst2 = dst.clone().requires_grad_(True)
    find_homography_dlt(src, dst1).matrix.square().sum().backward()
    kornia_h.find_homography_dlt(src, dst2, solver="svd").square().sum().backward()
    assert_close(dst1.grad, dst2.grad, rtol=1e-6, atol=1e-8)


# ------------------------------------------------------------------ hartley


def test_hartley_normalize(dtype):
    gen = torch.Generator().manual_seed(9)
    pts = (torch.rand(3, 7, 2, generator=gen, dtype=torch.float64) * 50 + 10).to(dtype)
    out = hartley_normalize(pts)
    assert_close(out.points.mean(-2), torch.zeros(3, 2), atol=1e-5, rtol=0)
    assert_close(out.points.norm(dim=-1).mean(-1), torch.full((3,), 2**0.5, dtype=torch.float64),
                 scale=10)
    assert_close(transform_points(out.transform, pts), out.points, scale=10)
    # coincident points: scale 1, finite gradient
    same = torch.ones(1, 4, 2, dtype=dtype, requires_grad=True)
    res = hartley_normalize(same)
    assert res.scale.item() == 1.0
    res.points.sum().backward()
    assert torch.isfinite(same.grad).all()


# ------------------------------------------------------------------ closed forms vs peers


def random_affine(batch, gen):
    lin = torch.eye(2, dtype=torch.float64) + 0.3 * torch.randn(batch, 2, 2, generator=gen,
                                                                  dtype=torch.float64)
    t = 10 * torch.randn(batch, 2, generator=gen, dtype=torch.float64)
    return est._affine_from(lin, t)


@pytest.mark.filterwarnings("ignore::FutureWarning")  # skimage 0.26 deprecates estimate()
def test_find_affine_exact_and_vs_lstsq_and_skimage():
    transform = pytest.importorskip("skimage.transform")
    gen = torch.Generator().manual_seed(10)
    src = torch.rand(16, 9, 2, generator=gen, dtype=torch.float64) * 100
    m = random_affine(16, gen)
    exact = transform_points(m, src)
    assert_close(find_affine(src, exact).matrix, m)
    dst = exact + torch.randn(16, 9, 2, generator=gen, dtype=torch.float64)
    ours = find_affine(src, dst).matrix
    design = torch.cat([src, torch.ones(16, 9, 1, dtype=torch.float64)], -1)  # (16, 9, 3)
    for i in range(16):
        # least squares written out: [x, y, 1] @ Mᵀ[:, :2] = dst
        sol = np.linalg.lstsq(design[i].numpy(), dst[i].numpy(), rcond=None)[0]  # (3, 2)
        assert_close(ours[i, :2], sol.T, rtol=1e-9, atol=1e-9)
        # skimage solves the same problem exactly on noise-free data
        peer = transform.AffineTransform()
        peer.estimate(src[i].numpy(), exact[i].numpy())
        assert_close(find_affine(src[i], exact[i]).matrix, peer.params, rtol=1e-8, atol=1e-8)


def umeyama_reference(src: np.ndarray, dst: np.ndarray, with_scale: bool) -> np.ndarray:
    """Umeyama (1991) with an SVD, written out for the test."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    s, d = src - mu_s, dst - mu_d
    cov = d.T @ s / len(src)
    u, sig, vt = np.linalg.svd(cov)
    e = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ e @ vt
    c = (sig * np.diag(e)).sum() / (s**2).sum(1).mean() if with_scale else 1.0
    out = np.eye(3)
    out[:2, :2] = c * r
    out[:2, 2] = mu_d - c * r @ mu_s
    return out


@pytest.mark.filterwarnings("ignore::FutureWarning")
@pytest.mark.parametrize("with_scale", [True, False])
def test_similarity_and_euclidean_vs_umeyama_and_skimage(with_scale):
    transform = pytest.importorskip("skimage.transform")
    gen = torch.Generator().manual_seed(11)
    src = torch.rand(32, 7, 2, generator=gen, dtype=torch.float64) * 100
    dst = torch.rand(32, 7, 2, generator=gen, dtype=torch.float64) * 100  # arbitrary pairs
    ours = (find_similarity if with_scale else find_euclidean)(src, dst).matrix
    cls = transform.SimilarityTransform if with_scale else transform.EuclideanTransform
    for i in range(32):
        ref = umeyama_reference(src[i].numpy(), dst[i].numpy(), with_scale)
        assert_close(ours[i], ref, rtol=1e-9, atol=1e-9)
        peer = cls()
        peer.estimate(src[i].numpy(), dst[i].numpy())
        assert_close(ours[i], peer.params, rtol=1e-9, atol=1e-9)


def test_closed_forms_recover_their_class(device, dtype, tol):
    gen = torch.Generator().manual_seed(12)
    src = (torch.rand(4, 6, 2, generator=gen, dtype=torch.float64) * 10).to(device, dtype)
    angle = torch.tensor([10.0, -100.0, 170.0, 45.0], dtype=torch.float64).deg2rad()
    c, s = angle.cos(), angle.sin()
    rot = torch.stack([c, -s, s, c], -1).unflatten(-1, (2, 2))
    t = torch.tensor([[1.0, 2.0], [-3.0, 0.5], [0.0, 0.0], [7.0, -7.0]], dtype=torch.float64)
    eu = est._affine_from(rot, t).to(device, dtype)
    sim = est._affine_from(rot * 2.5, t).to(device, dtype)
    tr = est._affine_from(torch.eye(2, dtype=torch.float64).expand(4, 2, 2), t).to(device, dtype)
    assert_close(find_euclidean(src, transform_points(eu, src)).matrix, eu, scale=100)
    assert_close(find_similarity(src, transform_points(sim, src)).matrix, sim, scale=100)
    assert_close(find_translation(src, transform_points(tr, src)).matrix, tr, scale=100)
    assert_close(find_affine(src, transform_points(sim, src)).matrix, sim, scale=1000)
    assert find_affine(src, src).matrix.dtype == dtype


def test_translation_weighted_mean():
    src = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    dst = src + torch.tensor([[1.0, 0.0], [3.0, 0.0], [5.0, 3.0]])
    w = torch.tensor([1.0, 1.0, 2.0])
    # hand-derived: (1 + 3 + 2*5) / 4 = 3.5, (0 + 0 + 2*3) / 4 = 1.5
    assert_close(find_translation(src, dst, weights=w).matrix[:2, 2], torch.tensor([3.5, 1.5]))


def test_affine_degenerate_is_minimum_norm_and_finite():
    src = torch.tensor([[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]], dtype=torch.float64,
                       requires_grad=True)
    dst = torch.tensor([[[0.0, 1.0], [2.0, 1.0], [4.0, 1.0], [6.0, 1.0]]], dtype=torch.float64)
    m = find_affine(src, dst).matrix
    assert torch.isfinite(m).all()
    # residual-free on the line, and the minimum-norm linear part: A = [[1, 1], [0, 0]]
    assert_close(transform_points(m, src), dst)
    assert_close(m[0, :2, :2], torch.tensor([[1.0, 1.0], [0.0, 0.0]], dtype=torch.float64))
    m.sum().backward()
    assert torch.isfinite(src.grad).all()
    same = torch.ones(1, 3, 2, dtype=torch.float64, requires_grad=True)
    for fn in CLOSED_FORMS:
        out = fn(same, same + 1)
        assert torch.isfinite(out).all()
        out.sum().backward()
        assert torch.isfinite(same.grad).all()


def test_closed_forms_gradcheck():
    gen = torch.Generator().manual_seed(13)
    src = torch.rand(2, 5, 2, generator=gen, dtype=torch.float64).requires_grad_(True)
    dst = torch.rand(2, 5, 2, generator=gen, dtype=torch.float64).requires_grad_(True)
    w = (torch.rand(2, 5, generator=gen, dtype=torch.float64) + 0.5).requires_grad_(True)
    for fn in CLOSED_FORMS:
        assert torch.autograd.gradcheck(lambda s, d, w_, f=fn: f(s, d, weights=w_),
                                        (src, dst, w))


def test_reprojection_error_brute_force():
    gen = torch.Generator().manual_seed(14)
    src, dst, h = random_problem(3, 5, gen, noise=1.0)
    w = torch.rand(3, 5, generator=gen, dtype=torch.float64)
    got = reprojection_error(h, src, dst, weights=w, symmetric=True)
    for b in range(3):
        fwd = bwd = 0.0
        hinv = torch.linalg.inv(h[b])
        for i in range(5):
            p = h[b] @ torch.cat([src[b, i], torch.ones(1, dtype=torch.float64)])
            fwd += w[b, i] * ((p[:2] / p[2] - dst[b, i]) ** 2).sum()
            q = hinv @ torch.cat([dst[b, i], torch.ones(1, dtype=torch.float64)])
            bwd += w[b, i] * ((q[:2] / q[2] - src[b, i]) ** 2).sum()
        assert_close(got[b], (fwd + bwd) / w[b].sum())


@given(
    st.lists(st.floats(-0.3, 0.3), min_size=6, max_size=6),
    st.floats(-2e-3, 2e-3),
    st.floats(-2e-3, 2e-3),
    st.integers(4, 12),
    st.integers(0, 2**16),
)
def test_property_dlt_recovers_m(lin, g, h, n, seed):
    gen = torch.Generator().manual_seed(seed)
    # a well-spread point set: the 4 corners (jittered) plus random points
    corners = torch.tensor([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]],
                           dtype=torch.float64)
    m = torch.tensor([[1 + lin[0], lin[1], 50 * lin[2]], [lin[3], 1 + lin[4], 50 * lin[5]],
                      [g, h, 1.0]], dtype=torch.float64)
    src = torch.rand(n, 2, generator=gen, dtype=torch.float64) * 100
    src[:4] = corners + 10 * torch.rand(4, 2, generator=gen, dtype=torch.float64)
    fit = find_homography_dlt(src, transform_points(m, src))
    assert fit.rank_ok
    assert rel_err(fit.matrix, m) < 1e-9


# ------------------------------------------------------------------ errors


def test_errors_name_the_argument():
    pts = torch.rand(5, 2)
    with pytest.raises(ShapeError, match="src"):
        find_homography_dlt(torch.rand(5, 3), pts)
    with pytest.raises(ShapeError, match="dst"):
        find_homography_dlt(pts, torch.rand(4, 2))
    with pytest.raises(ShapeError, match="dst"):
        find_affine(torch.rand(2, 5, 2), pts)
    with pytest.raises(TypeError, match="src"):
        find_similarity(torch.ones(5, 2, dtype=torch.long), pts)
    with pytest.raises(TypeError, match="dst"):
        find_euclidean(pts, pts.double())
    with pytest.raises(ShapeError, match="weights"):
        find_translation(pts, pts, weights=torch.ones(4))
    with pytest.raises(TypeError, match="weights"):
        find_homography_dlt(pts, pts, weights=torch.ones(5, dtype=torch.long))
    with pytest.raises(ShapeError, match="points"):
        hartley_normalize(torch.rand(5))
    with pytest.raises(ShapeError, match="matrix"):
        reprojection_error(torch.eye(2), pts, pts)
    with pytest.raises(TypeError, match="src"):
        find_affine([[0.0, 0.0]], pts)


# ------------------------------------------------------------------ exact DLT ----------


def svd_dlt(src, dst):
    """Reference: Hartley-normalized DLT by the SVD of the 2N x 9 system, float64."""
    ns, nd = hartley_normalize(src), hartley_normalize(dst)
    x, y = ns.points[..., 0], ns.points[..., 1]
    u, v = nd.points[..., 0], nd.points[..., 1]
    o, z = torch.ones_like(x), torch.zeros_like(x)
    r1 = torch.stack([x, y, o, z, z, z, -u * x, -u * y, -u], -1)
    r2 = torch.stack([z, z, z, x, y, o, -v * x, -v * y, -v], -1)
    a = torch.cat([r1, r2], -2)
    _, sing, vh = torch.linalg.svd(a, full_matrices=True)
    hn = vh[..., -1, :].unflatten(-1, (3, 3))
    h = torch.linalg.inv(nd.transform) @ hn @ ns.transform
    return h / h[..., 2:, 2:], a, sing


def with_outliers(dst, gen, fraction):
    mask = torch.rand(dst.shape[:-1], generator=gen, dtype=dst.dtype) < fraction
    junk = torch.rand(dst.shape, generator=gen, dtype=dst.dtype) * 200
    return torch.where(mask[..., None], junk, dst)


@pytest.mark.parametrize("case", ["noise50", "outliers50"])
def test_dlt_equals_svd_reference_on_noisy_and_outlier_data(case):
    gen = torch.Generator().manual_seed(12)
    noise = 50.0 if case == "noise50" else 1.0
    src, dst, _ = random_problem(400, 20, gen, noise=noise)
    if case == "outliers50":
        dst = with_outliers(dst, gen, 0.5)
    ref, _, _ = svd_dlt(src, dst)
    fit64 = find_homography_dlt(src, dst)
    assert rel_err(fit64.matrix, ref).max() <= 1e-6
    fit32 = find_homography_dlt(src.float(), dst.float())
    assert rel_err(fit32.matrix.double(), ref).max() <= 1e-3


def test_dlt_algebraic_cost_is_minimal_on_near_degenerate_data():
    # nearly collinear points (1e-4 off a line) and a near-duplicate: the SVD
    # vector is ill-determined, but the algebraic cost must still be the minimum σ_min
    gen = torch.Generator().manual_seed(13)
    src, dst, _ = random_problem(200, 8, gen, noise=0.5)
    t = torch.rand(200, 8, generator=gen, dtype=torch.float64) * 100
    src = torch.stack([t, 2 * t + 1], -1) + 1e-4 * torch.randn(200, 8, 2, generator=gen,
                                                                dtype=torch.float64)
    fit = find_homography_dlt(src, dst)
    _, a, sing = svd_dlt(src, dst)
    ns, nd = hartley_normalize(src), hartley_normalize(dst)
    hn = nd.transform @ fit.matrix @ torch.linalg.inv(ns.transform)
    hn = hn.flatten(-2) / hn.flatten(-2).norm(dim=-1, keepdim=True)
    cost = (a @ hn[..., None]).squeeze(-1).norm(dim=-1)
    assert (cost <= sing[..., -1] * (1 + 1e-6) + 1e-12 * sing[..., 0]).all()
    assert not fit.rank_ok.any()


def test_dlt_flags_duplicated_and_nearly_collinear_points():
    gen = torch.Generator().manual_seed(14)
    src, dst, _ = random_problem(100, 4, gen, noise=0.5)
    src[:, 3] = src[:, 2]  # condition 7.4e4: must not pass as rank_ok
    fit = find_homography_dlt(src, dst)
    assert not fit.rank_ok.any() and torch.isfinite(fit.matrix).all()
    src, dst, _ = random_problem(100, 8, gen, noise=0.5)
    t = torch.rand(100, 8, generator=gen, dtype=torch.float64) * 100
    src = torch.stack([t, 3 * t + 5], -1)
    src[:, 0, 1] += 1e-6
    fit = find_homography_dlt(src, dst)
    assert not fit.rank_ok.any() and (fit.condition > 1e6).all()
    src, dst, h = random_problem(100, 8, gen, noise=0.5)
    assert find_homography_dlt(src, dst).rank_ok.all()  # the control


@pytest.mark.grad
def test_dlt_gradcheck_random_noisy_and_outlier_correspondences():
    gen = torch.Generator().manual_seed(15)
    src, dst, _ = random_problem(3, 12, gen, noise=5.0)
    dst = with_outliers(dst, gen, 0.3)
    src.requires_grad_(True)
    dst.requires_grad_(True)
    w = (torch.rand(3, 12, generator=gen, dtype=torch.float64) + 0.5).requires_grad_(True)

    def fn(s, d, w_):
        return find_homography_dlt(s, d, weights=w_).matrix

    assert torch.autograd.gradcheck(fn, (src, dst, w), eps=1e-6, atol=1e-6, rtol=1e-4)


# ------------------------------------------------------------------ NaN and degenerate input


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_euclidean_on_tiny_spread_returns_the_rotation(dtype):
    gen = torch.Generator().manual_seed(16)
    src = (torch.randn(5, 2, generator=gen, dtype=torch.float64) * 1e-7).to(dtype)
    angle = torch.tensor(math.radians(30.0), dtype=dtype)
    rot = torch.stack([torch.cos(angle), -torch.sin(angle), torch.sin(angle),
                       torch.cos(angle)]).reshape(2, 2)
    dst = src @ rot.T
    m = find_euclidean(src, dst).matrix
    assert_close(m[:2, :2], rot, rtol=1e-5, atol=1e-5)
    # the same answer at every scale
    for s in (1e-6, 1e6):
        assert_close(find_euclidean(src * s, dst * s).matrix[:2, :2], rot, rtol=1e-5, atol=1e-5)
    assert_close(hartley_normalize(src).scale * 1e-7, hartley_normalize(src * 1e7).scale,
                 rtol=1e-5)


@pytest.mark.parametrize("fn", [*CLOSED_FORMS,
                                lambda s, d, weights: find_homography_dlt(s, d, weights).matrix,
                                lambda s, d, weights: reprojection_error(
                                    torch.eye(3, dtype=s.dtype), s, d, weights)])
def test_nan_weight_propagates(fn):
    gen = torch.Generator().manual_seed(17)
    src, dst, _ = random_problem(2, 6, gen)
    w = torch.ones(2, 6, dtype=torch.float64)
    w[0, 2] = float("nan")
    out = fn(src, dst, weights=w)
    assert torch.isnan(out[0]).any()
    assert torch.isfinite(out[1]).all()


@pytest.mark.parametrize("fn", [*CLOSED_FORMS,
                                find_homography_dlt,
                                lambda s, d: reprojection_error(torch.eye(3), s, d)])
def test_zero_points_raise_shape_error_naming_src(fn):
    empty = torch.zeros(3, 0, 2)
    with pytest.raises(ShapeError, match="src.*N >= 1"):
        fn(empty, empty)
    with pytest.raises(ShapeError, match="points.*N >= 1"):
        hartley_normalize(empty)


@pytest.mark.parametrize("fn", [*CLOSED_FORMS,
                                lambda s, d: find_homography_dlt(s, d).matrix])
def test_empty_batch_gives_empty_output(fn):
    empty = torch.zeros(0, 5, 2)
    assert fn(empty, empty).shape == (0, 3, 3)


# ------------------------------------------------------------------ contract regressions -----


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16], ids=["float16", "bfloat16"])
@pytest.mark.parametrize("fn", [*CLOSED_FORMS,
                                lambda s, d: reprojection_error(torch.eye(3, dtype=s.dtype), s, d),
                                lambda s, d: hartley_normalize(s).transform])
def test_low_precision_is_computed_in_float32(fn, low):
    # pixel coordinates ~1000: their squares overflow float16 (was NaN / inf); the float32
    # reference is computed from the same (rounded) inputs
    gen = torch.Generator().manual_seed(18)
    src = (torch.rand(2, 10, 2, generator=gen) * 1000).to(low)
    dst = (src.float() * 1.1 + 5).to(low)
    out = fn(src, dst)
    ref = fn(src.float(), dst.float())
    assert out.dtype == low and torch.isfinite(out).all()
    assert_close(out.float(), ref, rtol=2e-2, atol=2e-2 * float(ref.abs().amax()))


def test_hartley_weights_follow_the_points_dtype():
    gen = torch.Generator().manual_seed(19)
    pts = torch.randn(2, 5, 2, generator=gen)
    w = torch.rand(2, 5, generator=gen, dtype=torch.float64) + 0.5
    out = hartley_normalize(pts, w)
    ref = hartley_normalize(pts, w.float())
    assert all(a.dtype == torch.float32 for a in out)
    assert_close(out.transform, ref.transform)


def test_reprojection_error_mixed_matrix_dtype_names_both():
    src = torch.zeros(4, 2, dtype=torch.float64)
    with pytest.raises(TypeError, match="matrix.*float32.*src.*float64"):
        reprojection_error(torch.eye(3), src, src)
