"""Tests for torchgeo_cg.transforms.rotations and euler: scipy live, round trips, gradients."""

from __future__ import annotations

import itertools
import math
import warnings

import pytest
import torch

from torchgeo_cg.transforms import rotations as R

Rotation = pytest.importorskip("scipy.spatial.transform").Rotation
F64 = torch.float64
HARD = [0.0, 1e-12, 1e-8, 1e-4, math.pi - 1e-4, math.pi - 1e-8, math.pi]
SEQS = [a + b + c for a, b, c in itertools.product("xyz", repeat=3) if a != b and b != c]
SEQS = SEQS + [s.upper() for s in SEQS]


def hard_rotvecs(dtype=F64) -> torch.Tensor:
    """Angles of HARD about x, y, z and five random axes, plus 64 random rotation vectors."""
    gen = torch.Generator().manual_seed(0)
    axes = torch.cat([torch.eye(3, dtype=F64),
                      torch.nn.functional.normalize(torch.randn(5, 3, generator=gen,
                                                                dtype=F64), dim=-1)])
    rv = (torch.tensor(HARD, dtype=F64)[:, None, None] * axes[None]).reshape(-1, 3)
    rand = torch.randn(64, 3, generator=gen, dtype=F64)
    rand = rand * (torch.rand(64, 1, generator=gen, dtype=F64) * math.pi / rand.norm(dim=-1,
                                                                                    keepdim=True))
    return torch.cat([rv, rand]).to(dtype)


def same_quat(a, b):
    """Largest difference of two quaternion sets up to sign."""
    return torch.minimum((a - b).abs().amax(-1), (a + b).abs().amax(-1)).max().item()


@pytest.mark.parametrize("dtype,bound", [(F64, 1e-14), (torch.float32, 1e-6)])
def test_conversions_match_scipy_at_hard_angles(dtype, bound):
    rv = hard_rotvecs()
    ref = Rotation.from_rotvec(rv.numpy())
    mat = torch.from_numpy(ref.as_matrix())
    quat = torch.from_numpy(ref.as_quat()[:, [3, 0, 1, 2]])
    rvd, matd, quatd = rv.to(dtype), mat.to(dtype), quat.to(dtype)
    assert (R.so3_exp(rvd).double() - mat).abs().max() <= 4 * bound
    assert (R.axis_angle_to_matrix(rvd).double() - mat).abs().max() <= 4 * bound
    assert same_quat(R.matrix_to_quaternion(matd).double(), quat) <= 4 * bound
    assert (R.quaternion_to_matrix(quatd).double() - mat).abs().max() <= 4 * bound
    assert same_quat(R.axis_angle_to_quaternion(rvd).double(), quat) <= 4 * bound
    # the log: the same vector, or at π its antipode (the same rotation)
    ours = R.matrix_to_axis_angle(matd).double()
    peer = torch.from_numpy(Rotation.from_matrix(mat.numpy()).as_rotvec())
    err = torch.where(rv.norm(dim=-1) < math.pi - 1e-6, (ours - peer).norm(dim=-1),
                      torch.minimum((ours - peer).norm(dim=-1), (ours + peer).norm(dim=-1)))
    assert err.max() <= 8 * bound * math.pi
    assert (ours.norm(dim=-1) <= math.pi + 4 * bound).all()


def test_log_exp_round_trips_and_half_turns():
    rv = hard_rotvecs()
    inside = rv.norm(dim=-1) < math.pi - 1e-6
    back = R.so3_log(R.so3_exp(rv))
    scale = rv.norm(dim=-1).clamp_min(1e-300)
    assert ((back - rv).norm(dim=-1) / scale)[inside].max() <= 1e-14
    assert (R.so3_exp(R.so3_log(R.so3_exp(rv))) - R.so3_exp(rv)).abs().max() <= 1e-15 * 8
    # half-turns about every axis: diag(-1, 1, -1) breaks PyTorch3D's fast path
    for m in (torch.diag(torch.tensor(d, dtype=F64)) for d in
              ([-1.0, 1.0, -1.0], [1.0, -1.0, -1.0], [-1.0, -1.0, 1.0])):
        w = R.matrix_to_axis_angle(m)
        assert torch.isfinite(w).all() and abs(w.norm().item() - math.pi) < 1e-15
        assert (w >= 0).all()  # the documented sign rule: largest component positive
        assert (R.so3_exp(w) - m).abs().max() < 1e-15


