"""Every public ``nn.Module`` of torchgeo_cg survives the torch machinery.

The public modules are enumerated from ``tests/api_inventory.py`` (every public module's
``__all__``), and each needs a factory in :data:`SPECS`: a new module without one fails
:func:`test_every_public_module_has_a_factory`. For each module:

- ``copy.deepcopy`` and ``torch.optim.swa_utils.AveragedModel`` (which deep-copies);
- ``state_dict`` through ``torch.save`` / ``torch.load(weights_only=True)`` into a fresh
  instance, after the parameters moved (as training moves them);
- ``.to(torch.float64)`` moves every floating tensor and gives float64 results;
- ``torch.func.vmap`` over a leading batch (where the op is batched) against a loop, and
  ``torch.func.jacrev`` (where it is differentiable) against
  ``torch.autograd.functional.jacobian``;
- ``torch.compile`` (default backend) against eager (slow: one compile per module);
- DDP with default arguments, gloo, 2 processes on this machine (slow): a loss through
  the module trains, parameters stay identical across ranks and equal single-process
  training on the mean loss.
"""

from __future__ import annotations

import copy
import importlib
import inspect
import io
import json
import math
import os
from collections.abc import Callable
from datetime import timedelta
from typing import NamedTuple

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp
from torch import nn
from torch.nn.parallel import DistributedDataParallel
from torch.optim.swa_utils import AveragedModel

from tests.api_inventory import public_names
from torchgeo_cg.cameras import FisheyeCamera, OpenCVCamera, PinholeCamera
from torchgeo_cg.curves import (
    BezierCurve,
    BSplineCurve,
    HermiteCurve,
    HermiteSpline,
    NURBSCurve,
    PchipInterpolator,
)
from torchgeo_cg.mesh import (
    CatmullClark,
    FaceVaryingSubdivision,
    LoopSubdivision,
    MarchingCubes,
    SubdivisionTags,
    apply_operator,
    catmull_clark,
    loop_subdivide,
)
from torchgeo_cg.mesh.subdivision import SchemeOptions
from torchgeo_cg.points import ChamferDistance
from torchgeo_cg.sdf import (
    Annulus,
    Box,
    Capsule,
    Circle,
    Difference,
    Gyroid,
    Intersection,
    MeshSDF,
    Plane,
    Product,
    Rectangle,
    Rotate,
    Scale,
    SmoothIntersection,
    SmoothUnion,
    Sphere,
    Torus,
    Translate,
    Union,
)
from torchgeo_cg.surfaces import BezierSurface, BSplineSurface, NURBSSurface
from torchgeo_cg.transforms import (
    FixedTransform,
    HomogeneousTransform,
    HomographyModel,
    Orbit,
    Prismatic,
    Revolute,
    SceneGraph,
    TRSTransform,
)


def public_modules() -> dict[str, type]:
    """``qualified name -> class`` of every ``nn.Module`` subclass in the API inventory."""
    found: dict[str, type] = {}
    for name, attr in public_names():
        obj = getattr(importlib.import_module(name), attr)
        if inspect.isclass(obj) and issubclass(obj, nn.Module):
            found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


# ----------------------------------------------------------------------------- factories


class Spec(NamedTuple):
    """How to build one module and feed it.

    ``make()`` builds a float32 module; ``sample(seed)`` gives one float32 input; the
    output is reduced to a tensor by ``tensor_of``. ``batched``: the forward maps a
    leading batch dimension item by item (checked under ``vmap``); ``differentiable``:
    the output is differentiable in the input (checked by ``jacrev``).
    """

    make: Callable[[], nn.Module]
    sample: Callable[[int], torch.Tensor]
    batched: bool = True
    differentiable: bool = True
    tensor_of: Callable[[object], torch.Tensor] = lambda out: out
    call: Callable[[nn.Module, torch.Tensor], object] = lambda module, x: module(x)


