"""Contract entries of transforms in 3D: rotations, 3D estimation, joints and robust losses.

``ENTRIES`` join ``table.TABLE``;
``EXEMPT`` names have no geometry (result types). Rotations are scale-free
(law ``"unitless"``); translations and points scale by ``s``.
"""

from __future__ import annotations

import torch

import torchgeo_cg.transforms as T
import torchgeo_cg.transforms.rotations as R
from tests.contract.spec import GENERATORS, Arg, Entry

F64 = torch.float64


def _seeded(g: torch.Generator, offset: int) -> torch.Generator:
    return torch.Generator().manual_seed(g.initial_seed() * 11 + offset)


def _src3(shape, g, dtype):
    """Well-spread 3D source points, the same for every argument of one seed."""
    return 2 * torch.randn(shape, generator=_seeded(g, 0), dtype=F64)


def _dst3(scale: bool):
    """dst = s R src + t + noise for the seed of :func:`_src3`."""
    def gen(shape, g, dtype):
        src, sub = _src3(shape, g, dtype), _seeded(g, 1)
        rot = GENERATORS["rotation"]((*shape[:-2], 3, 3), sub, F64)
        s = (0.5 + torch.rand(*shape[:-2], 1, 1, generator=sub, dtype=F64)) if scale else 1.0
        t = 3 * torch.randn(*shape[:-2], 1, 3, generator=sub, dtype=F64)
        return s * src @ rot.mT + t + 1e-2 * torch.randn(shape, generator=sub, dtype=F64)
    return gen


def _quat(shape, g, dtype):
    return torch.nn.functional.normalize(torch.randn(shape, generator=g, dtype=F64), dim=-1)


def _rotvec(shape, g, dtype):
    return 0.9 * torch.randn(shape, generator=g, dtype=F64)


def _se3_log(rot, t):
    m = torch.eye(4, dtype=rot.dtype, device=rot.device).repeat(*rot.shape[:-2], 1, 1)
    m[..., :3, :3], m[..., :3, 3] = rot, t
    out = R.se3_log(m)
    return out[..., :3], out[..., 3:]


N3 = 9
SRC3 = Arg("src", (2, N3, 3), _src3)
ROT = Arg("matrix", (4, 3, 3), "rotation", "unitless")
QUAT = Arg("quaternion", (4, 4), _quat, "unitless")
RV = Arg("omega", (4, 3), _rotvec, "unitless")
FIT3 = ("matrix", "index", "unitless")

__all__ = ["ENTRIES", "EXEMPT"]

SQ = Arg("squared_residuals", (3, 7), "positive", "area")
SCALE = Arg("scale", (3, 1), "positive", "length")

def _closed_3d(name: str, scale: bool) -> list[Entry]:
    fn = getattr(T, name)
    return [
        Entry(f"transforms.{name}[3d]", lambda s, d: tuple(fn(s, d)),
              (SRC3, Arg("dst", (2, N3, 3), _dst3(scale))), out=FIT3,
              empty=((0, 0), (1, 0)), bad=((2, N3, 4), (2,))),
        Entry(f"transforms.{name}[3d,weights]", lambda w, s, d: tuple(fn(s, d, w)),
              (Arg("weights", (2, N3), "positive", "unitless"), SRC3,
               Arg("dst", (2, N3, 3), _dst3(scale))), out=FIT3,
              empty=((0, 0), (1, 0), (2, 0)), bad=((2, N3 + 1), (2, N3, 3))),
    ]


def _revolute(q, axis, origin):
    return T.Revolute(axis, origin)(q)


def _prismatic(q, axis, origin):
    return T.Prismatic(axis, origin)(q)


def _arm(q, o1, o2):
    """Forward kinematics of a three-joint chain, joint values ``q (T, 3)``."""
    z, y = o1.new_tensor([0.0, 0.0, 1.0]), o1.new_tensor([0.0, 1.0, 0.0])
    scene = T.SceneGraph()
    scene.add("base", None, T.Revolute(z))
    scene.add("upper", "base", T.Revolute(y, o1))
    scene.add("fore", "upper", T.Revolute(y, o2))
    world = scene.world_transforms(q)
    return world.matrices, world.positions()


def _slider(q, o1):
    """A prismatic chain: every joint value is a length."""
    x, z = o1.new_tensor([1.0, 0.0, 0.0]), o1.new_tensor([0.0, 0.0, 1.0])
    scene = T.SceneGraph()
    scene.add("rail", None, T.Prismatic(x))
    scene.add("lift", "rail", T.Prismatic(z, o1))
    world = scene.world_transforms(q)
    return world.matrices, world.positions()