def test_se3_round_trips_on_pytorch3d_1239_and_1609():
    # PyTorch3D #1239: a rotation of nearly π about a mixed axis with a large translation;
    # #1609: se3_log of a near-identity rotation with a tiny angle returned NaN.
    axis = torch.tensor([0.6, -0.48, 0.64], dtype=F64)
    cases = [R.se3_exp(torch.cat([torch.tensor([10.0, -20.0, 5.0], dtype=F64),
                                  axis * (math.pi - 1e-7)])),
             R.se3_exp(torch.tensor([0.1, 0.2, 0.3, 1e-9, -2e-9, 3e-9], dtype=F64)),
             R.se3_exp(torch.tensor([1.0, 0.0, 0.0, 0.0, 0.0, math.pi], dtype=F64))]
    for t in cases:
        assert (R.se3_exp(R.se3_log(t)) - t).abs().max() <= 1e-13 * t.abs().max()
    xi = torch.tensor([0.5, -1.0, 2.0, 0.1, 0.2, -0.3], dtype=F64)
    assert (R.se3_log(R.se3_exp(xi)) - xi).abs().max() < 1e-15 * 4


def test_se3_exp_matches_the_matrix_exponential():
    gen = torch.Generator().manual_seed(1)
    xi = torch.randn(16, 6, generator=gen, dtype=F64)
    twist = torch.zeros(16, 4, 4, dtype=F64)
    twist[:, :3, :3] = R.so3_hat(xi[:, 3:])
    twist[:, :3, 3] = xi[:, :3]
    assert (R.se3_exp(xi) - torch.linalg.matrix_exp(twist)).abs().max() < 1e-13


def test_left_jacobian_is_the_derivative_of_exp_and_inverts():
    gen = torch.Generator().manual_seed(2)
    for w in [torch.randn(3, generator=gen, dtype=F64), torch.tensor([1e-9, 0, 0], dtype=F64),
              torch.tensor([0.0, 0.0, 3.0], dtype=F64), torch.zeros(3, dtype=F64)]:
        jac = R.so3_left_jacobian(w)
        # exp(w + δ) exp(w)⁻¹ = exp(J δ): the derivative at δ = 0, column by column
        num = torch.autograd.functional.jacobian(
            lambda d, w=w: R.so3_log(R.so3_exp(w + d) @ R.so3_exp(w).mT),
            torch.zeros(3, dtype=F64))
        assert (num - jac).abs().max() < 1e-12
        assert (R.so3_left_jacobian_inverse(w) @ jac - torch.eye(3, dtype=F64)).abs().max() < 1e-14


@pytest.mark.parametrize("seq", SEQS)
def test_euler_matches_scipy_every_sequence(seq):
    gen = torch.Generator().manual_seed(3)
    ang = (torch.rand(64, 3, generator=gen, dtype=F64) * 2 - 1) * torch.tensor(
        [180.0, 90.0, 180.0], dtype=F64)
    if seq[0].lower() == seq[2].lower():
        ang[:, 1] = ang[:, 1].abs() * 2  # proper sequences: middle in [0, 180]
    mat = torch.from_numpy(Rotation.from_euler(seq, ang.numpy(), degrees=True).as_matrix())
    assert (R.euler_to_matrix(ang, seq) - mat).abs().max() < 1e-14 * 8
    ours = R.matrix_to_euler(mat, seq)
    peer = torch.from_numpy(Rotation.from_matrix(mat.numpy()).as_euler(seq, degrees=True))
    diff = (ours - peer).abs()
    assert torch.minimum(diff, 360 - diff).max() < 1e-14 * 180 * 8
    rad = R.matrix_to_euler(mat, seq, degrees=False)
    assert (R.euler_to_matrix(rad, seq, degrees=False) - mat).abs().max() < 1e-14 * 8