def _rand(*shape: int, lo: float = -1.0, hi: float = 1.0) -> Callable[[int], torch.Tensor]:
    def sample(seed: int) -> torch.Tensor:
        g = torch.Generator().manual_seed(seed)
        return lo + (hi - lo) * torch.rand(*shape, generator=g)

    return sample


_CUBE_V = torch.tensor([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
_CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
_OCTA_F = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5],
           [0, 3, 5]]


_CUBE_TAGS = SubdivisionTags(  # a semi-sharp crease, a corner and a hole ride along
    torch.tensor([[0, 1]]), torch.tensor([2.5]), torch.tensor([7]), torch.tensor([1.5]),
    torch.tensor([1]),
)


def _cube_sample(seed: int) -> torch.Tensor:
    return _CUBE_V + 0.1 * _rand(8, 3)(seed)


def _scene_graph() -> SceneGraph:
    scene = SceneGraph()
    scene.add("planet", None, Orbit(radius=3.0, learnable=True))
    scene.add("moon", "planet", Orbit(radius=1.0, speed=2.0, learnable=True))
    return scene


_RIGID = torch.tensor([[0.0, -1.0, 0.0, 0.5], [1.0, 0.0, 0.0, -0.2], [0.0, 0.0, 1.0, 1.0],
                       [0.0, 0.0, 0.0, 1.0]])


def _sphere_volume(seed: int) -> torch.Tensor:
    x = torch.linspace(-1.0, 1.0, 6)
    r2 = (torch.stack(torch.meshgrid(x, x, x, indexing="ij")) ** 2).sum(0)
    return r2 - 0.5 + 0.05 * _rand(6, 6, 6)(seed)


def _rotation_y() -> torch.Tensor:
    c, s = math.cos(0.3), math.sin(0.3)
    return torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


