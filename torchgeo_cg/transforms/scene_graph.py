"""Articulated motion: a kinematic tree of 2D or 3D homogeneous transforms (report section 2.3).

Convention:
    - Column vectors: a node's world matrix is ``world_from_node = world_from_parent @
      parent_from_node``, so a point ``p`` in the node's frame is at
      ``transform_points(world_from_node, p)`` in the world.
    - Nodes are ``(3, 3)`` (2D) or ``(4, 4)`` (3D) matrices, one size per graph.
    - Time ``theta`` is a batch of phases in **radians**, ``(T,)``; one animation
      cycle is ``theta`` in ``[0, 2π)``. A body with ``speed = k`` completes ``k``
      revolutions per cycle (period ``2π / k``).
    - Positive speeds orbit counter-clockwise (y up).
    - Joint values: ``theta`` may instead be ``(T, K)``, one column per node in
      insertion order, so each joint of a chain
      (:class:`~torchgeo_cg.transforms.Revolute`,
      :class:`~torchgeo_cg.transforms.Prismatic`) gets its own value: the forward
      kinematics of ``T`` configurations. Nodes without a joint ignore their column
      (a NaN there still gives NaN).

Each node's local transform is an ``nn.Module`` (or a fixed ``(3, 3)`` / ``(4, 4)``
tensor, or a plain callable) mapping ``theta (T,)`` to ``parent_from_node (T, 3, 3)``
or ``(T, 4, 4)``. :meth:`SceneGraph.world_transforms` evaluates every node for all
``T`` times in one pass per tree level: each level's local matrices are stacked and
multiplied by their parents' world matrices in a single batched matmul.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import torch
from torch import nn

from torchgeo_cg.core.check import (
    ShapeError,
    check_float,
    check_shape,
    check_tensor,
    format_shape,
)
from torchgeo_cg.core.coerce import as_tensor_like, check_module_dtype
from torchgeo_cg.core.numerics import cast_back, working_dtype
from torchgeo_cg.transforms.homogeneous import rotation, translation

__all__ = ["Orbit", "FixedTransform", "SceneGraph", "WorldTransforms", "solar_system"]


class WorldTransforms(NamedTuple):
    """Every node's world matrix for every time.

    Attributes:
        names: the node names, in the order of ``matrices``.
        matrices: ``(K, T, 3, 3)`` (2D) or ``(K, T, 4, 4)`` (3D) ``world_from_node``
            for the K nodes and T times.
    """

    names: tuple[str, ...]
    matrices: torch.Tensor

    def get(self, name: str) -> torch.Tensor:
        """``(T, 3, 3)`` (or ``(T, 4, 4)``) world matrix of node ``name``."""
        try:
            return self.matrices[self.names.index(name)]
        except ValueError:
            raise KeyError(f"WorldTransforms: no node named {name!r}; have {self.names}") from None

    def positions(self) -> torch.Tensor:
        """``(K, T, 2)`` (or ``(K, T, 3)``) world position of every node's origin."""
        d = self.matrices.shape[-1] - 1
        return self.matrices[..., :d, d]