@pytest.mark.parametrize("seq", SEQS)
def test_euler_gimbal_lock_as_scipy_with_finite_gradients(seq):
    ang = torch.tensor([[30.0, 0.0, 40.0], [-70.0, 0.0, 15.0]], dtype=F64)
    ang[:, 1] = 0.0 if seq[0].lower() == seq[2].lower() else 90.0
    mat = torch.from_numpy(Rotation.from_euler(seq, ang.numpy(), degrees=True).as_matrix())
    ours = R.matrix_to_euler(mat, seq)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy warns at lock
        peer = torch.from_numpy(Rotation.from_matrix(mat.numpy()).as_euler(seq, degrees=True))
    diff = (ours - peer).abs()
    assert torch.minimum(diff, 360 - diff).max() < 1e-9
    assert (R.euler_to_matrix(ours, seq) - mat).abs().max() < 1e-14 * 8
    m = mat.clone().requires_grad_(True)
    R.matrix_to_euler(m, seq).sum().backward()
    assert torch.isfinite(m.grad).all()


@pytest.mark.parametrize("dtype,bound", [(F64, 1e-14), (torch.float32, 1e-6)])
@pytest.mark.parametrize("seq", SEQS)
def test_euler_near_gimbal_lock_rebuilds_the_matrix(seq, dtype, bound):
    # within a few eps of the lock the middle angle keeps its sign: Ry(-2e-6) as "xyx"
    # is not (0, 2e-6, 0); every sequence, both lock angles, both sides, against scipy
    gen = torch.Generator().manual_seed(11)
    proper = seq[0].lower() == seq[2].lower()
    locks = (0.0, math.pi) if proper else (-math.pi / 2, math.pi / 2)
    steps = torch.tensor([0.0, 1e-9, 1e-7, 5e-7, 2e-6, 1e-5, 1e-3], dtype=F64)
    middle = torch.cat([lock + side * steps for lock in locks for side in (1.0, -1.0)])
    outer = (torch.rand(middle.shape[0], 2, generator=gen, dtype=F64) * 2 - 1) * math.pi
    ang = torch.stack([outer[:, 0], middle, outer[:, 1]], -1)
    mat = torch.from_numpy(Rotation.from_euler(seq, ang.numpy()).as_matrix())
    ours = R.matrix_to_euler(mat.to(dtype), seq, degrees=False)
    assert ours.dtype == dtype
    rebuilt = R.euler_to_matrix(ours.double(), seq, degrees=False)
    assert (rebuilt - mat).abs().max() <= bound
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy warns at lock
        peer = torch.from_numpy(Rotation.from_matrix(mat.numpy()).as_euler(seq))
    far = (middle - torch.tensor(locks, dtype=F64)[:, None]).abs().amin(0) >= 1e-5
    if dtype == F64:  # away from scipy's lock the angles are scipy's
        diff = (ours - peer)[far].abs()
        assert torch.minimum(diff, 2 * math.pi - diff).max() < 1e-9
    if proper:  # the middle angle of a proper sequence lies in [0, pi]
        assert bool(((ours[:, 1] >= 0) & (ours[:, 1] <= math.pi)).all())


def test_euler_issue_case_keeps_the_sign():
    m = torch.from_numpy(Rotation.from_euler("y", -2e-6).as_matrix()).float()
    angles = R.matrix_to_euler(m, "xyx", degrees=False)
    rebuilt = R.euler_to_matrix(angles.double(), "xyx", degrees=False)
    assert (rebuilt - m.double()).abs().max() < 1e-6


@pytest.mark.grad
@pytest.mark.parametrize("angle", HARD)
def test_gradcheck_vector_and_quaternion_maps(angle):
    axis = torch.nn.functional.normalize(torch.tensor([0.3, -0.5, 0.8], dtype=F64), dim=0)
    w = (axis * angle).requires_grad_(True)
    for fn in (R.so3_exp, R.so3_left_jacobian):
        assert torch.autograd.gradcheck(fn, (w,))
    if angle < math.pi - 1e-6:  # w >= 0 on output: the sign flips where w crosses 0 at π
        assert torch.autograd.gradcheck(R.axis_angle_to_quaternion, (w,))
    else:  # at π the one-sided derivative: finite
        R.axis_angle_to_quaternion(w).sum().backward()
        assert torch.isfinite(w.grad).all()
    if angle < math.pi - 1e-3:  # J⁻¹ and se3 near π are fine; the log's branch flips at π
        assert torch.autograd.gradcheck(R.so3_left_jacobian_inverse, (w,))
    xi = torch.cat([torch.tensor([0.3, -1.0, 2.0], dtype=F64), axis * angle]).requires_grad_(True)
    assert torch.autograd.gradcheck(R.se3_exp, (xi,))
    q = R.axis_angle_to_quaternion(axis * angle).detach()
    if q[0] > 1e-6:  # at w = 0 the canonical sign flips: one-sided derivative only
        assert torch.autograd.gradcheck(R.quaternion_to_axis_angle, (q.requires_grad_(True),))
    assert torch.autograd.gradcheck(R.quaternion_to_matrix, (q.requires_grad_(True),))


