"""Estimating transforms: DLT, LM fitting, RANSAC and image registration.

Targets, 1 thread, float32 (kornia's dtype):
- find_homography_dlt (4096 problems x 8 points): <= 1.0x kornia's find_homography_dlt
  (lu solver, its default) with the exact solver (``max_rel_diff_vs_svd`` on noisy and
  outlier data), and <= 0.05x a Python loop over OpenCV's findHomography (timed on a
  subset, scaled up).
- fit_transform(model="homography", solver=SolverOptions("lm")): total <= 3x our DLT.
- Adam: the time per step is reported (extra ``ms_per_step``).
- find_transform_ransac (256 problems x 200 correspondences, 40% outliers, 1 px noise,
  threshold 3 px): <= 1.0x OpenCV findHomography(USAC_MAGSAC) looped over the problems,
  with a median corner error <= OpenCV's (extras).
- register_images (32 pairs of 256 x 256 crops of skimage's camera, homographies moving
  the corners by up to 8 px): <= 1.0x OpenCV findTransformECC (MOTION_HOMOGRAPHY) looped
  over the pairs and <= 0.05x kornia's ImageRegistrator (homography, 3 levels; timed on
  2 pairs and scaled to 32), at a median corner error <= 0.1 px (extras).
"""

from __future__ import annotations

import torch

from benchmarks.harness import Case, time_fn
from torchgeo_cg.transforms import (
    SolverOptions,
    find_homography_dlt,
    find_transform_ransac,
    fit_transform,
    hartley_normalize,
    register_images,
    reprojection_error,
    transform_points,
)


def _problems(batch: int, n: int, noise: float, gen: torch.Generator):
    src = torch.rand(batch, n, 2, generator=gen) * 200
    h = torch.eye(3) + 0.1 * torch.randn(batch, 3, 3, generator=gen)
    h[:, 2, :2] *= 0.003
    h[:, :2, 2] *= 100
    dst = transform_points(h, src) + noise * torch.randn(batch, n, 2, generator=gen)
    return src, dst


def _svd_dlt(src, dst):
    """Reference: Hartley-normalized DLT by the SVD of the 2N x 9 system (float64)."""
    ns, nd = hartley_normalize(src), hartley_normalize(dst)
    x, y = ns.points[..., 0], ns.points[..., 1]
    u, v = nd.points[..., 0], nd.points[..., 1]
    o, z = torch.ones_like(x), torch.zeros_like(x)
    a = torch.cat([torch.stack([x, y, o, z, z, z, -u * x, -u * y, -u], -1),
                   torch.stack([z, z, z, x, y, o, -v * x, -v * y, -v], -1)], -2)
    hn = torch.linalg.svd(a, full_matrices=True).Vh[..., -1, :].unflatten(-1, (3, 3))
    h = torch.linalg.inv(nd.transform) @ hn @ ns.transform
    return h / h[..., 2:, 2:]


def _dlt_exactness(gen: torch.Generator) -> float:
    """Largest relative difference to the SVD solution, noisy (20 px) and 50%-outlier data."""
    src, dst = _problems(1024, 20, 20.0, gen)
    src, dst = src.double(), dst.double()
    junk = torch.rand(dst.shape, generator=gen, dtype=torch.float64) * 200
    dst = torch.where(torch.rand(dst.shape[:-1], generator=gen)[..., None] < 0.5, junk, dst)
    ref = _svd_dlt(src, dst)
    ours = find_homography_dlt(src, dst).matrix
    return float(((ours - ref).flatten(-2).norm(dim=-1) / ref.flatten(-2).norm(dim=-1)).max())


def _corner_error(matrix, truth, corners):
    c = corners.double().expand(truth.shape[0], 4, 2)
    return (transform_points(matrix.double(), c) - transform_points(truth.double(), c)).norm(
        dim=-1).mean(-1)


def _ransac_problems(b: int, n: int, gen: torch.Generator):
    """640 x 480 views, corners moved up to 32 px, 1 px noise, the first 40% outliers."""
    from kornia.geometry.transform import get_perspective_transform

    size = torch.tensor([640.0, 480.0])
    corners = torch.tensor([[0.0, 0.0], [640.0, 0.0], [640.0, 480.0], [0.0, 480.0]])
    moved = corners + 32 * (torch.rand(b, 4, 2, generator=gen) * 2 - 1)
    h = get_perspective_transform(corners.expand(b, 4, 2), moved)
    src = torch.rand(b, n, 2, generator=gen) * size
    dst = transform_points(h, src) + torch.randn(b, n, 2, generator=gen)
    k = int(0.4 * n)
    dst[:, :k] = torch.rand(b, k, 2, generator=gen) * size
    return src, dst, h, corners


