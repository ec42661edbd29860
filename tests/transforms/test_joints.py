"""3D joints and forward kinematics: hand-derived matrices, scipy, a brute-force chain."""

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.transforms import (
    FixedTransform,
    Orbit,
    Prismatic,
    Revolute,
    SceneGraph,
    compose,
    translation,
)
from torchgeo_cg.transforms.rotations import axis_angle_to_matrix

F64 = torch.float64


def _rigid(rot: np.ndarray, t) -> torch.Tensor:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot, t
    return torch.from_numpy(m)


def test_revolute_hand_derived():
    """Rz(q) about the z axis through a joint frame at (1, 0, 0), written out."""
    q = torch.tensor([0.0, math.pi / 2, math.pi, -math.pi / 3], dtype=F64)
    got = Revolute([0.0, 0.0, 3.0], origin=[1.0, 0.0, 0.0]).double()(q)
    for k, angle in enumerate(q.tolist()):
        c, s = math.cos(angle), math.sin(angle)
        want = torch.tensor([[c, -s, 0, 1], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=F64)
        torch.testing.assert_close(got[k], want, rtol=0, atol=1e-15)


def test_prismatic_hand_derived():
    q = torch.tensor([0.0, 0.5, -2.0], dtype=F64)
    got = Prismatic([0.0, 0.0, 2.0], origin=[1.0, 2.0, 3.0]).double()(q)
    for k, d in enumerate(q.tolist()):
        want = torch.eye(4, dtype=F64)
        want[:3, 3] = torch.tensor([1.0, 2.0, 3.0 + d], dtype=F64)
        torch.testing.assert_close(got[k], want, rtol=0, atol=0)


def test_revolute_against_scipy_and_axis_angle():
    g = torch.Generator().manual_seed(0)
    for _ in range(5):
        axis = torch.randn(3, generator=g, dtype=F64)
        q = 4 * torch.randn(7, generator=g, dtype=F64)
        q[0] = 0.0
        q[1] = math.pi
        q[2] = 1e-12
        got = Revolute(axis).double()(q)
        unit = (axis / axis.norm()).numpy()
        want = Rotation.from_rotvec(q.numpy()[:, None] * unit).as_matrix()
        torch.testing.assert_close(got[:, :3, :3], torch.from_numpy(want), rtol=0, atol=2e-15)
        rotvec = q[:, None] * torch.from_numpy(unit)
        torch.testing.assert_close(got[:, :3, :3], axis_angle_to_matrix(rotvec), rtol=0,
                                   atol=2e-15)
        torch.testing.assert_close(got[:, :3, 3], torch.zeros(7, 3, dtype=F64), rtol=0, atol=0)
        torch.testing.assert_close(got[:, 3], torch.tensor([[0.0, 0, 0, 1]] * 7, dtype=F64),
                                   rtol=0, atol=0)


def test_revolute_small_angle_is_relatively_accurate():
    """``R - I`` keeps its relative accuracy at tiny angles (2 sin²(q/2), not 1 - cos q)."""
    for q in (1e-4, 1e-8, 1e-12):
        got = Revolute([1.0, 0.0, 0.0]).double()(torch.tensor([q], dtype=F64))[0]
        assert got[1, 2].item() == pytest.approx(-math.sin(q), rel=1e-15)
        assert (1 - got[1, 1].item()) == pytest.approx(2 * math.sin(q / 2) ** 2, rel=1e-15)


def test_origin_as_a_matrix():
    """``parent_from_child(q) = origin @ motion(q)`` with a rigid (4, 4) origin."""
    rot = Rotation.from_rotvec([0.2, -0.5, 0.9]).as_matrix()
    origin = _rigid(rot, [0.5, -1.0, 2.0])
    q = torch.tensor([0.3, -1.2], dtype=F64)
    got = Revolute([0.0, 1.0, 0.0], origin).double()(q)
    for k in range(2):
        motion = _rigid(Rotation.from_rotvec([0.0, q[k].item(), 0.0]).as_matrix(), [0, 0, 0])
        torch.testing.assert_close(got[k], origin @ motion, rtol=0, atol=1e-15)
    got = Prismatic([1.0, 1.0, 0.0], origin).double()(q)
    for k in range(2):
        slide = translation(q[k] * torch.tensor([1.0, 1.0, 0.0], dtype=F64) / math.sqrt(2))
        torch.testing.assert_close(got[k], origin @ slide, rtol=0, atol=1e-15)


def _arm() -> SceneGraph:
    arm = SceneGraph()
    arm.add("base", None, Revolute([0.0, 0.0, 1.0]))
    arm.add("shoulder", "base", Revolute([0.0, 1.0, 0.0], origin=[0.0, 0.0, 1.0]))
    arm.add("elbow", "shoulder", Revolute([0.0, 1.0, 0.0], origin=[2.0, 0.0, 0.0]))
    arm.add("slide", "elbow", Prismatic([1.0, 0.0, 0.0], origin=[1.5, 0.0, 0.0]))
    arm.add("tool", "slide", translation(torch.tensor([0.0, 0.0, -0.25])))
    arm.add("camera", "base", Revolute([1.0, 1.0, 1.0], origin=[0.3, 0.0, 0.5]))
    return arm.double()


def test_chain_against_brute_force_composition():
    """Each node's world matrix is the product of the locals on its path, for every row."""
    g = torch.Generator().manual_seed(1)
    arm = _arm()
    q = torch.randn(11, 6, generator=g, dtype=F64)
    world = arm.world_transforms(q)
    assert world.matrices.shape == (6, 11, 4, 4)
    assert world.positions().shape == (6, 11, 3)
    for t in range(11):  # a loop in the test: the reference, not the implementation
        for k, name in enumerate(arm.names):
            path, node = [], name
            while node is not None:
                i = arm.names.index(node)
                path.append(arm.locals[node](q[t, i:i + 1])[0])
                node = arm.parent(node)
            want = compose(*reversed(path))
            torch.testing.assert_close(world.matrices[k, t], want, rtol=0, atol=1e-14)
    torch.testing.assert_close(arm(q), world.matrices)


def test_chain_tip_hand_derived():
    """Base yaw a, shoulder pitch b, elbow pitch c, slide d: the tool tip in closed form.

    In the arm's vertical plane (a rotation by +b about y tips x towards -z) the reach is
    ``r = 2 cos b + (1.5 + d) cos(b + c)`` and the height
    ``h = 1 - 2 sin b - (1.5 + d) sin(b + c) - 0.25 cos(b + c)``, with
    ``r += -0.25 sin(b + c)`` from the tool offset; the yaw turns the plane by ``a``.
    """
    q = torch.tensor([[0.3, 0.4, -0.9, 0.2, 0.0, 0.0], [-2.0, 1.1, 0.5, -0.7, 0.0, 0.0]],
                     dtype=F64)
    tip = _arm().world_transforms(q).get("tool")[:, :3, 3]
    for t, (a, b, c, d, _, _) in enumerate(q.tolist()):
        r = 2 * math.cos(b) + (1.5 + d) * math.cos(b + c) - 0.25 * math.sin(b + c)
        h = 1 - 2 * math.sin(b) - (1.5 + d) * math.sin(b + c) - 0.25 * math.cos(b + c)
        want = torch.tensor([r * math.cos(a), r * math.sin(a), h], dtype=F64)
        torch.testing.assert_close(tip[t], want, rtol=0, atol=1e-14)


def test_chain_jacobian_is_the_geometric_jacobian():
    """d tip / d q_i = axis_i × (tip - joint_i) for revolute joints, axis_i for the slide."""
    arm = _arm()
    q = torch.tensor([[0.3, 0.4, -0.9, 0.2, 0.1, -0.3]], dtype=F64)

    def tip(q):
        return arm.world_transforms(q).get("tool")[0, :3, 3]

    jac = torch.autograd.functional.jacobian(tip, q)[:, 0]  # (3, 6)
    world = arm.world_transforms(q)
    p = tip(q)
    for i, name in enumerate(("base", "shoulder", "elbow")):
        frame = world.get(name)[0]
        axis = frame[:3, :3] @ arm.locals[name].axis
        want = torch.linalg.cross(axis, p - frame[:3, 3])
        torch.testing.assert_close(jac[:, i], want, rtol=0, atol=1e-13)
    slide = world.get("slide")[0][:3, :3] @ arm.locals["slide"].axis
    torch.testing.assert_close(jac[:, 3], slide, rtol=0, atol=1e-14)
    torch.testing.assert_close(jac[:, 4:], torch.zeros(3, 2, dtype=F64), rtol=0, atol=0)


def test_gradcheck_joints_and_chain():
    g = torch.Generator().manual_seed(2)
    q = torch.randn(4, generator=g, dtype=F64, requires_grad=True)
    q0 = torch.tensor([0.0, math.pi, -math.pi, 1e-9], dtype=F64, requires_grad=True)
    for joint in (Revolute([0.2, 0.3, -1.0], origin=[1.0, 2.0, 0.0]),
                  Prismatic([0.0, 1.0, 1.0], origin=[0.0, 0.0, 1.0])):
        joint = joint.double()
        assert torch.autograd.gradcheck(joint, (q,))
        assert torch.autograd.gradcheck(joint, (q0,))
        assert torch.autograd.gradgradcheck(joint, (q,))
    arm = _arm()
    qs = torch.randn(3, 6, generator=g, dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x: arm.world_transforms(x).matrices, (qs,))


def test_shared_time_and_joint_values_agree():
    """A ``(T,)`` theta is the ``(T, K)`` one with every column equal to it."""
    arm = _arm()
    theta = torch.linspace(-3, 3, 9, dtype=F64)
    torch.testing.assert_close(arm.world_transforms(theta).matrices,
                               arm.world_transforms(theta[:, None].expand(9, 6)).matrices)
    # 2D graphs take joint values as well: one column per node
    scene = SceneGraph().double()
    scene.add("a", None, Orbit(2.0).double())
    scene.add("b", "a", Orbit(1.0, speed=3.0).double())
    q = torch.stack([theta, 2 * theta], -1)
    world = scene.world_transforms(q)
    torch.testing.assert_close(world.get("b"), Orbit(2.0).double()(theta)
                               @ Orbit(1.0, speed=3.0).double()(2 * theta))


def test_identity_and_fixed_nodes_take_the_graph_size():
    scene = SceneGraph()
    scene.add("root")
    scene.add("arm", "root", Revolute([0.0, 0.0, 1.0], origin=[1.0, 0.0, 0.0]))
    scene.add("frame", "arm")
    scene.add("fixed", "frame", torch.eye(4))
    world = scene.world_transforms(torch.tensor([0.0, math.pi / 2]))
    assert world.matrices.shape == (4, 2, 4, 4)
    torch.testing.assert_close(world.get("root"), torch.eye(4).expand(2, 4, 4))
    torch.testing.assert_close(world.get("fixed"), world.get("arm"))
    only_identity = SceneGraph()
    only_identity.add("a")
    assert only_identity.world_transforms(torch.zeros(2)).matrices.shape == (1, 2, 3, 3)


def test_nan_empty_and_dtypes():
    joint = Revolute([0.0, 1.0, 0.0], origin=[1.0, 0.0, 0.0])
    out = joint(torch.tensor([0.1, math.nan]))
    assert torch.isfinite(out[0]).all() and torch.isnan(out[1]).all()
    assert joint(torch.zeros(0)).shape == (0, 4, 4)
    assert joint(torch.zeros(2, 3)).shape == (2, 3, 4, 4)
    assert joint(torch.zeros(2, dtype=torch.float16)).dtype == torch.float16
    with pytest.raises(TypeError, match="float64"):
        joint(torch.zeros(2, dtype=F64))
    assert joint.double()(torch.zeros(2, dtype=F64)).dtype == F64
    arm = _arm()
    q = torch.zeros(3, 6, dtype=F64)
    q[1, 2] = math.nan
    world = arm.world_transforms(q)
    assert torch.isfinite(world.matrices[:, [0, 2]]).all()
    elbow_down = [arm.names.index(n) for n in ("elbow", "slide", "tool")]
    assert torch.isnan(world.matrices[elbow_down, 1]).any(dim=(-1, -2)).all()
    assert arm.world_transforms(torch.zeros(0, 6, dtype=F64)).matrices.shape == (6, 0, 4, 4)


def test_errors():
    with pytest.raises(ValueError, match="axis: expected a non-zero direction"):
        Revolute([0.0, 0.0, 0.0])
    with pytest.raises(ShapeError, match=r"axis: expected shape \(3\), got \(2\)"):
        Prismatic([1.0, 0.0])
    with pytest.raises(ShapeError, match=r"origin: expected shape \(4, 4\), got \(3, 3\)"):
        Revolute([1.0, 0.0, 0.0], origin=torch.eye(3))
    with pytest.raises(TypeError, match="origin is torch.float64.*axis is torch.float32"):
        Revolute(torch.tensor([1.0, 0.0, 0.0]), origin=torch.zeros(3, dtype=F64))
    with pytest.raises(TypeError, match="q: expected a floating"):
        Revolute([1.0, 0.0, 0.0])(torch.zeros(2, dtype=torch.long))
    with pytest.raises(ShapeError, match=r"matrix: expected shape \(3, 3\) or \(4, 4\)"):
        FixedTransform(torch.eye(5))
    mixed = SceneGraph()
    mixed.add("planet", None, Orbit(2.0))
    mixed.add("arm", "planet", Revolute([0.0, 0.0, 1.0]))
    with pytest.raises(ShapeError, match=r"node 'arm'.*\(2, 3, 3\).*got \(2, 4, 4\)"):
        mixed.world_transforms(torch.zeros(2))
    with pytest.raises(ShapeError, match=r"theta: expected shape \(T\) or \(T, K=2\)"):
        mixed.world_transforms(torch.zeros(2, 3))
