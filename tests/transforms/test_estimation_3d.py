"""Tests for the 3D closed forms (Kabsch, Umeyama, affine, translation) and scale-free weights."""

from __future__ import annotations

import math

import pytest
import torch

from torchgeo_cg.transforms import (
    SolverOptions,
    compose,
    find_affine,
    find_euclidean,
    find_homography_dlt,
    find_similarity,
    find_translation,
    fit_transform,
    hartley_normalize,
    inverse,
    parameters_to_matrix,
    transform_points,
    translation,
)
from torchgeo_cg.transforms.rotations import random_rotations

F64 = torch.float64
CUBE = torch.tensor([[x, y, z] for x in (0.0, 1) for y in (0.0, 1) for z in (0.0, 1)],
                    dtype=F64) - 0.5
TETRAHEDRON = torch.tensor([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1.0]], dtype=F64)
SQUARE = torch.tensor([[1, 1, 0], [1, -1, 0], [-1, 1, 0], [-1, -1, 0.0]], dtype=F64)


def svd_reference(p, q, w, with_scale, allow_reflection=False):
    """Umeyama (1991) with an SVD, written out for the test: (B, N, 3) -> (B, 4, 4)."""
    w = w / w.sum(-1, keepdim=True)
    mp, mq = (p * w[..., None]).sum(-2), (q * w[..., None]).sum(-2)
    pc, qc = p - mp[..., None, :], q - mq[..., None, :]
    u, s, vh = torch.linalg.svd((qc * w[..., None]).mT @ pc)
    d = torch.ones_like(s)
    if not allow_reflection:
        d[..., 2] = torch.det(u @ vh)
    rot = u @ torch.diag_embed(d) @ vh
    scale = ((s * d).sum(-1) / (pc.square().sum(-1) * w).sum(-1) if with_scale
             else torch.ones_like(s[..., 0]))
    out = torch.eye(4, dtype=p.dtype).repeat(p.shape[0], 1, 1)
    out[:, :3, :3] = scale[:, None, None] * rot
    out[:, :3, 3] = mq - (out[:, :3, :3] @ mp[..., None])[..., 0]
    return out


def noisy_problem(b=32, n=20, seed=0, mirror=False):
    gen = torch.Generator().manual_seed(seed)
    p = torch.randn(b, n, 3, generator=gen, dtype=F64)
    rot = random_rotations(b, generator=gen, dtype=F64)
    q = 1.7 * p @ rot.mT + torch.randn(b, 1, 3, generator=gen, dtype=F64)
    q = q + 0.05 * torch.randn(b, n, 3, generator=gen, dtype=F64)
    if mirror:
        q = q * torch.tensor([1.0, 1.0, -1.0], dtype=F64)
    return p, q, torch.rand(b, n, generator=gen, dtype=F64)


@pytest.mark.parametrize("with_scale", [False, True])
@pytest.mark.parametrize("mirror", [False, True])
def test_procrustes_matches_svd_reference(with_scale, mirror):
    p, q, w = noisy_problem(mirror=mirror)
    fn = find_similarity if with_scale else find_euclidean
    for allow in (False, True):
        fit = fn(p, q, w, allow_reflection=allow)
        ref = svd_reference(p, q, w, with_scale, allow)
        assert (fit.matrix - ref).abs().max() < 1e-13
        assert fit.rank_ok.all() and torch.isfinite(fit.condition).all()
        det = torch.det(fit.matrix[:, :3, :3])
        assert ((det < 0) == (allow and mirror)).all()


def test_zero_weights_ignore_padding():
    p, q, w = noisy_problem(b=4, n=12)
    padded_p = torch.cat([p, 1e3 * torch.ones(4, 5, 3, dtype=F64)], 1)
    padded_q = torch.cat([q, -7 * torch.ones(4, 5, 3, dtype=F64)], 1)
    padded_w = torch.cat([w, torch.zeros(4, 5, dtype=F64)], 1)
    for fn in (find_euclidean, find_similarity, find_affine, find_translation):
        assert (fn(padded_p, padded_q, padded_w).matrix - fn(p, q, w).matrix).abs().max() < 1e-11


def test_affine_and_translation_3d_exact():
    gen = torch.Generator().manual_seed(1)
    p = torch.randn(8, 10, 3, generator=gen, dtype=F64)
    a = torch.eye(4, dtype=F64).repeat(8, 1, 1)
    a[:, :3] = torch.randn(8, 3, 4, generator=gen, dtype=F64)
    fit = find_affine(p, transform_points(a, p))
    assert (fit.matrix - a).abs().max() < 1e-13 and fit.rank_ok.all()
    t = torch.randn(8, 3, generator=gen, dtype=F64)
    assert (find_translation(p, p + t[:, None]).matrix - translation(t)).abs().max() < 1e-15 * 8


