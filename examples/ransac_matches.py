"""Fit homographies to ORB feature matches with outliers, robustly and in one batch.

Two views of skimage's ``astronaut`` and ``camera`` images are made by known
homographies; ORB features (scikit-image) are matched between the views, and
:func:`find_transform_ransac` fits both homographies at once (the two problems
are padded to the same number of matches with zero weights). The fit is then
compared with the known homography (corner error) and with a plain DLT on all
matches, which the wrong matches drag away.

Run: python examples/ransac_matches.py  (needs scikit-image)
"""

import numpy as np
import torch

from torchgeo_cg.transforms import (
    find_homography_dlt,
    find_transform_ransac,
    transform_points,
    warp_image,
)

try:
    from skimage import data
    from skimage.color import rgb2gray
    from skimage.feature import ORB, match_descriptors
except ImportError:
    raise SystemExit("install scikit-image for this example: pip install scikit-image") from None


def orb_matches(img0: np.ndarray, img1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Matched keypoints (M, 2) in (x, y) pixel coordinates of the two images."""
    found = []
    for img in (img0, img1):
        orb = ORB(n_keypoints=400, fast_threshold=0.05)
        orb.detect_and_extract(img)
        found.append((orb.keypoints[:, ::-1].copy(), orb.descriptors))  # (row, col) -> (x, y)
    pairs = match_descriptors(found[0][1], found[1][1], cross_check=True)
    return found[0][0][pairs[:, 0]], found[1][0][pairs[:, 1]]


images = [rgb2gray(data.astronaut()), data.camera() / 255.0]
truths = [torch.tensor([[0.9, 0.1, 30.0], [-0.08, 0.95, 20.0], [1e-4, 5e-5, 1.0]]),
          torch.tensor([[1.05, -0.15, 10.0], [0.12, 1.0, -25.0], [-1e-4, 1e-4, 1.0]])]
src_list, dst_list = [], []
for image, h in zip(images, truths):
    img = torch.from_numpy(image).float()[None, None]
    view = warp_image(img, torch.linalg.inv(h)).image[0, 0].numpy()  # view(h p) = image(p)
    src, dst = orb_matches(image, view)
    src_list.append(src)
    dst_list.append(dst)
    print(f"{len(src)} ORB matches")

# pad to a batch: zero-weight rows are never sampled and never inliers
n = max(len(s) for s in src_list)
src = torch.zeros(2, n, 2)
dst = torch.zeros(2, n, 2)
weights = torch.zeros(2, n)
for i, (s, d) in enumerate(zip(src_list, dst_list)):
    src[i, :len(s)], dst[i, :len(d)], weights[i, :len(s)] = torch.tensor(s), torch.tensor(d), 1

fit = find_transform_ransac(src, dst, threshold=2.0, weights=weights,
                            generator=torch.Generator().manual_seed(0))
plain = find_homography_dlt(src, dst, weights=weights).matrix
corners = torch.tensor([[0.0, 0.0], [511.0, 0.0], [511.0, 511.0], [0.0, 511.0]])
for i, h in enumerate(truths):
    truth_c = transform_points(h, corners)
    err = (transform_points(fit.matrix[i], corners) - truth_c).norm(dim=-1).mean()
    err_dlt = (transform_points(plain[i], corners) - truth_c).norm(dim=-1).mean()
    residual = (transform_points(h, src[i]) - dst[i]).norm(dim=-1)
    correct = (residual < 2.0) & (weights[i] > 0)  # matches the true homography explains
    agree = (fit.inliers[i] == correct)[weights[i] > 0].float().mean()
    print(f"problem {i}: {int(fit.num_inliers[i])} inliers of {int(weights[i].sum())} matches "
          f"(rank_ok={bool(fit.rank_ok[i])}), {float(agree):.0%} agree with the truth; corner "
          f"error RANSAC {float(err):.2f} px, plain DLT {float(err_dlt):.1f} px")
