"""Articulated motion: orbit radii and periods measured numerically, hand-built references."""

import math

import numpy as np
import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.transforms import (
    FixedTransform,
    Orbit,
    SceneGraph,
    compose,
    rotation,
    solar_system,
    translation,
)

F64 = torch.float64


def _revolutions(relative_xy: torch.Tensor) -> float:
    """Signed number of turns made by a (T, 2) trajectory around the origin."""
    angle = np.unwrap(np.arctan2(relative_xy[:, 1].numpy(), relative_xy[:, 0].numpy()))
    return (angle[-1] - angle[0]) / (2 * np.pi)


@pytest.mark.parametrize("spin", [False, True])
def test_solar_system_radii_and_periods(spin):
    theta = torch.linspace(0, 2 * math.pi, 721, dtype=F64)
    world = solar_system(spin=spin).to(F64).world_transforms(theta)
    pos = {n: world.get(n)[:, :2, 2] for n in world.names}
    assert torch.allclose(pos["planet"], torch.zeros_like(pos["planet"]))
    radii = {
        "moon1": (pos["moon1"] - pos["planet"]).norm(dim=-1),
        "moon2": (pos["moon2"] - pos["planet"]).norm(dim=-1),
        "moon3": (pos["moon3"] - pos["moon2"]).norm(dim=-1),
    }
    for name, expected in (("moon1", 2.0), ("moon2", 3.0), ("moon3", 1.0)):
        torch.testing.assert_close(radii[name], torch.full_like(radii[name], expected))
    # revolutions per cycle: moon 2 twice as fast as moon 1; moon 3 round moon 2 by the
    # report's T_moon3 = T_moon2(θ)·R(θ)·T([1, 0]): once in moon 2's turning frame, three
    # times in fixed axes, so it does not move in lockstep with moon 2
    assert _revolutions(pos["moon1"]) == pytest.approx(1.0, abs=1e-9)
    assert _revolutions(pos["moon2"]) == pytest.approx(2.0, abs=1e-9)
    assert _revolutions(pos["moon3"] - pos["moon2"]) == pytest.approx(3.0, abs=1e-9)
    # seen along the planet-moon 2 line, moon 3 turns once per cycle (lockstep would be 0)
    along = torch.atan2(pos["moon2"][:, 1], pos["moon2"][:, 0])
    rel = pos["moon3"] - pos["moon2"]
    c, s = along.cos(), along.sin()
    in_moon2_frame = torch.stack([c * rel[:, 0] + s * rel[:, 1], c * rel[:, 1] - s * rel[:, 0]], -1)
    assert _revolutions(in_moon2_frame) == pytest.approx(1.0, abs=1e-9)
    # periods: moon 2 returns after half a cycle but not after a quarter
    half = world.get("moon2")[360, :2, 2]
    assert torch.allclose(half, pos["moon2"][0], atol=1e-12)
    assert not torch.allclose(world.get("moon2")[180, :2, 2], pos["moon2"][0], atol=1e-3)


@pytest.mark.parametrize("spin", [False, True])
def test_solar_system_is_the_reports_formula(spin):
    """Report 2.3 as written: T_moon2(θ) = R(2θ)·T([3, 0]), T_moon3 = T_moon2(θ)·R(θ)·T([1, 0])."""
    theta = torch.linspace(0, 2 * math.pi, 37, dtype=F64)
    world = solar_system(spin=spin).to(F64).world_transforms(theta)
    moon2 = compose(rotation(2 * theta, degrees=False),
                    translation(torch.tensor([3.0, 0.0], dtype=F64)))
    moon3 = compose(moon2, rotation(theta, degrees=False),
                    translation(torch.tensor([1.0, 0.0], dtype=F64)))
    torch.testing.assert_close(world.get("moon3")[:, :2, 2], moon3[:, :2, 2])
    if spin:  # the rotating frames themselves, not only the positions
        torch.testing.assert_close(world.get("moon3"), moon3)


def test_spin_true_reproduces_report_rotating_frames():
    """Report 2.3: T_moon2 = R(2θ)·T(3, 0) and T_moon3 = T_moon2·R(kθ)·T(1, 0), built by hand."""
    theta = torch.linspace(0, 2 * math.pi, 50, dtype=F64)
    scene = SceneGraph().to(F64)
    scene.add("planet")
    scene.add("moon2", "planet", Orbit(3.0, speed=2.0, spin=True))
    scene.add("moon3", "moon2", Orbit(1.0, speed=1.0, spin=True))
    world = scene.to(F64).world_transforms(theta)
    t3 = translation(torch.tensor([3.0, 0.0], dtype=F64))
    t1 = translation(torch.tensor([1.0, 0.0], dtype=F64))
    moon2 = compose(rotation(2 * theta, degrees=False), t3)
    moon3 = compose(moon2, rotation(theta, degrees=False), t1)
    torch.testing.assert_close(world.get("moon2"), moon2)
    torch.testing.assert_close(world.get("moon3"), moon3)


def test_world_transforms_against_explicit_chain_of_matmuls():
    theta = torch.rand(9, dtype=F64) * 6
    scene = SceneGraph()
    scene.add("a", None, translation(torch.tensor([1.0, 2.0])))
    scene.add("b", "a", Orbit(1.5, speed=-3.0, phase=0.4, spin=True))
    scene.add("c", "b", lambda t: rotation(t * 10))
    scene.add("d", "a", Orbit(0.5, speed=5.0))
    scene.add("e", "c")
    scene = scene.to(F64)
    world = scene.world_transforms(theta)
    local = {n: scene.locals[n](theta) for n in scene.names}
    ref = {"a": local["a"]}
    for n in ("b", "c", "d", "e"):
        ref[n] = ref[scene.parent(n)] @ local[n]
    for n in scene.names:
        torch.testing.assert_close(world.get(n), ref[n])
    assert world.matrices.shape == (5, 9, 3, 3)
    torch.testing.assert_close(scene(theta), world.matrices)
    assert world.positions().shape == (5, 9, 2)


