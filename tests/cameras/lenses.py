"""The five lenses of the round-trip tests, on a 3840 x 2160 image."""

from __future__ import annotations

import math

import torch

import torchgeo_cg.cameras as C

H, W = 2160, 3840

#: name -> (model, focal length in pixels, distortion)
LENSES = {
    # monotone everywhere: rd = 1.1336 -> r = 1.2498 (a fixed-point iteration cycles there)
    "newton_physics": ("opencv", 1800.0, [-0.45, 0.25, 0.0, 0.0]),
    # folds at r = 0.941 (rd = 0.603), inside the image's corners
    "folding": ("opencv", 2400.0, [-0.45, 0.05, 0.0, 0.0]),
    "rational8": ("opencv", 1500.0, [-0.3, 0.08, 1e-3, -5e-4, -0.01, 0.05, 0.01, 2e-3]),
    "full14": ("opencv", 1600.0, [-0.25, 0.06, 8e-4, -6e-4, -0.008, 0.04, 0.008, 1e-3,
                                  1e-3, -5e-4, 8e-4, 3e-4, 0.01, -0.02]),
    # 158 degrees off the axis at the corners; folds before that
    "strong_fisheye": ("fisheye", 800.0, [0.05, -0.02, 0.003, -5e-4]),
}


def make_camera(name: str, dtype=torch.float64, extrinsics: torch.Tensor | None = None):
    model, f, dist = LENSES[name]
    K = torch.tensor([[f, 0.0, (W - 1) / 2 + 3.25], [0.0, 1.02 * f, (H - 1) / 2 - 2.5],
                      [0.0, 0.0, 1.0]], dtype=torch.float64)
    d = torch.tensor(dist, dtype=torch.float64)
    cls = C.FisheyeCamera if model == "fisheye" else C.OpenCVCamera
    e = None if extrinsics is None else extrinsics.to(dtype)
    return cls(K.to(dtype), d.to(dtype), e, image_size=(H, W))


def pose(dtype=torch.float64) -> torch.Tensor:
    """A rigid world-to-camera pose (a rotation about a tilted axis and a shift)."""
    axis = torch.tensor([0.3, -0.5, 0.8], dtype=torch.float64)
    axis = axis / axis.norm()
    angle = 0.4
    k = torch.tensor([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]],
                     dtype=torch.float64)
    rot = torch.eye(3, dtype=torch.float64) + math.sin(angle) * k \
        + (1 - math.cos(angle)) * k @ k
    out = torch.eye(4, dtype=torch.float64)
    out[:3, :3] = rot
    out[:3, 3] = torch.tensor([0.2, -0.1, 0.5], dtype=torch.float64)
    return out.to(dtype)


def pixels(step: int, dtype=torch.float64) -> torch.Tensor:
    """Every ``step``-th pixel centre of the image (``step = 1``: all), ``(N, 2)``."""
    v, u = torch.meshgrid(torch.arange(0, H, step, dtype=dtype),
                          torch.arange(0, W, step, dtype=dtype), indexing="ij")
    return torch.stack([u, v], -1).reshape(-1, 2)