def test_degenerate_sets_are_flagged_never_nan():
    line = torch.linspace(0, 1, 5, dtype=F64)[:, None] * torch.tensor([1.0, 2.0, 3.0], dtype=F64)
    plane = SQUARE * torch.tensor([1.0, 2.0, 0.0], dtype=F64) + 0.25
    point = torch.ones(4, 3, dtype=F64)
    rot = random_rotations(1, generator=torch.Generator().manual_seed(2), dtype=F64)[0]
    cases = [
        (find_euclidean, line, {}, False), (find_similarity, line, {}, False),
        (find_euclidean, plane, {}, True), (find_euclidean, plane, {"allow_reflection": True},
                                            False),
        (find_affine, plane, {}, False), (find_similarity, point, {}, False),
        (find_euclidean, point, {}, False), (find_affine, point, {}, False),
        (find_euclidean, line[:2], {}, False),
    ]
    for fn, pts, kw, ok in cases:
        fit = fn(pts, pts @ rot.mT + 1, **kw)
        assert bool(fit.rank_ok) == ok, (fn.__name__, kw)
        assert torch.isfinite(fit.matrix).all() and torch.isfinite(fit.condition).all()
    g = line.clone().requires_grad_(True)
    find_similarity(g, g @ rot.mT).matrix.sum().backward()
    assert torch.isfinite(g.grad).all()


@pytest.mark.grad
@pytest.mark.parametrize("name,points", [("tetrahedron", TETRAHEDRON), ("square", SQUARE),
                                         ("cube", CUBE)])
def test_gradients_on_symmetric_sets_are_finite_and_correct(name, points):
    rot = random_rotations(1, generator=torch.Generator().manual_seed(3), dtype=F64)[0]
    dst = points @ rot.mT + 1.0  # exact: repeated singular values of the correlation
    for fn in (find_euclidean, find_similarity):
        src_g, dst_g = points.clone().requires_grad_(True), dst.clone().requires_grad_(True)
        assert torch.autograd.gradcheck(lambda a, b, f=fn: f(a, b).matrix, (src_g, dst_g))
        w = torch.rand(points.shape[0], generator=torch.Generator().manual_seed(4),
                       dtype=F64) + 0.5
        assert torch.autograd.gradcheck(lambda a, b, f=fn: f(points, dst, b).matrix[..., :3, :]
                                        .sum(-1) + a.sum() * 0, (src_g, w.requires_grad_(True)))


@pytest.mark.parametrize("scale", [1e-6, 1e6])
def test_scale_equivariance_3d(scale):
    p, q, w = noisy_problem(b=8)
    s = torch.diag(torch.tensor([scale, scale, scale, 1.0], dtype=F64))
    for fn in (find_euclidean, find_similarity, find_affine):
        fit, fit_s = fn(p, q, w), fn(p * scale, q * scale, w)
        expect = s @ fit.matrix @ inverse(s)
        assert (fit_s.matrix - expect).abs().max() <= 1e-12 * expect.abs().max()
        assert (fit_s.rank_ok == fit.rank_ok).all()


@pytest.mark.parametrize("dims", [2, 3])
@pytest.mark.parametrize("factor", [1e-300, 1e-200, 1e200, 1e300])
def test_weights_are_scale_free(dims, factor):
    gen = torch.Generator().manual_seed(5)
    p = torch.randn(6, 9, dims, generator=gen, dtype=F64)
    q = p * 1.3 + 0.1 * torch.randn(6, 9, dims, generator=gen, dtype=F64)
    w = torch.rand(6, 9, generator=gen, dtype=F64) + 0.1
    fns = [find_affine, find_euclidean, find_similarity, find_translation]
    if dims == 2:
        fns.append(find_homography_dlt)
    for fn in fns:
        ref, got = fn(p, q, w), fn(p, q, w * factor)
        assert torch.isfinite(got.matrix).all(), fn.__name__
        assert (got.matrix - ref.matrix).abs().max() < 1e-12, fn.__name__
    if dims == 2:
        ref, got = hartley_normalize(p, w), hartley_normalize(p, w * factor)
        assert (got.transform - ref.transform).abs().max() < 1e-13


def test_corners_parametrization_propagates_nan():
    params = torch.zeros(3, 8, dtype=F64)
    params[1, 4] = float("nan")  # the third corner's x, which the affine fallback ignored
    out = parameters_to_matrix(params, "homography", "corners")
    assert torch.isnan(out[1]).all() and torch.isfinite(out[[0, 2]]).all()


@pytest.mark.parametrize("tol", [-1.0, float("nan"), float("inf")])
def test_fit_transform_rejects_bad_tol(tol):
    src = torch.rand(5, 2, dtype=F64)
    with pytest.raises(ValueError, match="tol"):
        fit_transform(src, src, "affine", solver=SolverOptions(tol=tol))


def test_homogeneous_3d_ops():
    gen = torch.Generator().manual_seed(6)
    m = torch.randn(5, 4, 4, generator=gen, dtype=F64)
    p = torch.randn(5, 7, 3, generator=gen, dtype=F64)
    hom = torch.cat([p, torch.ones(5, 7, 1, dtype=F64)], -1) @ m.mT
    assert (transform_points(m, p) - hom[..., :3] / hom[..., 3:]).abs().max() < 1e-12
    assert (compose(m, inverse(m)) - torch.eye(4, dtype=F64)).abs().max() < 1e-12
    t = translation(torch.tensor([1.0, 2.0, 3.0], dtype=F64))
    assert t.shape == (4, 4) and (transform_points(t, p) - (p + t[:3, 3])).abs().max() < 1e-15
    with pytest.raises(Exception, match="matrices\\[1\\]"):
        compose(torch.eye(3), torch.eye(4))
    with pytest.raises(Exception, match="points"):
        transform_points(torch.eye(4), torch.zeros(3, 2))
    assert math.isfinite(float(inverse(torch.zeros(4, 4, dtype=F64)).abs().max()))