def test_gradient_at_zero_is_the_analytic_limit():
    w = torch.zeros(3, dtype=F64, requires_grad=True)
    jac = torch.autograd.functional.jacobian(R.so3_exp, w)  # d exp / dω at 0 = hat(e_k)
    for k in range(3):
        assert (jac[..., k] - R.so3_hat(torch.eye(3, dtype=F64)[k])).abs().max() == 0
    jac = torch.autograd.functional.jacobian(R.quaternion_to_axis_angle,
                                             torch.tensor([1.0, 0, 0, 0], dtype=F64))
    assert (jac[:, 1:] - 2 * torch.eye(3, dtype=F64)).abs().max() < 1e-15


@pytest.mark.grad
@pytest.mark.parametrize("angle", [1e-8, 1e-4, 1.0, math.pi - 1e-4])
def test_manifold_jacobian_of_matrix_maps(angle):
    # d log(R exp δ)/dδ at δ = 0 is J_r⁻¹(ω) = J_l⁻¹(-ω): checked against the analytic form
    axis = torch.nn.functional.normalize(torch.tensor([0.2, 0.9, -0.4], dtype=F64), dim=0)
    w = axis * angle
    rot = R.so3_exp(w)
    num = torch.autograd.functional.jacobian(lambda d: R.so3_log(rot @ R.so3_exp(d)),
                                             torch.zeros(3, dtype=F64))
    assert (num - R.so3_left_jacobian_inverse(-w)).abs().max() < 1e-8
    # rotation_angle(I, R exp δ) has derivative ω̂ᵀ J_r⁻¹ ... = ω̂ᵀ (its gradient along ω)
    num = torch.autograd.functional.jacobian(
        lambda d: R.rotation_angle(torch.eye(3, dtype=F64), rot @ R.so3_exp(d)),
        torch.zeros(3, dtype=F64))
    assert (num - axis).abs().max() < 1e-7


def test_rotation_angle_small_and_near_pi():
    for angle in HARD[1:]:
        w = torch.tensor([0.0, 0.6, 0.8], dtype=F64) * angle
        got = R.rotation_angle(torch.eye(3, dtype=F64), R.so3_exp(w))
        assert abs(got.item() - angle) <= 1e-14 * max(angle, 1e-300) * 4
    m = torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=F64)).requires_grad_(True)
    ang = R.rotation_angle(torch.eye(3, dtype=F64), m)
    ang.backward()
    assert abs(ang.item() - math.pi) < 1e-15 and torch.isfinite(m.grad).all()


def test_quaternion_algebra():
    gen = torch.Generator().manual_seed(4)
    a = R.matrix_to_quaternion(R.random_rotations(8, generator=gen, dtype=F64))
    b = R.matrix_to_quaternion(R.random_rotations(8, generator=gen, dtype=F64))
    ab = R.quaternion_multiply(a, b)
    assert (R.quaternion_to_matrix(ab) - R.quaternion_to_matrix(a) @ R.quaternion_to_matrix(b)
            ).abs().max() < 1e-15 * 8
    assert (ab[:, 0] >= 0).all()
    p = torch.randn(8, 3, generator=gen, dtype=F64)
    assert (R.quaternion_apply(a, p) - (R.quaternion_to_matrix(a) @ p[..., None])[..., 0]
            ).abs().max() < 1e-14
    eye = R.quaternion_multiply(a, R.quaternion_conjugate(a))
    assert (eye - torch.tensor([1.0, 0, 0, 0], dtype=F64)).abs().max() < 1e-15 * 4


def test_slerp_matches_scipy_and_endpoints():
    slerp = pytest.importorskip("scipy.spatial.transform").Slerp
    gen = torch.Generator().manual_seed(5)
    q0 = R.matrix_to_quaternion(R.random_rotations(6, generator=gen, dtype=F64))
    q1 = R.matrix_to_quaternion(R.random_rotations(6, generator=gen, dtype=F64))
    ts = torch.tensor([0.0, 0.25, 0.5, 1.0], dtype=F64)
    for i in range(6):  # six reference problems, scipy takes one pair at a time
        key = Rotation.from_quat(torch.stack([q0[i], q1[i]])[:, [1, 2, 3, 0]].numpy())
        peer = torch.from_numpy(slerp([0, 1], key)(ts.numpy()).as_quat()[:, [3, 0, 1, 2]])
        ours = R.quaternion_slerp(q0[i], q1[i], ts[:, None].squeeze(-1)[:, None].squeeze(-1))
        assert same_quat(ours, peer) < 1e-14