def test_learnable_orbit_gradients_and_gradcheck():
    orbit = Orbit(2.0, speed=1.0, learnable=True).to(F64)
    assert {n for n, _ in orbit.named_parameters()} == {"radius", "speed", "phase"}
    theta = torch.linspace(0, 3, 7, dtype=F64)

    def f(radius, speed):
        scene = SceneGraph()
        scene.add("p")
        scene.add("m", "p", lambda t: translation(radius * torch.stack([t.cos(), t.sin()], -1)))
        scene.add("n", "m", lambda t: rotation(speed * t, degrees=False))
        return scene.world_transforms(theta).matrices

    r = torch.tensor(2.0, dtype=F64, requires_grad=True)
    s = torch.tensor(0.7, dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(f, (r, s))
    scene = SceneGraph()
    scene.add("p")
    scene.add("m", "p", orbit)
    scene.world_transforms(theta).positions().sum().backward()
    assert orbit.radius.grad is not None and torch.isfinite(orbit.radius.grad)


def test_dtype_and_device_follow_inputs(dtype, device):
    scene = solar_system().to(device=device, dtype=dtype)
    theta = torch.linspace(0, 1, 4, dtype=dtype, device=device)
    out = scene.world_transforms(theta).matrices
    assert out.dtype == dtype and out.device.type == device.type


def test_errors():
    scene = SceneGraph()
    with pytest.raises(ValueError, match="no nodes"):
        scene.world_transforms(torch.zeros(3))
    scene.add("planet")
    with pytest.raises(ValueError, match="'planet' already exists"):
        scene.add("planet")
    with pytest.raises(ValueError, match="parent 'sun' of 'moon' is not a node"):
        scene.add("moon", "sun")
    with pytest.raises(TypeError, match="local_transform must be"):
        scene.add("moon", "planet", 3.0)
    with pytest.raises(ShapeError, match=r"theta: expected shape \(T\) or \(T, K=1\).* \(2, 3\)"):
        scene.world_transforms(torch.zeros(2, 3))
    with pytest.raises(TypeError, match="theta: expected a floating"):
        scene.world_transforms(torch.zeros(3, dtype=torch.long))
    with pytest.raises(ShapeError, match=r"matrix: expected shape \(3, 3\)"):
        FixedTransform(torch.eye(2))
    with pytest.raises(ShapeError, match=r"radius: expected shape \(\), got \(2\)"):
        Orbit(torch.ones(2))
    with pytest.raises(KeyError, match="no node named 'x'"):
        solar_system().world_transforms(torch.zeros(1)).get("x")


def _orbit_reference(theta, radius, speed, phase, spin):
    """``R(a)·T(r, 0)`` (spin) or ``T(r cos a, r sin a)``, written out by hand in float64."""
    a = (speed * theta.double() + phase).numpy()
    m = np.zeros((a.size, 3, 3))
    m[:, 2, 2] = 1.0
    if spin:
        m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1] = np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
    else:
        m[:, 0, 0] = m[:, 1, 1] = 1.0
    m[:, 0, 2], m[:, 1, 2] = radius * np.cos(a), radius * np.sin(a)
    return torch.from_numpy(m)


@pytest.mark.parametrize("spin", [False, True])
def test_orbit_state_and_theta_of_different_dtypes_raise(spin):
    """float64 parameters with float32 theta raise a TypeError naming both dtypes (the
    module rule); converting the module gives the result in theta's dtype."""
    theta = torch.tensor([0.0, 0.4, 2.5], dtype=torch.float32)
    orbit = Orbit(torch.tensor(1.5, dtype=F64), torch.tensor(2.0, dtype=F64), 0.3, spin=spin)
    with pytest.raises(TypeError, match="float32.*float64"):
        orbit(theta)
    out = orbit.float()(theta)
    assert out.dtype == torch.float32
    torch.testing.assert_close(out.double(), _orbit_reference(theta, 1.5, 2.0, 0.3, spin),
                               rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16])
@pytest.mark.parametrize("spin", [False, True])
def test_low_precision_is_computed_in_float32(low, spin):
    """float16/bfloat16 theta is computed in float32 and cast back (solar_system(spin=True)
    included), not a raw 'expected scalar type Half' error."""
    theta = torch.tensor([0.0, 0.7, 5.9]).to(low)
    out = solar_system(spin=spin).world_transforms(theta).matrices
    assert out.dtype == low
    ref = solar_system(spin=spin).to(F64).world_transforms(theta.double()).matrices
    eps = torch.finfo(low).eps  # one rounding of the cast back
    torch.testing.assert_close(out.double(), ref.to(low).double(), rtol=eps, atol=eps)


def test_integer_theta_is_rejected():
    """Orbit and FixedTransform reject an integer theta (FixedTransform would truncate its
    matrix to integers)."""
    matrix = translation(torch.tensor([0.5, 1.5]))
    with pytest.raises(TypeError, match="theta: expected a floating"):
        FixedTransform(matrix)(torch.zeros(2, dtype=torch.long))
    with pytest.raises(TypeError, match="theta: expected a floating"):
        Orbit(1.0)(torch.zeros(2, dtype=torch.long))