def _typical(points):
    """A robust scale that scales with the points: their mean |coordinate| (1 if none)."""
    size = points.detach().nan_to_num(0.0).abs().double()
    return float(size.mean()) if size.numel() and bool(size.mean() > 0) else 1.0


def _outliers(gen):
    """``gen``'s correspondences with the first 6 replaced by gross outliers."""
    def out(shape, g, dtype):
        dst = gen(shape, g, dtype)
        dst[..., :6, :] = 10 * torch.randn(*shape[:-2], 6, 3, generator=_seeded(g, 2),
                                           dtype=F64)
        return dst
    return out


def _ransac3(model: str):
    def call(src, dst):
        top = float(dst.detach().nan_to_num(0.0).abs().amax()) if dst.numel() else 1.0
        return tuple(T.find_transform_ransac(src, dst, model, threshold=0.02 * top,
                                             generator=torch.Generator().manual_seed(0),
                                             hypotheses_per_round=16))
    return call


JOINT = Arg("q", (5,), "normal", "unitless")
AXIS = Arg("axis", (3,), "unit_vector", "unitless")
ORIGIN = Arg("origin", (3,))

#: The joints' errors name their own arguments (origin), not the entries' o1, o2; the
#: Revolute and Prismatic entries cover the joints' batches.
JOINT_ERRORS = "the joints' errors name their own arguments (origin), not o1, o2"

