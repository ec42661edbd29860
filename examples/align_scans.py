"""Register two scans of the shipped rabbit with ICP and print the remaining error.

    python examples/align_scans.py
"""

import torch

from torchgeo_cg.mesh.data import rabbit_scan_pairs
from torchgeo_cg.points import estimate_normals, icp

pairs = rabbit_scan_pairs(1, 8000, generator=torch.Generator().manual_seed(4),
                          angles=(30.0, 40.0))
normals = estimate_normals(pairs.target, 10)
out = icp(pairs.source, pairs.target, method="point_to_plane", target_normals=normals,
          max_distance=0.2 * pairs.size)
delta = out.transform[0, :3, :3] @ pairs.truth[0, :3, :3].T
angle = torch.rad2deg(torch.acos(((delta.trace() - 1) / 2).clamp(-1, 1)))
shift = (out.transform[0, :3, 3] - pairs.truth[0, :3, 3]).norm() / pairs.size
print(f"iterations {int(out.iterations[0])}, converged {bool(out.converged[0])}")
print(f"rotation error {float(angle):.3f} deg, translation error {float(shift):.2e} x size")
print(f"inlier RMSE {float(out.rmse[0]):.4f} ({float(out.inlier_fraction[0]):.0%} inliers)")