_TETRA_V = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
_TETRA_F = torch.tensor([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
_P3 = _rand(5, 3)
_P2 = _rand(5, 2)
_T = _rand(5, lo=0.0, hi=1.0)

_GRID = torch.stack(torch.meshgrid(torch.linspace(0, 1, 4), torch.linspace(0, 1, 5),
                                   indexing="ij") + (torch.zeros(4, 5),), -1) + 0.1
_UV = _rand(5, 2, lo=0.0, hi=1.0)


def _uv_call(module: nn.Module, x: torch.Tensor) -> torch.Tensor:
    return module(x[..., 0], x[..., 1])


def _ahead(seed: int) -> torch.Tensor:
    """Five points in front of a camera."""
    return _rand(5, 3)(seed) + torch.tensor([0.0, 0.0, 3.0])


_K = torch.tensor([[500.0, 0.0, 320.0], [0.0, 480.0, 240.0], [0.0, 0.0, 1.0]])

SPECS: dict[str, Spec] = {
    "torchgeo_cg.cameras.models.PinholeCamera": Spec(
        lambda: PinholeCamera(_K, _RIGID, image_size=(480, 640)), _ahead
    ),
    "torchgeo_cg.cameras.models.OpenCVCamera": Spec(
        lambda: OpenCVCamera(_K, torch.tensor([-0.2, 0.05, 1e-3, -2e-3, 0.01]), _RIGID), _ahead
    ),
    "torchgeo_cg.cameras.models.FisheyeCamera": Spec(
        lambda: FisheyeCamera(_K, torch.tensor([0.05, -0.02, 0.003, -5e-4])), _ahead
    ),
    "torchgeo_cg.curves.bspline.BSplineCurve": Spec(
        lambda: BSplineCurve(torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0],
                                           [5.0, 1.0]]), 3), _T
    ),
    "torchgeo_cg.curves.nurbs.NURBSCurve": Spec(
        lambda: NURBSCurve(torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
                           torch.tensor([1.0, 0.7071, 1.0]), 2), _T
    ),
    "torchgeo_cg.surfaces.modules.BezierSurface": Spec(lambda: BezierSurface(_GRID), _UV,
                                                       call=_uv_call),
    "torchgeo_cg.surfaces.modules.BSplineSurface": Spec(lambda: BSplineSurface(_GRID, (2, 3)),
                                                        _UV, call=_uv_call),
    "torchgeo_cg.surfaces.modules.NURBSSurface": Spec(
        lambda: NURBSSurface(_GRID, 1.0 + 0.1 * torch.rand(4, 5, generator=torch.Generator(
        ).manual_seed(0)), (2, 3)), _UV, call=_uv_call),
    "torchgeo_cg.curves.bezier.BezierCurve": Spec(
        lambda: BezierCurve(torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]])), _T
    ),
    "torchgeo_cg.curves.hermite.HermiteCurve": Spec(
        lambda: HermiteCurve(torch.tensor([0.0, 0.0]), torch.tensor([1.0, 0.0]),
                             torch.tensor([0.0, 1.0]), torch.tensor([0.0, -1.0])), _T
    ),
    "torchgeo_cg.curves.hermite.HermiteSpline": Spec(
        lambda: HermiteSpline(torch.tensor([0.0, 1.0, 3.0]), torch.tensor([0.0, 1.0, 0.0]),
                              torch.tensor([1.0, 0.0, -1.0]), learnable=True),
        _rand(5, lo=0.1, hi=2.9),
    ),
    "torchgeo_cg.curves.hermite.PchipInterpolator": Spec(
        lambda: PchipInterpolator(torch.tensor([0.0, 1.0, 2.0, 3.0]),
                                  torch.tensor([0.0, 1.0, 4.0, 2.0])),
        _rand(5, lo=0.1, hi=2.9),
    ),
    "torchgeo_cg.mesh.marching_cubes.dense.MarchingCubes": Spec(
        lambda: MarchingCubes(iso=0.0), _sphere_volume, batched=False,
        tensor_of=lambda out: out.verts,
    ),
    "torchgeo_cg.mesh.subdivision.catmark.CatmullClark": Spec(
        lambda: CatmullClark(_CUBE_F, 8, levels=1, tags=_CUBE_TAGS), _cube_sample
    ),
    "torchgeo_cg.mesh.subdivision.face_varying.FaceVaryingSubdivision": Spec(
        lambda: FaceVaryingSubdivision(_CUBE_F, [[4 * f + k for k in range(4)] for f in range(6)],
                                       8, 24, levels=1, tags=_CUBE_TAGS), _rand(24, 2)
    ),
    "torchgeo_cg.sdf.mesh_distance.MeshSDF": Spec(
        lambda: MeshSDF(_TETRA_V, _TETRA_F), _P3, tensor_of=lambda out: out.sdf
    ),
    "torchgeo_cg.points.chamfer.ChamferDistance": Spec(  # two clouds stacked on dim 0
        ChamferDistance, _rand(2, 6, 3), batched=False,  # data-dependent search: no vmap
        call=lambda module, x: module(x[0], x[1]), tensor_of=lambda out: out.loss,
    ),
    "torchgeo_cg.mesh.subdivision.loop.LoopSubdivision": Spec(
        lambda: LoopSubdivision(_OCTA_F, 6, levels=1), _rand(6, 3)
    ),
    "torchgeo_cg.sdf.primitives.Sphere": Spec(lambda: Sphere(0.7, center=[0.1, 0.0, 0.2]), _P3),
    "torchgeo_cg.sdf.primitives.Box": Spec(lambda: Box([0.5, 0.4, 0.3], radius=0.1), _P3),
    "torchgeo_cg.sdf.primitives.Capsule": Spec(
        lambda: Capsule([0.0, 0.0, -0.3], [0.0, 0.2, 0.3], radius=0.2), _P3
    ),
    "torchgeo_cg.sdf.primitives.Plane": Spec(lambda: Plane([0.0, 0.6, 0.8], offset=0.1), _P3),
    "torchgeo_cg.sdf.primitives.Torus": Spec(lambda: Torus(0.6, 0.2), _P3),
    "torchgeo_cg.sdf.primitives.Gyroid": Spec(lambda: Gyroid(2.0, 0.1), _P3),
    "torchgeo_cg.sdf.primitives.Circle": Spec(lambda: Circle(0.6, center=[0.1, 0.0]), _P2),
    "torchgeo_cg.sdf.primitives.Rectangle": Spec(lambda: Rectangle([0.5, 0.3], 0.05), _P2),
    "torchgeo_cg.sdf.primitives.Annulus": Spec(lambda: Annulus(0.6, 0.1), _P2),
    "torchgeo_cg.sdf.operators.Union": Spec(lambda: Union(Sphere(0.5), Box([0.3, 0.6, 0.2])), _P3),
    "torchgeo_cg.sdf.operators.Intersection": Spec(
        lambda: Intersection(Sphere(0.8), Box([0.3, 0.6, 0.2])), _P3
    ),
    "torchgeo_cg.sdf.operators.Difference": Spec(
        lambda: Difference(Sphere(0.8), Box([0.3, 0.6, 0.2])), _P3
    ),
    "torchgeo_cg.sdf.operators.SmoothUnion": Spec(
        lambda: SmoothUnion(Sphere(0.5), Sphere(0.5, [0.6, 0.0, 0.0]), k=0.2), _P3
    ),
    "torchgeo_cg.sdf.operators.SmoothIntersection": Spec(
        lambda: SmoothIntersection(Sphere(0.5), Sphere(0.5, [0.6, 0.0, 0.0]), k=0.2), _P3
    ),
    "torchgeo_cg.sdf.operators.Product": Spec(lambda: Product(Sphere(0.5), Torus(0.6, 0.2)), _P3),
    "torchgeo_cg.sdf.operators.Translate": Spec(
        lambda: Translate(Box([0.3, 0.6, 0.2]), [0.1, 0.2, 0.3]), _P3
    ),
    "torchgeo_cg.sdf.operators.Rotate": Spec(
        lambda: Rotate(Capsule(radius=0.2), _rotation_y()), _P3
    ),
    "torchgeo_cg.sdf.operators.Scale": Spec(lambda: Scale(Torus(0.6, 0.2), 1.5), _P3),
    "torchgeo_cg.transforms.fitting.HomographyModel": Spec(
        lambda: HomographyModel(init=torch.tensor([[1.1, 0.1, 0.2], [0.0, 0.9, -0.1],
                                                   [0.05, 0.02, 1.0]])), _P2
    ),
    "torchgeo_cg.transforms.scene_graph.FixedTransform": Spec(
        lambda: FixedTransform(torch.tensor([[0.0, -1.0, 1.0], [1.0, 0.0, 2.0], [0.0, 0.0, 1.0]])),
        _T, differentiable=False,  # a constant: its Jacobian is zero, checked by value below
    ),
    "torchgeo_cg.transforms.modules.HomogeneousTransform": Spec(
        lambda: HomogeneousTransform(torch.tensor([[1.0, 0.2, 0.3], [-0.1, 0.9, 0.0],
                                                   [0.0, 0.0, 1.0]]), learnable=True), _P2
    ),
    "torchgeo_cg.transforms.scene_graph.Orbit": Spec(
        lambda: Orbit(radius=2.0, speed=1.5, phase=0.2, learnable=True), _T
    ),
    "torchgeo_cg.transforms.scene_graph.SceneGraph": Spec(_scene_graph, _T),
    "torchgeo_cg.transforms.joints.Revolute": Spec(
        lambda: Revolute([0.3, -0.4, 1.0], origin=[0.5, 0.0, 1.0]), _T
    ),
    "torchgeo_cg.transforms.joints.Prismatic": Spec(
        lambda: Prismatic([1.0, 2.0, 0.5], origin=_RIGID), _T
    ),
    "torchgeo_cg.transforms.modules.TRSTransform": Spec(
        lambda: TRSTransform(torch.tensor([0.5, -1.0]), torch.tensor(30.0), torch.tensor(1.5)),
        _P2,
    ),
}

