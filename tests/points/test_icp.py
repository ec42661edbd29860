"""icp: exact recovery, ragged batches, gradients, robust losses, and Open3D's
registration_icp side by side on scans of the shipped rabbit."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from torchgeo_cg.core import ShapeError
from torchgeo_cg.mesh.data import rabbit_scan_pairs
from torchgeo_cg.points import ICPConvergence, ICPRobust, estimate_normals, icp
from torchgeo_cg.transforms import find_euclidean, find_similarity


def _rotation(angle, axis):
    axis = torch.nn.functional.normalize(torch.tensor(axis, dtype=torch.float64), dim=0)
    x, y, z = axis.tolist()
    k = torch.tensor([[0, -z, y], [z, 0, -x], [-y, x, 0]], dtype=torch.float64)
    return torch.eye(3, dtype=torch.float64) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def _rigid(angle, axis, shift):
    m = torch.eye(4, dtype=torch.float64)
    m[:3, :3] = _rotation(angle, axis)
    m[:3, 3] = torch.tensor(shift, dtype=torch.float64)
    return m


def _apply(m, p):
    return p @ m[..., :3, :3].transpose(-1, -2) + m[..., None, :3, 3]


def _angle_deg(a, b):
    d = a[..., :3, :3] @ b[..., :3, :3].transpose(-1, -2)
    c = ((d.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1, 1)
    return torch.rad2deg(torch.acos(c))


def _cloud(n, seed):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n, 3, generator=g, dtype=torch.float64) * torch.tensor([1.0, 0.7, 0.5])


@pytest.mark.parametrize("method", ["point_to_point", "point_to_plane"])
def test_recovers_a_known_rigid_motion_exactly(method):
    target = _cloud(400, 0)
    truth = _rigid(0.12, [1.0, 2.0, 0.5], [0.03, -0.02, 0.01])
    source = _apply(torch.linalg.inv(truth), target)
    res = icp(source, target, method=method, convergence=ICPConvergence(60))
    assert bool(res.converged) and int(res.iterations) < 60
    torch.testing.assert_close(res.transform, truth, atol=1e-9, rtol=0)
    assert float(res.rmse) < 1e-9 and float(res.inlier_fraction) == 1.0


def test_similarity_recovers_the_scale():
    target = _cloud(400, 1)
    truth = _rigid(0.08, [0.0, 1.0, 1.0], [0.02, 0.0, -0.03])
    truth[:3, :3] *= 1.1
    source = _apply(torch.linalg.inv(truth), target)
    for method in ("point_to_point", "point_to_plane"):
        res = icp(source, target, model="similarity", method=method,
                  convergence=ICPConvergence(80, tol=1e-12))
        torch.testing.assert_close(res.transform, truth, atol=1e-8, rtol=0)


def test_ragged_batch_equals_each_pair():
    clouds = [_cloud(300, s) for s in range(3)]
    truths = [_rigid(0.05 * (i + 1), [1.0, -1.0, 2.0 * i], [0.01 * i, 0.02, 0.0])
              for i in range(3)]
    sl, tl = torch.tensor([300, 180, 250]), torch.tensor([300, 300, 220])
    target = torch.stack(clouds)
    source = torch.stack([_apply(torch.linalg.inv(m), c) for m, c in zip(truths, clouds)])
    res = icp(source, target, source_lengths=sl, target_lengths=tl, method="point_to_plane")
    for i in range(3):
        one = icp(source[i, : sl[i]], target[i, : tl[i]], method="point_to_plane")
        torch.testing.assert_close(res.transform[i], one.transform, atol=1e-12, rtol=0)
        torch.testing.assert_close(res.rmse[i], one.rmse, atol=1e-12, rtol=0)
        assert int(res.iterations[i]) == int(one.iterations)


def test_init_and_max_distance():
    target = _cloud(300, 4)
    truth = _rigid(0.9, [0.0, 0.0, 1.0], [0.3, 0.0, 0.0])  # far: needs the initial guess
    source = _apply(torch.linalg.inv(truth), target)
    near = _rigid(0.85, [0.0, 0.0, 1.0], [0.28, 0.0, 0.0])
    res = icp(source, target, init=near, max_distance=0.2,
              convergence=ICPConvergence(60))
    torch.testing.assert_close(res.transform, truth, atol=1e-9, rtol=0)
    tight = icp(source, target, max_distance=1e-3, convergence=ICPConvergence(5))
    assert float(tight.inlier_fraction) < 0.1


def test_point_to_point_step_is_the_closed_form_on_the_last_matches():
    """The final transform is find_euclidean / find_similarity of the last matches."""
    target = _cloud(400, 6)
    truth = _rigid(0.2, [1.0, 2.0, 0.5], [0.05, -0.02, 0.03])
    source = _apply(torch.linalg.inv(truth), target)[:300]
    source = source + 1e-3 * torch.randn(300, 3, generator=torch.Generator().manual_seed(0),
                                         dtype=torch.float64)
    for model, closed in (("euclidean", find_euclidean), ("similarity", find_similarity)):
        res = icp(source, target, model=model, convergence=ICPConvergence(60))
        moved = _apply(res.transform, source)
        nearest = target[torch.cdist(moved, target).argmin(-1)]  # brute-force matches
        torch.testing.assert_close(res.transform, closed(source, nearest).matrix,
                                   atol=1e-9, rtol=0)


def test_no_match_keeps_the_initial_transform():
    """Every match rejected by max_distance: the pair keeps init, not the identity."""
    target = _cloud(50, 7)
    init = _rigid(0.3, [0.0, 1.0, 0.0], [5.0, 0.0, 0.0])
    res = icp(target + 100.0, target, init=init, max_distance=1e-3,
              convergence=ICPConvergence(3))
    torch.testing.assert_close(res.transform, init, atol=0, rtol=0)
    assert float(res.inlier_fraction) == 0.0


@pytest.mark.grad
@pytest.mark.parametrize("method", ["point_to_point", "point_to_plane"])
def test_gradcheck_given_the_last_correspondences(method):
    target = _cloud(40, 5)
    truth = _rigid(0.05, [1.0, 0.0, 1.0], [0.01, 0.0, 0.0])
    source = _apply(torch.linalg.inv(truth), target)
    if method == "point_to_point":  # residuals: the gradient of the closed form
        source = source + 1e-3 * torch.randn(source.shape, dtype=torch.float64,
                                             generator=torch.Generator().manual_seed(0))
    normals = estimate_normals(target, 8)  # constants
    # Started at the noise-free solution, each perturbed run converges in one or two
    # iterations; the derivative of the converged transform given the last matches does not
    # depend on init, so this checks the same thing as a start from the identity, 4x cheaper.

    def f(src, tgt):
        out = icp(src, tgt, method=method, init=truth, target_normals=normals,
                  convergence=ICPConvergence(100, tol=1e-12))
        if method == "point_to_plane":  # zero residuals: the RMSE has a kink there
            return out.transform[:3]
        return out.transform[:3], out.rmse

    assert torch.autograd.gradcheck(f, (source.requires_grad_(), target.requires_grad_()),
                                    atol=1e-6)


def test_nan_empty_and_bad_arguments():
    target = _cloud(50, 6)
    bad = target.clone()
    bad[3, 1] = math.nan
    batch = torch.stack([target, bad])
    res = icp(batch, torch.stack([target, target]))
    assert res.transform[1].isnan().all() and res.rmse[1].isnan()
    assert not res.transform[0].isnan().any() and float(res.rmse[0]) < 1e-12
    empty = icp(torch.zeros(0, 3), target.float())
    assert torch.equal(empty.transform, torch.eye(4)) and float(empty.inlier_fraction) == 0
    with pytest.raises(ShapeError, match="source"):
        icp(torch.zeros(5, 2), target)
    with pytest.raises(TypeError, match="target"):
        icp(target.float(), target)
    with pytest.raises(ShapeError, match="init"):
        icp(target, target, init=torch.eye(3, dtype=torch.float64))
    with pytest.raises(ShapeError, match="target_normals"):
        icp(target, target, target_normals=torch.zeros(4, 3, dtype=torch.float64))
    for kwargs, name in (({"method": "plane"}, "method"), ({"model": "affine"}, "model"),
                         ({"max_distance": 0.0}, "max_distance"),
                         ({"backend": "fast"}, "backend")):
        with pytest.raises(ValueError, match=name):
            icp(target, target, **kwargs)
    for make, name in ((lambda: ICPRobust("l1"), "loss"), (lambda: ICPRobust(scale=-1.0), "scale"),
                       (lambda: ICPConvergence(tol=0), "tol"),
                       (lambda: ICPConvergence(max_iterations=-1), "max_iterations")):
        with pytest.raises(ValueError, match=name):
            make()
    with pytest.raises(TypeError, match="robust"):
        icp(target, target, robust="cauchy")


# ----------------------------------------------------------------------------- Open3D


def _open3d_icp(o3d, pairs, method, max_distance, normals, iterations):
    reg = o3d.pipelines.registration
    est = (reg.TransformationEstimationPointToPoint() if method == "point_to_point"
           else reg.TransformationEstimationPointToPlane())
    out = []
    for b in range(pairs.source.shape[0]):  # the peer, one pair per call
        src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pairs.source[b].numpy()))
        tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pairs.target[b].numpy()))
        tgt.normals = o3d.utility.Vector3dVector(normals[b].numpy())
        r = reg.registration_icp(src, tgt, max_distance, np.eye(4), est,
                                 reg.ICPConvergenceCriteria(1e-6, 1e-6, iterations))
        out.append((np.asarray(r.transformation), r.inlier_rmse))
    transforms = torch.tensor(np.stack([t for t, _ in out]))
    return transforms, torch.tensor([e for _, e in out], dtype=torch.float64)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["point_to_point", "point_to_plane"])
def test_against_open3d_on_rabbit_scans(method):
    o3d = pytest.importorskip("open3d", exc_type=ImportError)
    pairs = rabbit_scan_pairs(4, 8000, generator=torch.Generator().manual_seed(0))
    max_distance = 0.2 * pairs.size
    normals = estimate_normals(pairs.target, 10)
    iterations = 50 if method == "point_to_point" else 30
    ours = icp(pairs.source, pairs.target, method=method, max_distance=max_distance,
               target_normals=normals, convergence=ICPConvergence(iterations))
    peer, peer_rmse = _open3d_icp(o3d, pairs, method, max_distance, normals, iterations)
    ok_ours = _angle_deg(ours.transform, pairs.truth) < 0.5
    ok_peer = _angle_deg(peer, pairs.truth) < 0.5
    # the pairs of generator seed 0: Open3D and ours both within 0.5 deg on 2 of the 4
    assert int(ok_ours.sum()) >= int(ok_peer.sum()) and int(ok_ours.sum()) >= 2
    # same max_distance: RMSE no worse than Open3D's to 1e-4 relative. Our relative
    # convergence test stops after 12-14 point-to-plane iterations where Open3D runs on;
    # measured: ours 1e-5 to 5.1e-5 above Open3D's on these 4 pairs, angles equally good.
    assert bool((ours.rmse[ok_peer] <= peer_rmse[ok_peer] * (1 + 1e-4)).all())


@pytest.mark.slow
def test_cauchy_with_outliers_beats_least_squares():
    """30% outliers, no max_distance: Cauchy point-to-plane converges in >= 8 of 10 cases,
    more often than plain (least-squares) point-to-point.

    Measured (seed 2, 10 pairs, rotation errors in degrees): at 3000 points Cauchy
    point-to-plane converges in 10 of 10 (at most 0.40 deg left), least-squares
    point-to-point in 0 of 10 (1.2-7.3 deg left); at 2000 points Cauchy reaches 8 of 10
    (0.50 and 0.68 deg left, the sampling bias of 1400 inlier points), at 4000 and 6000
    points 10 of 10, so 3000 points keep a margin at a bounded test time.
    Cauchy point-to-point converges too slowly to be the method here (2 of 10 within
    40 iterations at 2000 and at 6000 points): each step only moves part of the way.
    """
    pairs = rabbit_scan_pairs(10, 3000, generator=torch.Generator().manual_seed(2), outliers=0.3)
    l2 = icp(pairs.source, pairs.target, convergence=ICPConvergence(30))
    cauchy = icp(pairs.source, pairs.target, robust=ICPRobust("cauchy"),
                 method="point_to_plane", convergence=ICPConvergence(30))
    ok_l2 = _angle_deg(l2.transform, pairs.truth) < 0.5
    ok_cauchy = _angle_deg(cauchy.transform, pairs.truth) < 0.5
    assert int(ok_cauchy.sum()) >= 8 and int(ok_cauchy.sum()) > int(ok_l2.sum())


@pytest.mark.slow
def test_tukey_from_a_rough_alignment():
    pairs = rabbit_scan_pairs(3, 3000, generator=torch.Generator().manual_seed(3), outliers=0.3,
                              angles=(3.0, 5.0), shift=0.01)
    res = icp(pairs.source, pairs.target, robust=ICPRobust("tukey"), method="point_to_plane",
              convergence=ICPConvergence(30))
    assert bool((_angle_deg(res.transform, pairs.truth) < 0.5).all())


def test_cycling_matches_stop_without_losing_accuracy():
    """On these noisy scans the matches of two pairs cycle between neighbours: the motion
    never falls below ``tol`` (30 iterations, unconverged, with the motion test alone).
    The RMSE test stops them, and 30 more iterations improve nothing that matters (the
    RMSE by at most 1e-4 of itself, below the spread of Open3D against us, measured:
    at most 2.2e-5)."""
    pairs = rabbit_scan_pairs(4, 10000, generator=torch.Generator().manual_seed(0))
    normals = estimate_normals(pairs.target, 10)
    kw = {"method": "point_to_plane", "max_distance": 0.2 * pairs.size,
          "target_normals": normals}
    res = icp(pairs.source, pairs.target, **kw)
    assert bool(res.converged.all()) and int(res.iterations.max()) < 20
    more = icp(pairs.source, pairs.target, init=res.transform,
               convergence=ICPConvergence(30, tol=1e-12), **kw)
    assert bool((more.rmse >= res.rmse * (1 - 1e-4)).all())
    # the rotation moves by less than a quarter of its own error against the truth
    error = _angle_deg(res.transform, pairs.truth)
    assert bool((_angle_deg(more.transform, res.transform) < 0.25 * error).all())
    shift = (more.transform[:, :3, 3] - res.transform[:, :3, 3]).norm(dim=-1)
    assert float(shift.max()) < 1e-4 * pairs.size