@pytest.mark.grad
def test_slerp_gradcheck_near_equal_and_antipodal():
    gen = torch.Generator().manual_seed(6)
    q0 = R.matrix_to_quaternion(R.random_rotations(1, generator=gen, dtype=F64))[0]
    near = q0 + 1e-6 * torch.randn(4, generator=gen, dtype=F64)
    for q1 in (near / near.norm(), -near / near.norm(),
               R.matrix_to_quaternion(R.random_rotations(1, generator=gen, dtype=F64))[0]):
        for t in (0.0, 0.3, 1.0):
            tt = torch.tensor(t, dtype=F64, requires_grad=True)
            assert torch.autograd.gradcheck(R.quaternion_slerp, (
                q0.clone().requires_grad_(True), q1.clone().requires_grad_(True), tt))


def test_random_rotations_are_haar():
    r = R.random_rotations(20000, generator=torch.Generator().manual_seed(7), dtype=F64)
    assert (r @ r.mT - torch.eye(3, dtype=F64)).abs().max() < 1e-14
    assert (torch.linalg.det(r) - 1).abs().max() < 1e-14
    # Haar: E[R] = 0 and the angle density (1 - cos θ)/π has mean π/2 + 2/π
    assert r.mean(0).abs().max() < 0.02
    ang = R.rotation_angle(torch.eye(3, dtype=F64), r)
    assert abs(ang.mean().item() - (math.pi / 2 + 2 / math.pi)) < 0.02


def test_rotation_6d_uses_columns_and_round_trips():
    r = R.random_rotations(5, generator=torch.Generator().manual_seed(8), dtype=F64)
    d6 = R.matrix_to_rotation_6d(r)
    assert (d6[:, :3] - r[:, :, 0]).abs().max() == 0
    assert (R.rotation_6d_to_matrix(d6) - r).abs().max() < 1e-15 * 4
    assert torch.isfinite(R.rotation_6d_to_matrix(torch.zeros(6, dtype=F64))).all()


@pytest.mark.grad
def test_rotation_mean_is_the_chordal_minimizer_and_differentiable():
    gen = torch.Generator().manual_seed(9)
    center = R.random_rotations(1, generator=gen, dtype=F64)[0]
    rots = center @ R.so3_exp(0.3 * torch.randn(7, 3, generator=gen, dtype=F64))
    w = torch.rand(7, generator=gen, dtype=F64) + 0.1
    mean = R.rotation_mean(rots, w)
    m = (rots * w[:, None, None]).sum(0)
    u, _, vh = torch.linalg.svd(m)
    ref = u @ torch.diag(torch.tensor([1.0, 1.0, torch.det(u @ vh).item()], dtype=F64)) @ vh
    assert (mean - ref).abs().max() < 1e-14
    assert (R.rotation_mean(rots, w * 1e300) - mean).abs().max() < 1e-14
    assert torch.autograd.gradcheck(R.rotation_mean, (rots.clone().requires_grad_(True),
                                                      w.clone().requires_grad_(True)))
    same = center.expand(4, 3, 3).clone().requires_grad_(True)  # repeated singular values
    R.rotation_mean(same).sum().backward()
    assert torch.isfinite(same.grad).all()


def test_bad_input_errors():
    with pytest.raises(ValueError, match="seq"):
        R.euler_to_matrix(torch.zeros(3), "xxy")
    with pytest.raises(ValueError, match="seq"):
        R.matrix_to_euler(torch.eye(3), "xYz")
    with pytest.raises(Exception, match="matrix"):
        R.matrix_to_quaternion(torch.zeros(3, 4))
    with pytest.raises(Exception, match="omega"):
        R.so3_exp(torch.zeros(4))
    with pytest.raises(ValueError, match="n"):
        R.random_rotations(-1)
    assert torch.isnan(R.matrix_to_quaternion(torch.full((3, 3), float("nan")))).all()
