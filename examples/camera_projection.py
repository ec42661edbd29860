"""Render a depth image of the shipped rabbit through an OpenCV camera, and lift it back.

    python examples/camera_projection.py [--out depth.png]

A camera 3 sizes in front of the rabbit (OpenCV frame: x right, y down, z forward),
looking at it, with a wide-angle lens. ``pixel_rays()`` gives one world-space ray per
pixel centre (the lens inverted exactly), ``torchgeo_cg.rays.render_depth`` casts them at
the rabbit (Catmull-Clark subdivided twice) and returns the distance along each ray.
Turned into camera-frame z, that depth image is what a depth sensor with this lens would
record: ``unproject(pixels, z)`` lifts it back onto the surface, and ``project`` of the
surface points lands on the pixel centres again.
"""

from __future__ import annotations

import argparse

import torch

from torchgeo_cg.cameras import OpenCVCamera, convert_pose
from torchgeo_cg.mesh import catmull_clark
from torchgeo_cg.mesh.data import rabbit
from torchgeo_cg.rays import render_depth


def make_camera(centre: torch.Tensor, size: float, image_size=(120, 160)) -> OpenCVCamera:
    """A wide-angle camera on the +z side of the rabbit, 3 sizes away, looking down -z."""
    # an OpenGL-style pose (camera-to-world, y up, z back), as Blender stores it
    gl_pose = torch.eye(4, dtype=torch.float64)
    gl_pose[:3, 3] = centre + torch.tensor([0.0, 0.0, 3 * size], dtype=torch.float64)
    extrinsics = convert_pose(gl_pose, "opengl", "opencv")  # world-to-camera
    h, w = image_size
    f = 1.1 * w
    K = torch.tensor([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]],
                     dtype=torch.float64)
    lens = torch.tensor([-0.28, 0.07, 1e-3, -5e-4, -0.01], dtype=torch.float64)
    return OpenCVCamera(K, lens, extrinsics, image_size=image_size)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="save the depth image (needs matplotlib)")
    args = parser.parse_args(argv)

    cage = rabbit(dtype=torch.float64)
    verts, faces = catmull_clark(cage.verts, cage.faces, levels=2)  # quads, y up
    centre = verts.mean(0)
    size = float((verts - centre).norm(dim=-1).max())
    camera = make_camera(centre, size)

    rays = camera.pixel_rays()  # (H, W, 3) origins and unit directions, (H, W) valid
    image = render_depth((verts, faces), rays.origins, rays.directions)
    mask = image.mask & rays.valid
    # t along a unit ray -> camera-frame z: the z of the direction in the camera frame
    rotation = camera.extrinsics[:3, :3]
    z = image.depth * (rays.directions @ rotation.T)[..., 2]
    h, w = camera.image_size
    print(f"{h} x {w} depth image of {faces.shape[0]} quads: {int(mask.sum())} pixels hit, "
          f"z {float(z[mask].min()):.3f}..{float(z[mask].max()):.3f}")

    pixels = camera.pixel_grid()[mask]  # (N, 2) pixel centres (u, v) that hit
    surface = rays.origins[mask] + image.depth[mask, None] * rays.directions[mask]
    back = camera.unproject(pixels, z[mask])
    lift = float((back.points - surface).norm(dim=-1).max()) / size
    reproject = float((camera.project(surface) - pixels).abs().max())
    print(f"unproject(pixels, z): all valid {bool(back.valid.all())}, "
          f"max error {lift:.1e} x size; project back: max {reproject:.1e} px")

    if args.out:
        import matplotlib.pyplot as plt

        far = float(z[mask].max())
        shown = torch.where(mask, z, far).numpy()  # the background at the farthest hit
        plt.imsave(args.out, shown, cmap="viridis_r", vmin=float(z[mask].min()), vmax=far)
        print(f"wrote {args.out}")
    return {"hits": int(mask.sum()), "lift_error": lift, "reproject_px": reproject}


if __name__ == "__main__":
    main()
