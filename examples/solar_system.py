"""Articulated motion: evaluate the report's planet-and-moons system for many times at once.

Run: python examples/solar_system.py
"""

import math

import torch

from torchgeo_cg.transforms import Orbit, solar_system, transform_points

scene = solar_system().to(torch.float64)
theta = torch.linspace(0, 2 * math.pi, 9, dtype=torch.float64)  # (T,) phases, one cycle
world = scene.world_transforms(theta)  # world.matrices: (4 nodes, T, 3, 3)

print("theta   " + "  ".join(f"{n:>15s}" for n in world.names))
for t in range(len(theta)):
    row = "  ".join(f"({x:6.2f},{y:6.2f})" for x, y in world.positions()[:, t].tolist())
    print(f"{theta[t]:5.2f}   {row}")

# A moon's outline, drawn in its own frame, placed in the world by its world matrix.
square = torch.tensor([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]], dtype=torch.float64)
moon3_outline = transform_points(world.get("moon3")[:, None], square)  # (T, 4, 2)
print("moon 3 outline at theta=0:", moon3_outline[0].round(decimals=3).tolist())

# Learnable: fit an orbit radius to observed positions by gradient descent.
observed = world.get("moon2")[:, :2, 2]
orbit = Orbit(radius=1.0, speed=2.0, learnable=True).to(torch.float64)
optim = torch.optim.Adam([orbit.radius], lr=0.1)
for _ in range(200):
    optim.zero_grad()
    loss = (orbit(theta)[:, :2, 2] - observed).pow(2).mean()
    loss.backward()
    optim.step()
print(f"recovered moon 2 radius: {orbit.radius.item():.4f} (true 3.0)")