class Orbit(nn.Module):
    """A circular orbit around the parent: ``parent_from_node(θ)``.

    With angle ``a = speed·θ + phase`` (radians):

    - ``spin=False``: ``T(r·cos a, r·sin a)``; the node's axes stay parallel to its
      parent's, so a child of this node orbits relative to fixed axes.
    - ``spin=True``: ``R(a)·T(r, 0)``, the report's rotating frame (its
      ``T_moon3 = T_moon2(θ)·R(θ)·T([1, 0])``): the node's axes turn with the
      orbit, so a child's angular speed adds to this node's.

    Convention:
        Column vectors, radians, counter-clockwise positive; ``speed`` is in
        revolutions per cycle of ``θ ∈ [0, 2π)``. The result follows ``theta``'s
        dtype (radius, speed and phase are cast to it); float16/bfloat16 are
        computed in float32 and cast back.

    Args:
        radius: orbit radius (a float or a 0-d tensor; learnable if ``learnable``).
        speed: revolutions per cycle.
        phase: angle at ``θ = 0``, radians.
        spin: rotate the node's frame with the orbit.
        learnable: register radius, speed and phase as ``nn.Parameter``.

    Example:
        >>> orbit = Orbit(radius=3.0, speed=2.0)
        >>> orbit(torch.tensor([0.0, math.pi / 4]))[:, :2, 2].round(decimals=4) + 0.0
        tensor([[3., 0.],
                [0., 3.]])
    """

    def __init__(
        self,
        radius: float | torch.Tensor,
        speed: float | torch.Tensor = 1.0,
        phase: float | torch.Tensor = 0.0,
        spin: bool = False,
        learnable: bool = False,
    ) -> None:
        super().__init__()
        self.spin = spin
        for name, value in (("radius", radius), ("speed", speed), ("phase", phase)):
            value = as_tensor_like(value, None, name).clone()
            check_shape(value, [], name)  # a scalar: ShapeError naming it
            if learnable:
                setattr(self, name, nn.Parameter(value))
            else:
                self.register_buffer(name, value, persistent=True)

    def forward(self, theta: torch.Tensor) -> torch.Tensor:
        """``(T,)`` phases in radians -> ``(T, 3, 3)`` ``parent_from_node``."""
        check_module_dtype(self, theta, "theta")
        check_float(theta, "theta")
        theta_w = theta.to(working_dtype(theta.dtype))
        radius, speed, phase = (p.to(theta_w) for p in (self.radius, self.speed, self.phase))
        angle = speed * theta_w + phase  # (T,)
        if self.spin:
            offset = torch.stack([radius.expand_as(angle), torch.zeros_like(angle)], -1)
            local = rotation(angle, degrees=False) @ translation(offset)
        else:
            local = translation(radius * torch.stack([torch.cos(angle), torch.sin(angle)], -1))
        return cast_back(local, theta.dtype)

    def extra_repr(self) -> str:
        return f"spin={self.spin}"


class FixedTransform(nn.Module):
    """A constant ``parent_from_node`` matrix, stored as a buffer so ``.to()`` moves it.

    Convention:
        Column vectors; ``forward(theta (*))`` returns the ``(3, 3)`` (2D) or
        ``(4, 4)`` (3D) matrix expanded to ``(*, 3, 3)`` / ``(*, 4, 4)`` in ``theta``'s
        (float) dtype, the same for every time; a cast to float16/bfloat16 saturates at
        the largest finite value.

    Example:
        >>> FixedTransform(translation(torch.tensor([1.0, 2.0])))(torch.zeros(3)).shape
        torch.Size([3, 3, 3])
        >>> FixedTransform(translation(torch.tensor([1.0, 2.0, 3.0])))(torch.zeros(2)).shape
        torch.Size([2, 4, 4])
    """

    def __init__(self, matrix: torch.Tensor) -> None:
        super().__init__()
        check_tensor(matrix, "matrix")
        if tuple(matrix.shape) not in ((3, 3), (4, 4)):
            raise ShapeError(f"matrix: expected shape (3, 3) or (4, 4), "
                             f"got {format_shape(tuple(matrix.shape))}")
        check_float(matrix, "matrix")
        self.register_buffer("matrix", matrix.clone(), persistent=True)

    def forward(self, theta: torch.Tensor) -> torch.Tensor:
        check_module_dtype(self, theta, "theta")
        check_float(theta, "theta")  # an integer theta would truncate the matrix
        size = self.matrix.shape[-1]
        matrix = cast_back(self.matrix, theta.dtype).expand(*theta.shape, size, size)
        # the matrix does not depend on the time, but an undefined time stays undefined
        return torch.where(theta.isnan()[..., None, None], math.nan, matrix)


class _Identity(nn.Module):
    """The identity node: its size (3 or 4) is the graph's, known only at evaluation."""

    def forward(self, theta: torch.Tensor, size: int = 3) -> torch.Tensor:
        eye = torch.eye(size, dtype=theta.dtype, device=theta.device)
        return eye.expand(*theta.shape, size, size) + 0 * theta[..., None, None]


class _CallableTransform(nn.Module):
    def __init__(self, fn: Callable[[torch.Tensor], torch.Tensor]) -> None:
        super().__init__()
        self.fn = fn

    def forward(self, theta: torch.Tensor) -> torch.Tensor:
        return self.fn(theta)


