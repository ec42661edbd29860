"""Estimating transforms (issue 7): batched DLT and LM fitting on 4096 problems x 8 points.

Targets, 1 thread, float32 (kornia's dtype):
- find_homography_dlt: <= 1.0x kornia's find_homography_dlt (lu solver, its default) and
  <= 0.05x a Python loop over OpenCV's findHomography (timed on a subset, scaled up).
- fit_transform(model="homography", optimizer="lm"): total <= 3x our DLT.
- Adam: the time per step is reported (extra ``ms_per_step``).
"""

from __future__ import annotations

import torch

from benchmarks.harness import Case, time_fn
from torchgeo_cg.transforms import (
    find_homography_dlt,
    fit_transform,
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

    lm_fit = fit_transform(src, dst, optimizer="lm")
    lm_err = reprojection_error(lm_fit.matrix, src, dst)
    adam_steps = 20

    def adam():
        return fit_transform(src, dst, optimizer="adam", steps=adam_steps, patience=10**6)

    adam_ms = time_fn(adam, 1, 0.3)[0] * 1e3
    return [
        Case(
            f"find_homography_dlt {size}",
            lambda: find_homography_dlt(src, dst),
            lambda: kornia_dlt(src, dst),
            peer_k,
            target=1.0,
            threads=(1, 2),
            extra={
                "err_ratio_vs_kornia": float(ours_err.mean() / k_err.mean()),
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
            lambda: fit_transform(src, dst, optimizer="lm"),
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
