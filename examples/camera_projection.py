"""Project the shipped rabbit's vertices through an OpenCV camera and lift them back.

    python examples/camera_projection.py

A camera 3 units in front of the rabbit (OpenCV frame: x right, y down, z forward),
looking at it, with a wide-angle lens. ``project`` gives pixels, ``depth`` their
camera-frame z, and ``unproject(pixels, depth)`` inverts the lens exactly and returns the
vertices. (Once ``torchgeo_cg.rays`` casts rays against meshes, ``pixel_rays()`` of the
same camera renders its depth image.)
"""

import torch

from torchgeo_cg.cameras import OpenCVCamera, convert_pose
from torchgeo_cg.mesh.data import rabbit

verts = rabbit(dtype=torch.float64).verts  # (V, 3), y up
centre = verts.mean(0)
size = float((verts - centre).norm(dim=-1).max())

# an OpenGL-style pose (camera-to-world, y up, z back), as Blender stores it: the camera
# on the +z side of the rabbit, 3 sizes away, looking down -z at it
gl_pose = torch.eye(4, dtype=torch.float64)
gl_pose[:3, 3] = centre + torch.tensor([0.0, 0.0, 3 * size], dtype=torch.float64)
extrinsics = convert_pose(gl_pose, "opengl", "opencv")  # world-to-camera

K = torch.tensor([[900.0, 0.0, 639.5], [0.0, 900.0, 359.5], [0.0, 0.0, 1.0]],
                 dtype=torch.float64)
lens = torch.tensor([-0.28, 0.07, 1e-3, -5e-4, -0.01], dtype=torch.float64)
camera = OpenCVCamera(K, lens, extrinsics, image_size=(720, 1280))

pixels = camera.project(verts)  # (V, 2)
depth = camera.depth(verts)  # (V,)
inside = ((pixels >= 0) & (pixels <= torch.tensor([1279.0, 719.0], dtype=torch.float64))).all(-1)
back = camera.unproject(pixels, depth)

print(f"{verts.shape[0]} vertices, {int(inside.sum())} inside the 1280 x 720 image")
print(f"pixels from ({float(pixels[:, 0].min()):.1f}, {float(pixels[:, 1].min()):.1f}) "
      f"to ({float(pixels[:, 0].max()):.1f}, {float(pixels[:, 1].max()):.1f}), "
      f"depth {float(depth.min()):.3f}..{float(depth.max()):.3f}")
err = float((back.points - verts).norm(dim=-1).max()) / size
print(f"round trip: all valid {bool(back.valid.all())}, max error {err:.1e} x size")