ENTRIES: list[Entry] = [
    # --- joints: angles scale-free, offsets and slides x s
    Entry("transforms.Revolute", _revolute, (JOINT, AXIS, ORIGIN), out="matrix",
          empty=(0, 0), bad=((2,), (3, 3)), bad_arg=1),
    Entry("transforms.Revolute[matrix]", _revolute,
          (JOINT, AXIS, Arg("origin", (4, 4), lambda shape, g, dt: T.compose(
              T.translation(torch.randn(3, generator=g, dtype=F64)),
              torch.block_diag(GENERATORS["rotation"]((3, 3), g, F64), torch.ones(1, 1,
                                                                                dtype=F64))),
              "matrix")),
          out="matrix", empty=(0, 0), bad=((4, 3), (4,)), bad_arg=2),
    Entry("transforms.Prismatic", _prismatic, (Arg("q", (5,)), AXIS, ORIGIN), out="matrix",
          empty=(0, 0), bad=((2,), (3, 3)), bad_arg=1),
    # the nodes' dtype mismatch raises in the joints (Revolute, Prismatic entries)
    Entry("transforms.SceneGraph[3d,joints]", _arm,
          (Arg("theta", (5, 3), "normal", "unitless"), Arg("o1", (3,)), Arg("o2", (3,))),
          out=("matrix", "length"), empty=(0, 0), mixed=None, bad=((5, 2), (5, 3, 1)),
          cross=JOINT_ERRORS),
    Entry("transforms.SceneGraph[3d,prismatic]", _slider, (Arg("theta", (5, 2)), Arg("o1", (3,))),
          out=("matrix", "length"), empty=(0, 0), mixed=None, bad=((5, 3), (5, 2, 1)),
          cross=JOINT_ERRORS),
    *_closed_3d("find_euclidean", False),
    *_closed_3d("find_similarity", True),
    *_closed_3d("find_affine", True),
    *_closed_3d("find_translation", False),
    Entry("transforms.find_euclidean[3d,reflection]",
          lambda s, d: tuple(T.find_euclidean(s, d, allow_reflection=True)),
          (SRC3, Arg("dst", (2, N3, 3), _dst3(False))), out=FIT3, empty=((0, 0), (1, 0)),
          bad=((2, N3, 4), (2,))),
    # --- iterative 3D fits (LM on se(3)): matrix, params, loss, history
    *[Entry(f"transforms.fit_transform[3d,{model},{loss}]",
            lambda s, d, model=model, loss=loss: tuple(T.fit_transform(
                s, d, model, solver=T.SolverOptions(steps=4, tol=0.0),
                loss=T.LossOptions(loss, scale=_typical(s)))),
            (SRC3, Arg("dst", (2, N3, 3), _dst3(model == "similarity"))),
            out=("matrix", "unitless", "area", "area"), empty=((0, 0), (1, 0)),
            bad=((2, N3, 4), (2,)))
      for model, loss in (("euclidean", "l2"), ("similarity", "cauchy"),
                          ("euclidean", "tukey"))],
    Entry("transforms.fit_transform[3d,weights]",
          lambda w, s, d: tuple(T.fit_transform(s, d, "similarity", weights=w,
                                                solver=T.SolverOptions(steps=4, tol=0.0))),
          (Arg("weights", (2, N3), "positive", "unitless"), SRC3,
           Arg("dst", (2, N3, 3), _dst3(True))), out=("matrix", "unitless", "area", "area"),
          empty=((0, 0), (1, 0), (2, 0)), bad=((2, N3 + 1), (2, N3, 3))),
    # --- RANSAC in 3D: the threshold is a fraction of the data's extent (scales with it)
    *[Entry(f"transforms.find_transform_ransac[3d,{model}]", _ransac3(model),
            (Arg("src", (2, 24, 3), _src3),
             Arg("dst", (2, 24, 3), _outliers(_dst3(model == "similarity")))),
            out=("matrix", "index", "index", "index"), empty=((0, 0), (1, 0)), nan="skip",
            bad=((2, 24, 4), (2,)))
      for model in ("euclidean", "similarity", "affine")],
    # --- homogeneous 3D
    Entry("transforms.translation[3d]", T.translation, (Arg("offset", (4, 3)),), out="matrix",
          empty=(0, 0), bad=((4, 4), ())),
    Entry("transforms.transform_points[3d]", lambda p, m: T.transform_points(m, p),
          (Arg("points", (4, 6, 3)), Arg("matrix", (4, 4, 4), "normal", "matrix")),
          bad=((4, 6, 2), (3,))),
    Entry("transforms.inverse[3d]", T.inverse, (Arg("matrix", (4, 4, 4), "normal", "matrix"),),
          out="matrix", empty=(0, 0), bad=((4, 4, 3), (4,))),
    Entry("transforms.compose[3d]", T.compose,
          (Arg("matrices[0]", (4, 4, 4), "normal", "matrix"),
           Arg("matrices[1]", (4, 4, 4), "normal", "matrix")),
          out="matrix", empty=((0, 0), (1, 0)), bad=((4, 4, 3), (4,))),
    # --- rotations: scale-free
    Entry("transforms.so3_exp", R.so3_exp, (RV,), out="unitless", empty=(0, 0),
          bad=((4, 4), ())),
    Entry("transforms.axis_angle_to_matrix", R.axis_angle_to_matrix,
          (Arg("axis_angle", (4, 3), _rotvec, "unitless"),), out="unitless", empty=(0, 0),
          bad=((4, 4), ())),
    Entry("transforms.axis_angle_to_quaternion", R.axis_angle_to_quaternion,
          (Arg("axis_angle", (4, 3), _rotvec, "unitless"),), out="unitless", empty=(0, 0),
          bad=((4, 4), ())),
    Entry("transforms.so3_log", R.so3_log, (ROT,), out="unitless", empty=(0, 0),
          bad=((4, 3, 4), (3,))),
    Entry("transforms.matrix_to_axis_angle", R.matrix_to_axis_angle, (ROT,),
          out="unitless", empty=(0, 0), bad=((4, 3, 4), (3,))),
    Entry("transforms.matrix_to_quaternion", R.matrix_to_quaternion, (ROT,),
          out="unitless", empty=(0, 0), bad=((4, 3, 4), (3,))),
    Entry("transforms.quaternion_to_matrix", R.quaternion_to_matrix, (QUAT,),
          out="unitless", empty=(0, 0), bad=((4, 3), ())),
    Entry("transforms.quaternion_to_axis_angle", R.quaternion_to_axis_angle, (QUAT,),
          out="unitless", empty=(0, 0), bad=((4, 3), ())),
    Entry("transforms.matrix_to_rotation_6d", R.matrix_to_rotation_6d, (ROT,),
          out="unitless", empty=(0, 0), bad=((4, 3, 4), (3,))),
    Entry("transforms.rotation_6d_to_matrix", R.rotation_6d_to_matrix,
          (Arg("d6", (4, 6), "normal", "length"),), out="unitless", empty=(0, 0),
          bad=((4, 5), ())),
    Entry("transforms.quaternion_multiply", R.quaternion_multiply,
          (Arg("a", (4, 4), _quat, "unitless"), Arg("b", (4, 4), _quat, "unitless")),
          out="unitless", empty=((0, 0), (1, 0)), bad=((4, 3), ())),
    Entry("transforms.quaternion_conjugate", R.quaternion_conjugate, (QUAT,),
          out="unitless", empty=(0, 0), bad=((4, 3), ())),
    Entry("transforms.quaternion_apply", lambda p, q: R.quaternion_apply(q, p),
          (Arg("points", (4, 3)), QUAT), empty=((0, 0), (1, 0)), bad=((4, 2), ())),
    Entry("transforms.quaternion_slerp", R.quaternion_slerp,
          (Arg("q0", (4, 4), _quat, "unitless"), Arg("q1", (4, 4), _quat, "unitless"),
           Arg("t", (4,), "t01", "unitless")),
          out="unitless", empty=((0, 0), (1, 0), (2, 0)), bad=((4, 3), ())),
    Entry("transforms.rotation_angle", R.rotation_angle,
          (Arg("r1", (4, 3, 3), "rotation", "unitless"),
           Arg("r2", (4, 3, 3), "rotation", "unitless")),
          out="unitless", empty=((0, 0), (1, 0)), bad=((4, 3, 4), (3,))),
    Entry("transforms.rotation_mean", R.rotation_mean,
          (Arg("rotations", (2, 5, 3, 3), "rotation", "unitless"),
           Arg("weights", (2, 5), "positive", "unitless")),
          out="unitless", empty=((0, 0), (1, 0)), bad=((2, 5, 3, 4), (3, 3)),
          mixed=("follow", 0)),  # weights follow the rotations, as in the find_* functions
    Entry("transforms.so3_hat", R.so3_hat, (Arg("omega", (4, 3)),), empty=(0, 0),
          bad=((4, 4), ())),
    Entry("transforms.so3_left_jacobian", R.so3_left_jacobian, (RV,),
          out="unitless", empty=(0, 0), bad=((4, 4), ())),
    Entry("transforms.so3_left_jacobian_inverse", R.so3_left_jacobian_inverse, (RV,),
          out="unitless", empty=(0, 0), bad=((4, 4), ())),
    Entry("transforms.se3_exp",
          lambda v, w: (lambda m: (m[..., :3, :3], m[..., :3, 3]))(
              R.se3_exp(torch.cat([v, w.to(v.dtype)], -1))),
          (Arg("xi", (4, 3)), Arg("omega", (4, 3), _rotvec, "unitless")),
          out=("unitless", "length"), empty=None, bad=(), mixed=None,
          cross="the call concatenates xi and omega into the one argument of se3_exp"),
    Entry("transforms.se3_log", _se3_log,
          (Arg("matrix", (4, 3, 3), "rotation", "unitless"), Arg("t", (4, 3))),
          out=("length", "unitless"), empty=None, bad=(), mixed=None,
          cross="the call assembles the one (4, 4) argument of se3_log from matrix and t"),
    *[Entry(f"transforms.euler_to_matrix[{seq}]",
            lambda a, seq=seq: R.euler_to_matrix(a, seq),
            (Arg("angles", (4, 3), "angle", "unitless"),), out="unitless", empty=(0, 0),
            bad=((4, 4), ()))
      for seq in ("xyz", "ZXZ")],
    *[Entry(f"transforms.matrix_to_euler[{seq}]",
            lambda m, seq=seq: R.matrix_to_euler(m, seq), (ROT,), out="unitless", empty=(0, 0),
            bad=((4, 3, 4), (3,)))
      for seq in ("xyz", "ZXZ")],
    # --- robust losses: residuals and scale both x s
    *[Entry(f"transforms.robust_weights[{loss}]",
            lambda sq, c, loss=loss: T.robust_weights(sq, loss, c), (SQ, SCALE),
            out="unitless", empty=(0, -1), mixed="promote", bad=())
      for loss in ("huber", "cauchy", "tukey")],
    *[Entry(f"transforms.robust_loss[{loss}]",
            lambda sq, c, loss=loss: T.robust_loss(sq, loss, c), (SQ, SCALE),
            out="area", empty=(0, -1), mixed="promote", bad=())
      for loss in ("huber", "cauchy", "tukey")],
]

EXEMPT: dict[str, str] = {
    "transforms.TransformFit": "NamedTuple result of the closed-form estimators",
    "transforms.random_rotations": "factory of random rotations (n, generator), no tensor "
    "input; tests/transforms/test_rotations.py",
}