def _params(names: list[str]) -> list:
    return [pytest.param(name, id=name.rsplit(".", 1)[-1]) for name in names]


_ALL = sorted(SPECS)


def _out(spec: Spec, module: nn.Module, x: torch.Tensor) -> torch.Tensor:
    return spec.tensor_of(spec.call(module, x))


def _move_parameters(module: nn.Module, seed: int = 7, scale: float = 0.01) -> None:
    """A small deterministic step on every floating parameter (what training does)."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in module.parameters():
            if p.is_floating_point():
                p.add_(scale * torch.randn(p.shape, generator=g).to(p.dtype))


def _floating_tensors(module: nn.Module) -> list[tuple[str, torch.Tensor]]:
    tensors = list(module.named_parameters()) + list(module.named_buffers())
    return [(n, t) for n, t in tensors if t.is_floating_point()]


# ----------------------------------------------------------------------------- inventory


def test_every_public_module_has_a_factory():
    """A new public module must come with a factory here (and pass the checks)."""
    found = set(public_modules())
    assert found, "no public nn.Module found: the enumeration is broken"
    assert found - set(SPECS) == set(), "public modules without a factory in SPECS"
    assert set(SPECS) - found == set(), "factories for modules that are not public"


# ----------------------------------------------------------------------------- copies


@pytest.mark.parametrize("name", _params(_ALL))
def test_deepcopy(name):
    spec = SPECS[name]
    module = spec.make()
    twin = copy.deepcopy(module)
    x = spec.sample(0)
    torch.testing.assert_close(_out(spec, twin, x), _out(spec, module, x), rtol=0, atol=0)
    for (n, a), (_, b) in zip(_floating_tensors(module), _floating_tensors(twin)):
        assert a.data_ptr() != b.data_ptr() or a.numel() == 0, f"{n} shares memory"
    _move_parameters(twin)  # the copy is independent: moving it leaves the original
    torch.testing.assert_close(_out(spec, module, x), _out(spec, spec.make(), x), rtol=0, atol=0)


@pytest.mark.parametrize("name", _params(_ALL))
def test_state_dict_round_trip_into_fresh_instance(name):
    spec = SPECS[name]
    trained = spec.make()
    _move_parameters(trained)
    buffer = io.BytesIO()
    torch.save(trained.state_dict(), buffer)
    buffer.seek(0)
    state = torch.load(buffer, weights_only=True)
    fresh = spec.make()
    fresh.load_state_dict(state)
    x = spec.sample(1)
    torch.testing.assert_close(_out(spec, fresh, x), _out(spec, trained, x), rtol=0, atol=0)
    if any(True for _ in trained.parameters()):  # the load did something
        moved = dict(trained.named_parameters())
        for n, p in fresh.named_parameters():
            torch.testing.assert_close(p, moved[n], rtol=0, atol=0)


@pytest.mark.parametrize("name", _params(_ALL))
def test_to_float64(name):
    spec = SPECS[name]
    module = spec.make()
    x = spec.sample(2)
    expected = _out(spec, module, x)
    module64 = module.to(torch.float64)
    for n, t in _floating_tensors(module64):
        assert t.dtype == torch.float64, f"{n} stayed {t.dtype}"
    out64 = _out(spec, module64, x.double())
    assert out64.dtype == torch.float64
    torch.testing.assert_close(out64.float(), expected, rtol=1e-5, atol=1e-5)


# Documented departures: the mesh of MeshSDF follows its query points, as in mesh_sdf
# (float64 trimesh vertices with float32 points work, README SDF tour).
FOLLOWS_INPUT = {"torchgeo_cg.sdf.mesh_distance.MeshSDF"}


def _has_floating_state(module: nn.Module) -> bool:
    return bool(_floating_tensors(module))


@pytest.mark.parametrize("name", _params(_ALL))
def test_state_and_input_of_different_dtypes_raise(name):
    """One rule: floating module state and a floating input share one dtype, else a
    ``TypeError`` names both dtypes (as ``nn.Linear``); nothing is cast silently."""
    spec = SPECS[name]
    x = spec.sample(3)
    if name in FOLLOWS_INPUT or not _has_floating_state(spec.make()):  # follows the input
        assert _out(spec, spec.make(), x.double()).dtype == torch.float64
        assert _out(spec, spec.make().double(), x).dtype == torch.float32
        return
    for module_dtype, input_dtype in ((torch.float64, torch.float32),
                                      (torch.float32, torch.float64)):
        module = spec.make().to(module_dtype)
        with pytest.raises(TypeError) as err:
            _out(spec, module, x.to(input_dtype))
        message = str(err.value)
        assert str(module_dtype) in message and str(input_dtype) in message, message
        assert _out(spec, module, x.to(module_dtype)).dtype == module_dtype


@pytest.mark.parametrize("name", _params(_ALL))
def test_swa_averaged_model(name):
    spec = SPECS[name]
    module = spec.make()
    swa = AveragedModel(module)
    x = spec.sample(3)
    torch.testing.assert_close(_out(spec, swa, x), _out(spec, module, x), rtol=0, atol=0)
    before = [p.detach().clone() for p in module.parameters()]
    if not before:  # torch's running average needs at least one parameter
        return
    swa.update_parameters(module)
    _move_parameters(module)
    swa.update_parameters(module)  # the running mean of the two states
    for avg, p0, p1 in zip(swa.module.parameters(), before, module.parameters()):
        torch.testing.assert_close(avg, (p0 + p1.detach()) / 2)


# ----------------------------------------------------------------------------- functorch


@pytest.mark.parametrize("name", _params([n for n in _ALL if SPECS[n].batched]))
def test_vmap_over_a_leading_batch(name):
    spec = SPECS[name]
    module = spec.make()
    xs = torch.stack([spec.sample(seed) for seed in range(3)])
    looped = torch.stack([_out(spec, module, x) for x in xs])
    vmapped = torch.func.vmap(lambda x: _out(spec, module, x))(xs)
    torch.testing.assert_close(vmapped, looped, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("name", _params([n for n in _ALL if SPECS[n].differentiable]))
def test_jacrev_matches_autograd_jacobian(name):
    spec = SPECS[name]
    module = spec.make().double()
    x = spec.sample(4).double()

    def f(x):
        return _out(spec, module, x)

    expected = torch.autograd.functional.jacobian(f, x)
    torch.testing.assert_close(torch.func.jacrev(f)(x), expected, rtol=1e-10, atol=1e-12)
    assert expected.abs().sum() > 0, "the check must see a non-zero Jacobian"


def test_fixed_transform_ignores_its_input():
    """FixedTransform is excluded from jacrev: its output does not depend on theta."""
    spec = SPECS["torchgeo_cg.transforms.scene_graph.FixedTransform"]
    module = spec.make()
    out = module(spec.sample(0))
    torch.testing.assert_close(out, module(spec.sample(1)), rtol=0, atol=0)


# ----------------------------------------------------------------------------- subdivision


@pytest.mark.grad
@pytest.mark.parametrize("builder", ["catmull_clark", "loop"])
def test_subdivision_functions_under_jacrev_and_vmap(builder):
    """The convenience functions (operator built inside) compose with func transforms.

    Reference: the Jacobian of ``S @ V`` w.r.t. ``V`` is ``S`` (x) ``I_D``.
    """
    if builder == "catmull_clark":
        verts, faces, fn = _CUBE_V.double(), _CUBE_F, catmull_clark
    else:
        verts, faces, fn = _rand(6, 3)(0).double(), _OCTA_F, loop_subdivide
    module = (CatmullClark if builder == "catmull_clark" else LoopSubdivision)(
        faces, verts.shape[0], levels=1, dtype=torch.float64
    )
    s = module.operator(0).matrix.to_dense()  # (V1, V0)
    jac = torch.func.jacrev(lambda v: fn(v, faces)[0])(verts)  # (V1, 3, V0, 3)
    expected = torch.einsum("rc,de->rdce", s, torch.eye(3, dtype=torch.float64))
    torch.testing.assert_close(jac, expected, rtol=0, atol=1e-15)
    batch = torch.stack([verts, 2 * verts, verts + 1])
    out = torch.func.vmap(lambda v: fn(v, faces)[0])(batch)
    torch.testing.assert_close(out, torch.einsum("rc,bcd->brd", s, batch))
    jac_op = torch.func.jacrev(lambda v: apply_operator(module.operator(0), v))(verts)
    torch.testing.assert_close(jac_op, expected, rtol=0, atol=1e-15)


@pytest.mark.grad
def test_subdivision_double_backward():
    """The backward is itself differentiable (gradgradcheck), also under vmap."""
    cc = CatmullClark([[0, 1, 2, 3], [1, 4, 5, 2]], 6, levels=2, dtype=torch.float64)
    verts = _rand(6, 2)(5).double().requires_grad_(True)
    assert torch.autograd.gradcheck(cc, (verts,))
    assert torch.autograd.gradgradcheck(cc, (verts,))
    cotangents = torch.randn(4, cc.num_vertices_out, 2, dtype=torch.float64)
    _, vjp_fn = torch.func.vjp(cc, verts.detach())
    (grads,) = torch.func.vmap(vjp_fn)(cotangents)
    s = torch.eye(6, dtype=torch.float64)
    s = cc(s.unsqueeze(-1)).squeeze(-1).T  # (V2, V0): the composed stencils, column by column
    torch.testing.assert_close(grads, torch.einsum("rc,brd->bcd", s, cotangents))


def test_catmull_clark_compiles_fullgraph():
    """fullgraph compiles without "Attempted to wrap sparse Tensor" (the eager backend
    keeps this fast; the default backend runs in the slow compile test)."""
    cc = CatmullClark(_CUBE_F, 8, levels=2, tags=_CUBE_TAGS)
    loop = LoopSubdivision(_OCTA_F, 6, levels=2, options=SchemeOptions(boundary="none"))
    for module, x in ((cc, _cube_sample(0)), (loop, _rand(2, 6, 3)(0))):
        compiled = torch.compile(module, fullgraph=True, backend="aot_eager")
        torch.testing.assert_close(compiled(x), module(x), rtol=0, atol=0)
        xg = x.clone().requires_grad_(True)
        compiled(xg).square().sum().backward()
        xe = x.clone().requires_grad_(True)
        module(xe).square().sum().backward()
        torch.testing.assert_close(xg.grad, xe.grad)


# ----------------------------------------------------------------------------- compile


@pytest.mark.slow
@pytest.mark.parametrize("name", _params(_ALL))
def test_torch_compile_matches_eager(name):
    spec = SPECS[name]
    module = spec.make()
    x = spec.sample(6)
    fullgraph = name.endswith(("CatmullClark", "LoopSubdivision"))
    torch._dynamo.reset()
    compiled = torch.compile(module, fullgraph=fullgraph)
    torch.testing.assert_close(_out(spec, compiled, x), _out(spec, module, x),
                               rtol=1e-5, atol=1e-6)


# ----------------------------------------------------------------------------- DDP


class _Trainable(nn.Module):
    """The module plus its input as a parameter, so every module has something to train."""

    def __init__(self, spec: Spec, module: nn.Module, x: torch.Tensor) -> None:
        super().__init__()
        self.spec, self.module = spec, module
        self.x = nn.Parameter(x.clone(), requires_grad=spec.differentiable)
        self.scale = nn.Parameter(torch.ones(()))  # trains even when x cannot

    def forward(self) -> torch.Tensor:
        out = _out(self.spec, self.module, self.x)
        return (self.scale * out).square().mean()


def _train(model: nn.Module, rank_weight: float, steps: int = 2) -> None:
    opt = torch.optim.SGD([p for p in model.parameters() if p.requires_grad], lr=0.1)
    for _ in range(steps):
        opt.zero_grad()
        (rank_weight * model()).backward()
        opt.step()


def _flat(model: nn.Module) -> torch.Tensor:
    return torch.cat([p.detach().reshape(-1) for p in model.parameters()])


def _ddp_one(name: str, rank: int) -> str:
    spec = SPECS[name]
    torch.manual_seed(0)
    local = _Trainable(spec, spec.make(), spec.sample(8))
    reference = copy.deepcopy(local)
    start = _flat(local)
    ddp = DistributedDataParallel(local)
    _train(ddp, rank_weight=float(rank + 1))
    _train(reference, rank_weight=1.5)  # the mean of the two ranks' weights
    mine = _flat(local)
    gathered = [torch.empty_like(mine) for _ in range(2)]
    dist.all_gather(gathered, mine)
    if not torch.equal(gathered[0], gathered[1]):
        return "parameters differ across ranks"
    if torch.equal(mine, start):
        return "nothing trained"
    if not torch.allclose(mine, _flat(reference), rtol=1e-4, atol=1e-6):
        return "DDP training differs from single-process training on the mean loss"
    return "ok"


def _ddp_worker(rank: int, store_path: str, out_dir: str) -> None:
    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"file://{store_path}", rank=rank,
                            world_size=2, timeout=timedelta(seconds=120))
    results = {}
    try:
        for name in _ALL:
            try:
                results[name] = _ddp_one(name, rank)
            except Exception as error:  # recorded per module, reported by the test
                results[name] = f"{type(error).__name__}: {str(error).splitlines()[0][:300]}"
            dist.barrier()
    finally:
        dist.destroy_process_group()
    with open(os.path.join(out_dir, f"rank{rank}.json"), "w") as f:
        json.dump(results, f)


@pytest.fixture(scope="module")
def ddp_results(tmp_path_factory) -> list[dict[str, str]]:
    """One 2-process gloo run over every module (one spawn for the whole suite)."""
    tmp = tmp_path_factory.mktemp("ddp")
    mp.start_processes(_ddp_worker, args=(str(tmp / "store"), str(tmp)), nprocs=2,
                       join=True, start_method="spawn")
    return [json.loads((tmp / f"rank{r}.json").read_text()) for r in range(2)]


@pytest.mark.slow
@pytest.mark.parametrize("name", _params(_ALL))
def test_ddp_two_processes_gloo(name, ddp_results):
    assert [r[name] for r in ddp_results] == ["ok", "ok"]


# ----------------------------------------------------------------------------- mesh_sdf

def _tetrahedron() -> tuple[torch.Tensor, torch.Tensor]:
    verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=torch.float64)
    faces = torch.tensor([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return verts, faces


def test_mesh_sdf_under_vmap():
    from torchgeo_cg.sdf import mesh_sdf

    verts, faces = _tetrahedron()
    points = _rand(3, 5, 3)(0).double()
    looped = torch.stack([mesh_sdf(verts, faces, p).sdf for p in points])
    vmapped = torch.func.vmap(lambda p: mesh_sdf(verts, faces, p).sdf)(points)
    torch.testing.assert_close(vmapped, looped)


@pytest.mark.parametrize("wrt", ["points", "vertices"])
def test_mesh_sdf_under_jacrev(wrt):
    from torchgeo_cg.sdf import mesh_sdf

    verts, faces = _tetrahedron()
    points = _rand(5, 3)(1).double()
    if wrt == "points":
        f, x = (lambda p: mesh_sdf(verts, faces, p).sdf), points
    else:
        f, x = (lambda v: mesh_sdf(v, faces, points).sdf), verts
    expected = torch.autograd.functional.jacobian(f, x)
    torch.testing.assert_close(torch.func.jacrev(f)(x), expected)
