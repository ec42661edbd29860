"""Align a real image pair by gradient-based registration, coarse to fine.

The pair: skimage's ``camera`` (a 256 x 256 crop is the source) and a target made
from the full image by a known homography, plus noise and a brightness/contrast
change. :func:`register_images` fits ``target(H p) ≈ source(p)`` with the
normalized loss (``loss="ncc"``, invariant to the brightness change) over a
3-level pyramid; the corner error is printed after each level.

Run: python examples/register_images.py
"""

import torch

from torchgeo_cg.transforms import register_images, transform_points, warp_image

torch.manual_seed(0)
try:
    from skimage.data import camera
except ImportError:  # scikit-image is needed for the image only
    raise SystemExit("install scikit-image for this example: pip install scikit-image") from None

big = torch.from_numpy(camera()).float()[None, None] / 255  # (1, 1, 512, 512)
size, off = 256, 128
source = big[..., off:off + size, off:off + size].contiguous()

# The known motion (pixel coordinates: x right, y down): the crop's corners move ~8 px.
corners = torch.tensor([[0.0, 0.0], [size - 1, 0.0], [size - 1, size - 1], [0.0, size - 1]])
truth = torch.tensor([[1.02, 0.03, -4.0], [-0.02, 0.99, 6.0], [2e-5, -3e-5, 1.0]])
# target(q) = big(T_off · truth⁻¹ · q), so that target(truth · p) = source(p)
t_off = torch.tensor([[1.0, 0.0, off], [0.0, 1.0, off], [0.0, 0.0, 1.0]])
target = warp_image(big, t_off @ torch.linalg.inv(truth), (size, size)).image
target = 0.8 * target + 0.1 + 0.02 * torch.randn(target.shape)  # contrast, brightness, noise


def corner_error(matrix: torch.Tensor) -> float:
    """Mean distance (px) between the corners mapped by ``matrix`` and by the truth."""
    return float((transform_points(matrix, corners) - transform_points(truth, corners))
                 .norm(dim=-1).mean())


print(f"before: corner error {corner_error(torch.eye(3)):.3f} px")
steps = 50
for done in range(1, 4):  # stop after the coarsest `done` levels of the pyramid
    iterations = [steps] * done + [0] * (3 - done)
    fit = register_images(source, target, loss="ncc", levels=3, iterations=iterations)
    level = 3 - done
    print(f"after level {level} ({size >> level} px): corner error "
          f"{corner_error(fit.matrix[0]):.3f} px, 1 - ZNCC {float(fit.loss[0]):.4f}")

print("fitted target_from_source:\n", fit.matrix[0])
print(f"{fit.history.shape[0]} steps in all, converged: {bool(fit.converged[0])}")