class SceneGraph(nn.Module):
    """A kinematic tree of named 2D or 3D frames.

    Convention:
        Column vectors. Each node has a ``parent_from_node`` local transform, a
        module or callable mapping times ``theta (T,)`` to ``(T, 3, 3)`` (2D) or
        ``(T, 4, 4)`` (3D), one size for the whole graph (identity nodes take it);
        a node's world matrix is ``world_from_parent @ parent_from_node`` (the
        root's is its local transform). Nodes are added parents first;
        ``world_transforms`` evaluates one tree level at a time, all nodes of a level
        and all times batched. ``theta`` is ``(T,)``, shared by every node, or
        ``(T, K)``: joint values, column ``k`` for node ``k`` in insertion order
        (forward kinematics, differentiable in the joint values). See the module
        docstring.

    Example:
        >>> scene = SceneGraph()
        >>> scene.add("planet")
        >>> scene.add("moon", "planet", Orbit(radius=2.0))
        >>> world = scene.world_transforms(torch.tensor([0.0, math.pi / 2]))
        >>> world.names, world.matrices.shape
        (('planet', 'moon'), torch.Size([2, 2, 3, 3]))
        >>> world.get("moon")[:, :2, 2].round(decimals=4) + 0.0
        tensor([[2., 0.],
                [0., 2.]])

        A 3D arm: a base turning about z, an elbow about y one unit up, a slider.

        >>> from torchgeo_cg.transforms import Prismatic, Revolute
        >>> arm = SceneGraph()
        >>> arm.add("base", None, Revolute([0.0, 0.0, 1.0]))
        >>> arm.add("elbow", "base", Revolute([0.0, 1.0, 0.0], origin=[0.0, 0.0, 1.0]))
        >>> arm.add("tip", "elbow", Prismatic([1.0, 0.0, 0.0]))
        >>> q = torch.tensor([[math.pi / 2, 0.0, 2.0]])  # (T=1, K=3) joint values
        >>> arm.world_transforms(q).get("tip")[0, :3, 3].round(decimals=4) + 0.0
        tensor([0., 2., 1.])
    """

    def __init__(self) -> None:
        super().__init__()
        self.locals = nn.ModuleDict()
        self._parent: dict[str, str | None] = {}
        self._depth: dict[str, int] = {}

    @property
    def names(self) -> tuple[str, ...]:
        """Node names in insertion order (parents before children)."""
        return tuple(self._parent)

    def parent(self, name: str) -> str | None:
        """The parent of ``name`` (``None`` for a root)."""
        return self._parent[name]

    def add(
        self,
        name: str,
        parent: str | None = None,
        local_transform: nn.Module | torch.Tensor | Callable | None = None,
    ) -> None:
        """Add node ``name`` under ``parent`` (``None``: a root in the world frame).

        Args:
            name: a new, unique node name.
            parent: an existing node, or ``None``.
            local_transform: ``parent_from_node``: an ``nn.Module`` or callable
                mapping ``theta (T,)`` to ``(T, 3, 3)`` or ``(T, 4, 4)``, a fixed
                ``(3, 3)`` or ``(4, 4)`` tensor, or ``None`` for the identity.

        Raises:
            ValueError: ``name`` exists already, or ``parent`` does not.
        """
        if name in self._parent:
            raise ValueError(f"SceneGraph.add: name {name!r} already exists")
        if parent is not None and parent not in self._parent:
            raise ValueError(
                f"SceneGraph.add: parent {parent!r} of {name!r} is not a node; have {self.names}"
            )
        if local_transform is None:
            # the identity has no dtype nor size of its own: it follows theta and the graph
            local_transform = _Identity()
        elif isinstance(local_transform, torch.Tensor):
            local_transform = FixedTransform(local_transform)
        elif not isinstance(local_transform, nn.Module):
            if not callable(local_transform):
                raise TypeError(
                    "SceneGraph.add: local_transform must be an nn.Module, a callable, a (3, 3) "
                    f"or (4, 4) tensor or None, got {type(local_transform).__name__}"
                )
            local_transform = _CallableTransform(local_transform)
        self.locals[name] = local_transform
        self._parent[name] = parent
        self._depth[name] = 0 if parent is None else self._depth[parent] + 1

    def world_transforms(self, theta: torch.Tensor) -> WorldTransforms:
        """``world_from_node`` for every node at every time in ``theta``.

        Args:
            theta: ``(T,)`` float phases in radians, given to every node, or ``(T, K)``
                joint values, column ``k`` to node ``k`` (insertion order).

        Returns:
            :class:`WorldTransforms` with ``matrices (K, T, 3, 3)`` (2D nodes) or
            ``(K, T, 4, 4)`` (3D nodes), nodes in insertion order, in ``theta``'s
            dtype (every local transform is cast to it; float16/bfloat16 are computed
            in float32 and cast back). A graph of identity nodes only is 2D.

        Raises:
            ShapeError: ``theta`` is neither ``(T,)`` nor ``(T, K)``, or a node's local
                transform is not ``(T, 3, 3)`` / ``(T, 4, 4)`` of the graph's size.
        """
        names = self.names
        if not names:
            raise ValueError("SceneGraph.world_transforms: the graph has no nodes")
        check_tensor(theta, "theta")
        if theta.ndim not in (1, 2) or (theta.ndim == 2 and theta.shape[1] != len(names)):
            raise ShapeError(
                f"theta: expected shape (T) or (T, K={len(names)}) (one column per node), "
                f"got {format_shape(tuple(theta.shape))}")
        check_float(theta, "theta")
        theta_w = theta.to(working_dtype(theta.dtype))
        steps = theta.shape[0]
        per_node = theta_w.unbind(-1) if theta.ndim == 2 else (theta_w,) * len(names)
        index = {n: i for i, n in enumerate(names)}
        local = {n: self.locals[n](per_node[index[n]]) for n in names
                 if not isinstance(self.locals[n], _Identity)}
        size = next((m.shape[-1] for m in local.values()
                     if isinstance(m, torch.Tensor) and m.ndim >= 1), 3)
        for n in names:
            if n in local:
                m = local[n]
                if not isinstance(m, torch.Tensor) or tuple(m.shape) != (steps, size, size):
                    got = tuple(m.shape) if isinstance(m, torch.Tensor) else type(m).__name__
                    raise ShapeError(
                        f"SceneGraph: node {n!r}: expected its local transform of shape "
                        f"{format_shape([steps, size, size])} (one size per graph), got {got}")
                local[n] = m.to(theta_w)
            else:
                local[n] = self.locals[n](per_node[index[n]], size)
        world = theta_w.new_zeros(len(names), steps, size, size)  # (K, T, d+1, d+1)
        for depth in range(max(self._depth.values()) + 1):  # loop over tree levels
            level = [n for n in names if self._depth[n] == depth]
            rows = torch.tensor([index[n] for n in level], device=theta.device)
            stacked = torch.stack([local[n] for n in level])  # (L, T, d+1, d+1)
            if depth == 0:
                world = world.index_copy(0, rows, stacked)
            else:
                parents = torch.tensor([index[self._parent[n]] for n in level], device=theta.device)
                world = world.index_copy(0, rows, world[parents] @ stacked)
        return WorldTransforms(names, cast_back(world, theta.dtype))

    def forward(self, theta: torch.Tensor) -> torch.Tensor:
        """``(K, T, 3, 3)`` or ``(K, T, 4, 4)``: ``world_transforms(theta).matrices``."""
        check_module_dtype(self, theta, "theta")
        return self.world_transforms(theta).matrices