def _ransac_cases(quick: bool) -> list[Case]:
    import cv2
    import numpy as np

    cv2.setNumThreads(1)  # the comparison is at 1 thread; OpenCV has its own pool

    gen = torch.Generator().manual_seed(1)
    b = 64 if quick else 256
    src, dst, h, corners = _ransac_problems(b, 200, gen)
    src_np, dst_np = src.numpy(), dst.numpy()

    def ours():
        return find_transform_ransac(src, dst, threshold=3.0,
                                     generator=torch.Generator().manual_seed(0))

    def magsac():
        return [cv2.findHomography(s, d, cv2.USAC_MAGSAC, 3.0)[0] for s, d in zip(src_np, dst_np)]

    err = _corner_error(ours().matrix, h, corners)
    cv_err = _corner_error(torch.from_numpy(np.stack(magsac())), h, corners)
    return [Case(
        f"find_transform_ransac {b}x200 40% outliers f32",
        ours,
        magsac,
        f"cv2 {cv2.__version__} findHomography USAC_MAGSAC loop",
        target=1.0,
        threads=(1,),
        extra={"median_corner_err_px": float(err.median()),
               "cv2_median_corner_err_px": float(cv_err.median()),
               "within_2px": float((err < 2).float().mean()),
               "cv2_within_2px": float((cv_err < 2).float().mean())},
    )]


def _camera_pairs(b: int, gen: torch.Generator, size: int = 256):
    """Crops of skimage's camera and targets from the full image: target(H p) = source(p)."""
    from kornia.geometry.transform import get_perspective_transform, warp_perspective
    from skimage.data import camera

    big = torch.from_numpy(camera()).float()[None, None] / 255
    off = (512 - size) // 2
    corners = torch.tensor([[0.0, 0.0], [size - 1, 0.0], [size - 1, size - 1],
                            [0.0, size - 1]])
    moved = corners + 8 * (torch.rand(b, 4, 2, generator=gen) * 2 - 1)
    h = get_perspective_transform(corners.expand(b, 4, 2), moved)
    t_off = torch.tensor([[1.0, 0, off], [0, 1, off], [0, 0, 1]])
    source = big[..., off:off + size, off:off + size].expand(b, 1, size, size).contiguous()
    target = warp_perspective(big.expand(b, 1, 512, 512), h @ torch.linalg.inv(t_off),
                              (size, size), align_corners=True)
    return source, target, h, corners


def _registration_cases(quick: bool) -> list[Case]:
    import cv2
    import kornia
    import numpy as np
    from kornia.geometry.conversions import denormalize_homography
    from kornia.geometry.transform import ImageRegistrator

    cv2.setNumThreads(1)

    gen = torch.Generator().manual_seed(2)
    b = 8 if quick else 32
    source, target, h, corners = _camera_pairs(b, gen)
    src_np, tgt_np = source[:, 0].numpy(), target[:, 0].numpy()
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-3)  # OpenCV's default

    def ours():
        return register_images(source, target)

    def ecc():  # template = source, input = target: warp = target_from_source, like ours
        out = []
        for s, t in zip(src_np, tgt_np):
            warp = np.eye(3, dtype=np.float32)
            try:
                warp = cv2.findTransformECC(s, t, warp, cv2.MOTION_HOMOGRAPHY, criteria, None,
                                            5)[1]
            except cv2.error:  # did not converge: keep the identity
                pass
            out.append(warp)
        return out

    k_pairs = 2

    def kornia_reg():  # register(target, source) returns target_from_source, normalized
        out = []
        for i in range(k_pairs):
            reg = ImageRegistrator("homography", pyramid_levels=3)
            out.append(reg.register(target[i:i + 1], source[i:i + 1]).detach())
        return torch.cat(out)

    err = _corner_error(ours().matrix, h, corners)
    ecc_err = _corner_error(torch.from_numpy(np.stack(ecc())), h, corners)
    k_mat = denormalize_homography(kornia_reg(), (256, 256), (256, 256), align_corners=False)
    k_err = _corner_error(k_mat, h[:k_pairs], corners)
    acc = {"median_corner_err_px": float(err.median()),
           "within_0.5px": float((err <= 0.5).float().mean())}
    return [
        Case(f"register_images {b}x256x256 homography", ours, ecc,
             f"cv2 {cv2.__version__} findTransformECC loop", target=1.0, threads=(1,),
             extra={**acc, "ecc_median_corner_err_px": float(ecc_err.median())}),
        Case(f"register_images {b}x256x256 homography vs kornia", ours, kornia_reg,
             f"kornia {kornia.__version__} ImageRegistrator ({k_pairs} timed, x{b // k_pairs})",
             target=0.05, threads=(1,), peer_scale=b / k_pairs,
             extra={**acc, "kornia_median_corner_err_px": float(k_err.median())}),
    ]


def cases(quick: bool = False) -> list[Case]:
    import cv2
    import kornia
    from kornia.geometry.homography import find_homography_dlt as kornia_dlt

    batch = 1024 if quick else 4096
    n = 8
    gen = torch.Generator().manual_seed(0)
    src, dst = _problems(batch, n, 0.5, gen)
    size = f"{batch}x{n} f32"
    peer_k = f"kornia {kornia.__version__} (lu)"

    # accuracy on the same batch (noise 0.5 px): mean squared transfer error ratios
    ours_err = reprojection_error(find_homography_dlt(src, dst).matrix, src, dst)
    k_err = reprojection_error(kornia_dlt(src, dst), src, dst)
    subset = 256
    src_np, dst_np = src[:subset].numpy(), dst[:subset].numpy()

    def cv_loop():
        return [cv2.findHomography(s, d, 0)[0] for s, d in zip(src_np, dst_np)]

    cv_h = torch.from_numpy(__import__("numpy").stack(cv_loop())).float()
    cv_err = reprojection_error(cv_h, src[:subset], dst[:subset])
    # degenerate input (collinear points): who flags it, who gives NaN
    line = torch.linspace(0, 1, n)
    deg_src = torch.stack([line, 2 * line + 1], -1).expand(64, n, 2).contiguous()
    deg = find_homography_dlt(deg_src, deg_src + 1)
    k_deg = kornia_dlt(deg_src, deg_src + 1)

    lm_fit = fit_transform(src, dst, solver=SolverOptions("lm"))
    lm_err = reprojection_error(lm_fit.matrix, src, dst)
    adam_steps = 20

    def adam():
        return fit_transform(src, dst,
                             solver=SolverOptions("adam", steps=adam_steps, patience=10**6))

    adam_ms = time_fn(adam, 1, 0.3)[0] * 1e3
    exactness = _dlt_exactness(gen)
    return _ransac_cases(quick) + _registration_cases(quick) + [
        Case(
            f"find_homography_dlt {size}",
            lambda: find_homography_dlt(src, dst),
            lambda: kornia_dlt(src, dst),
            peer_k,
            target=1.0,
            threads=(1, 2),
            extra={
                "err_ratio_vs_kornia": float(ours_err.mean() / k_err.mean()),
                "max_rel_diff_vs_svd": exactness,
                "err_ratio_vs_opencv": float(ours_err[:subset].mean() / cv_err.mean()),
                "collinear_flagged": float((~deg.rank_ok).float().mean()),
                "ours_nonfinite": float((~torch.isfinite(deg.matrix)).any(-1).any(-1)
                                        .float().mean()),
                "kornia_nonfinite": float((~torch.isfinite(k_deg)).any(-1).any(-1)
                                          .float().mean()),
            },
        ),
        Case(
            f"find_homography_dlt {size} vs OpenCV loop",
            lambda: find_homography_dlt(src, dst),
            cv_loop,
            f"cv2 {cv2.__version__} findHomography loop ({subset} timed, x{batch // subset})",
            target=0.05,
            peer_scale=batch / subset,
        ),
        Case(
            f"fit_transform homography lm {size}",
            lambda: fit_transform(src, dst, solver=SolverOptions("lm")),
            lambda: find_homography_dlt(src, dst),
            "our find_homography_dlt",
            target=3.0,
            extra={
                "lm_iterations": lm_fit.history.shape[0] - 1,
                "frac_within_1pct_of_dlt_cost": float((lm_err <= 1.01 * ours_err).float()
                                                      .mean()),
            },
        ),
        Case(
            f"fit_transform homography adam {adam_steps} steps {size}",
            adam,
            None,
            extra={"ms_per_step_1thread": adam_ms / adam_steps},
        ),
    ]