def solar_system(spin: bool = False) -> SceneGraph:
    """The report's system (section 2.3): a planet with three moons.

    - ``planet``: at the origin.
    - ``moon1``: orbits the planet at distance 2, once per cycle (the report does
      not give this radius; 2 is our choice).
    - ``moon2``: orbits the planet at distance 3, twice as fast as moon 1:
      ``T_moon2(θ) = R(2θ)·T([3, 0])``.
    - ``moon3``: orbits moon 2 at distance 1 by the report's formula
      ``T_moon3 = T_moon2(θ)·R(θ)·T([1, 0])``: once per cycle in moon 2's turning
      frame, so in fixed axes it circles moon 2 three times per cycle while moon 2
      circles the planet twice, and its trail is an epicycle round moon 2's orbit.
      (The report's prose says "twice per animation cycle"; its formula gives the
      motion above, which we follow.)

    Convention:
        ``theta`` in radians, one cycle is ``[0, 2π)``; all orbits counter-clockwise.
        Both values of ``spin`` give the same world positions. ``spin=True`` builds
        the report's rotating frames literally (each moon's axes turn with its
        orbit); ``spin=False`` keeps every frame's axes parallel to the world's,
        so moon 3's local speed is 3 revolutions per cycle relative to fixed axes.

    Example:
        >>> world = solar_system().world_transforms(torch.tensor([0.0, math.pi / 2]))
        >>> world.positions()[:, 0]
        tensor([[0., 0.],
                [2., 0.],
                [3., 0.],
                [4., 0.]])
        >>> (world.positions()[3, 1] - world.positions()[2, 1]).round(decimals=4) + 0.0
        tensor([ 0., -1.])
    """
    scene = SceneGraph()
    scene.add("planet")
    scene.add("moon1", "planet", Orbit(radius=2.0, speed=1.0, spin=spin))
    scene.add("moon2", "planet", Orbit(radius=3.0, speed=2.0, spin=spin))
    scene.add("moon3", "moon2", Orbit(radius=1.0, speed=1.0 if spin else 3.0, spin=spin))
    return scene
