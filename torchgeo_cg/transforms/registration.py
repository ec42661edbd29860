"""Image registration: fit the transform that aligns two images, batched, coarse to fine.

:func:`register_images` fits ``matrix`` so that ``target(matrix · p) ≈ source(p)``
for every pixel ``p`` of ``source``, with the inverse-compositional Lucas-Kanade
algorithm (Baker & Matthews 2004, "Lucas-Kanade 20 years on", section 3.2) over an
image pyramid: the steepest-descent images ``∇source · ∂W/∂Δ`` are computed once
per level, and each Gauss-Newton step warps ``target`` by the current matrix,
solves the masked normal equations and composes ``W ← W ∘ W(Δ)⁻¹``. Gradient
descent (Adam through the differentiable :func:`warp_image`) is an option.
:func:`warp_image` is the bilinear warp used throughout.

Convention:
    - Pixel coordinates: ``x`` to the right (column index), ``y`` down (row
      index), pixel centres at integers, so ``image[..., y, x]`` is the value at
      ``(x, y)`` (``align_corners=True`` in ``grid_sample`` terms). Matrices act
      on column vectors ``[x, y, 1]ᵀ`` with the perspective divide, as in the
      rest of the library and in kornia / OpenCV.
    - The library's other figures use ``y`` up. A matrix ``M`` in these pixel
      coordinates is ``F M F⁻¹`` in a y-up frame with the origin at the
      bottom-left pixel centre, where ``F = [[1, 0, 0], [0, -1, H - 1], [0, 0, 1]]``
      (``F`` is its own inverse); a counter-clockwise rotation in pixel
      coordinates turns clockwise on screen.
    - ``matrix`` maps ``source`` pixels to ``target`` pixels: it is
      ``target_from_source``, like ``dst_from_src`` of :func:`find_homography_dlt`
      on matched features (source = src image, target = dst image).
    - Pixels whose image ``matrix · p`` falls outside ``target`` (or outside
      ``mask``) do not count, in the steps and in the reported loss.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
import torch.nn.functional as F

from torchgeo_cg.core.autograd import records_graph
from torchgeo_cg.core.check import ShapeError, check_choice, check_float, check_shape
from torchgeo_cg.core.numerics import cast_back, working_dtype

__all__ = ["WarpedImage", "RegistrationResult", "REGISTRATION_MODELS", "warp_image",
           "register_images"]


class WarpedImage(NamedTuple):
    """Result of :func:`warp_image`.

    Attributes:
        image: ``(B, C, h, w)`` the warped image (0 where ``valid`` is False).
        valid: ``(B, 1, h, w)`` bool, True where the sample point lies inside the
            input image (pixel centres ``0 <= x <= W - 1``, ``0 <= y <= H - 1``).
    """

    image: torch.Tensor
    valid: torch.Tensor


class RegistrationResult(NamedTuple):
    """Result of :func:`register_images`.

    Attributes:
        matrix: ``(B, 3, 3)`` ``target_from_source`` in full-resolution pixel
            coordinates (``matrix[..., 2, 2] = 1``).
        loss: ``(B,)`` final loss at full resolution over the valid pixels: the
            mean squared difference (``loss="ssd"``) or ``1 - ZNCC`` (``"ncc"``).
            When every image converged with Gauss-Newton it is the loss before
            the last step (which moved no corner by ``tol``), sparing one warp.
        history: ``(steps [+ 1], B)`` the loss before each step (an image that has
            converged at a level keeps its last value there), all levels in
            order, coarse to fine (at each level's scale), then the final loss
            unless it is the last entry already.
        converged: ``(B,)`` bool, the last step at full resolution moved every
            image corner by less than ``tol`` pixels.
    """

    matrix: torch.Tensor
    loss: torch.Tensor
    history: torch.Tensor
    converged: torch.Tensor


def _generators(model: str, like: torch.Tensor) -> torch.Tensor:
    """(P, 3, 3) Lie-algebra generators of ``model`` (the warp is ``exp(Σ Δ_k E_k)``)."""
    e = torch.zeros(8, 3, 3, dtype=like.dtype, device=like.device)
    rows = [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (2, 0), (2, 1)]
    for k, (i, j) in enumerate(rows):  # one generator per free homography entry
        e[k, i, j] = 1.0
    if model == "homography":
        return e
    if model == "affine":
        return e[:6]
    rot = e[3] - e[1]  # [[0, -1], [1, 0]]
    if model == "similarity":
        return torch.stack([e[0] + e[4], rot, e[2], e[5]])
    if model == "euclidean":
        return torch.stack([rot, e[2], e[5]])
    return torch.stack([e[2], e[5]])  # translation


#: Models of :func:`register_images` and their number of parameters.
REGISTRATION_MODELS: dict[str, int] = {"homography": 8, "affine": 6, "similarity": 4,
                                       "euclidean": 3, "translation": 2}


def _pixel_grid(h: int, w: int, like: torch.Tensor) -> torch.Tensor:
    """(h w, 3) homogeneous pixel centres ``(x, y, 1)`` in row-major order."""
    ys, xs = torch.meshgrid(torch.arange(h, dtype=like.dtype, device=like.device),
                            torch.arange(w, dtype=like.dtype, device=like.device),
                            indexing="ij")
    return torch.stack([xs, ys, torch.ones_like(xs)], -1).reshape(-1, 3)


def _sampling_grid(matrix: torch.Tensor, out_hw, in_hw):
    """``grid_sample`` grid (B, h, w, 2) of ``π(M p)`` over the output pixels, and validity.

    The output pixels form a lattice, so each homogeneous coordinate is a
    plane ``c0 x + c1 y + c2``: an outer sum of a row and a column (one
    image-sized operation each, instead of a matmul per pixel). The
    normalization to ``[-1, 1]`` (``align_corners=True``) is folded into the
    coefficients. Points mapped to infinity or beyond the input are invalid
    (and sampled as 0).
    """
    (h, w), (height, width) = out_hw, in_hw
    xs = torch.arange(w, dtype=matrix.dtype, device=matrix.device)
    ys = torch.arange(h, dtype=matrix.dtype, device=matrix.device)

    def plane(c):  # (B, 3) -> (B, h, w), contiguous along x
        return torch.add((c[:, 0, None] * xs)[:, None, :], (c[:, 1, None] * ys + c[:, 2, None])[
            :, :, None])

    den = plane(matrix[:, 2])
    inv = torch.where(den > 0, den, torch.full_like(den, math.nan)).reciprocal_()  # w <= 0: out
    gx = plane(matrix[:, 0] * (2.0 / (width - 1)) - matrix[:, 2]).mul_(inv)
    gy = plane(matrix[:, 1] * (2.0 / (height - 1)) - matrix[:, 2]).mul_(inv)
    edge = 1 + 4 * torch.finfo(matrix.dtype).eps  # pixel centres on the border count
    valid = (gx.abs() <= edge) & (gy.abs() <= edge)  # NaN -> False
    if not bool((den > 0).all()):  # points at or behind infinity: sampled as 0, finite
        gx, gy = (torch.nan_to_num(g, nan=-2.0, posinf=-2.0, neginf=-2.0) for g in (gx, gy))
    # clamped (far points give no huge indices inside grid_sample) and interleaved
    if records_graph(matrix):
        return torch.stack([gx, gy], -1).clamp(-2.0, 2.0), valid[:, None]
    grid = gx.new_empty(*gx.shape, 2)
    torch.clamp(gx, -2.0, 2.0, out=grid[..., 0])  # written in place: no stack copy
    torch.clamp(gy, -2.0, 2.0, out=grid[..., 1])
    return grid, valid[:, None]


def _warp(image: torch.Tensor, matrix: torch.Tensor, out_hw) -> WarpedImage:
    """Bilinear ``image(matrix · p)`` (B, C, h, w) over the output pixels, 0 where invalid."""
    grid, valid = _sampling_grid(matrix, out_hw, image.shape[-2:])
    warped = F.grid_sample(image, grid, mode="bilinear", padding_mode="zeros",
                           align_corners=True)
    return WarpedImage(warped, valid)


def _project(matrix: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    """π(M p) (B, n, 2) of homogeneous points (n, 3) by matrices (B, 3, 3) (inf/NaN at w = 0)."""
    uvw = grid @ matrix.mT  # (B, n, 3)
    return uvw[..., :2] / uvw[..., 2:]


def warp_image(
    image: torch.Tensor, matrix: torch.Tensor, size: tuple[int, int] | None = None
) -> WarpedImage:
    """Bilinear warp ``out(p) = image(matrix · p)`` for every output pixel ``p``, batched.

    Convention:
        Pixel coordinates as in the module docstring (x right, y down, centres
        at integers); ``matrix`` is ``input_from_output`` (it maps output pixels
        to where they sample the input), column vectors with the perspective
        divide. kornia's ``warp_perspective(image, M, dsize, align_corners=True)``
        is ``warp_image(image, inverse(M), dsize).image``. Samples outside the
        input are 0 and flagged in ``valid``; a point mapped to infinity is
        invalid. Differentiable with respect to ``image`` and ``matrix``.
        float16/bfloat16 are computed in float32 (the sample points need the
        digits) and the image is returned in the input dtype.

    Args:
        image: ``(B, C, H, W)`` float images (``H, W >= 2``).
        matrix: ``(B, 3, 3)`` or ``(3, 3)`` ``input_from_output``.
        size: output ``(h, w)``; default ``(H, W)``.

    Returns:
        :class:`WarpedImage` ``(image (B, C, h, w), valid (B, 1, h, w))``.

    Example:
        >>> img = torch.arange(12.0).reshape(1, 1, 3, 4)
        >>> shift = torch.tensor([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        >>> out = warp_image(img, shift)  # out(x, y) = img(x + 1, y)
        >>> out.image[0, 0]
        tensor([[ 1.,  2.,  3.,  0.],
                [ 5.,  6.,  7.,  0.],
                [ 9., 10., 11.,  0.]])
        >>> out.valid[0, 0, 0]
        tensor([ True,  True,  True, False])
    """
    check_shape(image, ["B", "C", "H", "W"], "image")
    check_float(image, "image")
    check_float(matrix, "matrix")
    if image.shape[-1] < 2 or image.shape[-2] < 2:
        raise ShapeError(f"image: expected H, W >= 2, got {tuple(image.shape)}")
    if matrix.dim() == 2:
        check_shape(matrix, ["3", "3"], "matrix")
        matrix = matrix.expand(image.shape[0], 3, 3)
    check_shape(matrix, [str(image.shape[0]), "3", "3"], "matrix")
    if matrix.dtype != image.dtype:
        raise TypeError(f"matrix: expected the dtype of image ({image.dtype}), got {matrix.dtype}")
    out_hw = tuple(image.shape[-2:]) if size is None else (int(size[0]), int(size[1]))
    work = working_dtype(image.dtype)  # float16/bfloat16: sampled in float32
    out = _warp(image.to(work), matrix.to(work), out_hw)
    return out._replace(image=cast_back(out.image, image.dtype))


def _level_scale(like: torch.Tensor) -> torch.Tensor:
    """S (3, 3): pixel centres of a 2x-downsampled level -> the finer level's pixels."""
    return like.new_tensor([[2.0, 0.0, 0.5], [0.0, 2.0, 0.5], [0.0, 0.0, 1.0]])


def _normalizer(h: int, w: int, like: torch.Tensor) -> torch.Tensor:
    """N (3, 3): pixels -> centred coordinates in about [-1, 1] (well-conditioned steps)."""
    s = max(h, w) / 2.0
    return like.new_tensor([[1 / s, 0.0, -(w - 1) / (2 * s)], [0.0, 1 / s, -(h - 1) / (2 * s)],
                            [0.0, 0.0, 1.0]])


def _pyramid(image: torch.Tensor, levels: int) -> list[torch.Tensor]:
    """Finest first: each level is the 2x2 box average of the previous one."""
    out = [image]
    for _ in range(levels - 1):
        out.append(F.avg_pool2d(out[-1], 2))
    return out


class _Level(NamedTuple):
    template: torch.Tensor  # (B, C, h, w) source at this level
    target: torch.Tensor  # (B, C, h', w') target at this level
    mask: torch.Tensor  # (B, 1, h, w) template pixels that may count
    gx: torch.Tensor  # (B, C, h w) ∂T/∂x̃ in normalized units
    gy: torch.Tensor  # (B, C, h w) ∂T/∂ỹ
    g2: torch.Tensor  # (B, 3, h w) Σ_C gx², gx gy, gy²
    mono: torch.Tensor  # (15, h w) monomials x̃^i ỹ^j, i + j <= 4 (first 6: degree <= 2)
    cu: torch.Tensor  # (P, 6) ∂ũ/∂Δ_k in the basis 1, x̃, ỹ, x̃², x̃ỹ, ỹ²
    cv: torch.Tensor  # (P, 6) ∂ṽ/∂Δ_k
    norm: torch.Tensor  # (3, 3) N of this level
    gens: torch.Tensor  # (P, 3, 3)


# Monomials x^i y^j of degree <= 4, degree <= 2 first; _PAIR[a][b] is the index of the
# product of quadratic monomials a and b (the Hessian's moments, as in the DLT).
_POWERS = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (3, 0), (2, 1), (1, 2), (0, 3),
           (4, 0), (3, 1), (2, 2), (1, 3), (0, 4)]
_PAIR = [[_POWERS.index((_POWERS[a][0] + _POWERS[b][0], _POWERS[a][1] + _POWERS[b][1]))
          for b in range(6)] for a in range(6)]


def _warp_derivatives(gens: torch.Tensor):
    """(P, 6) coefficients of ``∂W/∂Δ_k = E_k p̃ - p̃ (E_k p̃)_z`` in 1, x, y, x², xy, y².

    ``∂u = E02 + (E00 - E22) x + E01 y - E20 x² - E21 xy``,
    ``∂v = E12 + E10 x + (E11 - E22) y - E20 xy - E21 y²``.
    """
    e = gens
    zero = torch.zeros_like(e[:, 0, 0])
    cu = torch.stack([e[:, 0, 2], e[:, 0, 0] - e[:, 2, 2], e[:, 0, 1], -e[:, 2, 0], -e[:, 2, 1],
                      zero], -1)
    cv = torch.stack([e[:, 1, 2], e[:, 1, 0], e[:, 1, 1] - e[:, 2, 2], zero, -e[:, 2, 0],
                      -e[:, 2, 1]], -1)
    return cu, cv


def _make_level(template, target, mask, gens) -> _Level:
    """The per-level constants: ``∇T`` (central differences) and the warp's monomials.

    The steepest-descent images ``J_k = ∇T · ∂W/∂Δ_k`` are never formed: the
    gradient ``Jᵀ r`` and the matrix ``Jᵀ diag(m) J`` are products of the images
    ``r ∂T/∂x̃``, ``m (∂T/∂x̃)²``, ... with the monomials (a few GEMMs, no
    ``(B, C h w, P)`` tensor).
    """
    h, w = template.shape[-2:]
    border = torch.zeros_like(template[:, :1], dtype=torch.bool)
    border[..., 1:-1, 1:-1] = True  # the gradient needs both neighbours
    norm = _normalizer(h, w, template)
    unit = 1.0 / float(norm[0, 0])  # pixels per normalized unit
    gx = torch.zeros_like(template)
    gy = torch.zeros_like(template)
    gx[..., 1:-1] = (template[..., 2:] - template[..., :-2]) * (unit / 2)
    gy[..., 1:-1, :] = (template[..., 2:, :] - template[..., :-2, :]) * (unit / 2)
    pts = _pixel_grid(h, w, template) @ norm.mT  # (h w, 3) normalized (x̃, ỹ, 1)
    x, y = pts[:, 0], pts[:, 1]
    mono = torch.stack([x.pow(i) * y.pow(j) for i, j in _POWERS])  # (15, h w)
    cu, cv = _warp_derivatives(gens)
    gx, gy = gx.flatten(-2), gy.flatten(-2)
    g2 = torch.stack([(gx * gx).sum(1), (gx * gy).sum(1), (gy * gy).sum(1)], 1)
    return _Level(template, target, mask & border, gx, gy, g2, mono, cu, cv, norm, gens)


def _residual(level: _Level, matrix: torch.Tensor, loss: str):
    """Residual (B, C, h w) (0 outside), pixel weights (B, h w) and loss (B,) at ``matrix``."""
    out = _warp(level.target, matrix, tuple(level.template.shape[-2:]))
    c = level.template.shape[1]
    m = (out.valid & level.mask).flatten(1).to(matrix.dtype)  # (B, h w)
    warped, tmpl = out.image.flatten(2), level.template.flatten(2)  # (B, C, h w)
    count = m.sum(-1) * c
    count_safe = torch.where(count > 0, count, torch.ones_like(count))
    mc = m[:, None]
    if loss == "ssd":
        r = (warped - tmpl).mul_(mc)
        return r, m, torch.einsum("bcn,bcn->b", r, r) / count_safe

    def centred(img):
        return (img - (img * mc).sum((1, 2), keepdim=True) / count_safe[:, None, None]) * mc

    dw, dt = centred(warped), centred(tmpl)
    cov, var_t, var_w = (dw * dt).sum((1, 2)), dt.square().sum((1, 2)), dw.square().sum((1, 2))
    alpha = cov / torch.where(var_t > 0, var_t, torch.ones_like(var_t))
    alpha = torch.where(alpha != 0, alpha, torch.ones_like(alpha))  # gain undefined: none
    return dw / alpha[:, None, None] - dt, m, _one_minus_zncc(dw, dt, var_w, var_t)


def _one_minus_zncc(dw, dt, var_w, var_t) -> torch.Tensor:
    """``1 - ZNCC`` (B,) of centred images (B, C, n) as ``‖ŵ - t̂‖² / 2`` of the unit images.

    The same value as ``1 - cov / sqrt(var_w var_t)`` without its cancellation near a
    perfect match (which left one ulp of 1, 6e-8 in float32, in a loss of 1e-4); 1 where
    an image is constant (ZNCC undefined, taken as 0). NaN stays NaN.
    """
    nw, nt = var_w.sqrt(), var_t.sqrt()
    flat = (nw == 0) | (nt == 0)
    one = torch.ones_like(nw)
    diff = dw / torch.where(flat, one, nw)[:, None, None] - dt / torch.where(flat, one, nt)[
        :, None, None]
    value = torch.where(flat, one, 0.5 * torch.einsum("bcn,bcn->b", diff, diff))
    return value + (nw + nt) * 0  # NaN in either image wins over "constant"


def _hessian(level: _Level, m: torch.Tensor) -> torch.Tensor:
    """Masked Gauss-Newton matrix ``Jᵀ diag(m) J`` (B, P, P) from image moments.

    ``J_k = gx ∂u_k + gy ∂v_k``, so ``JᵀJ = Cu A Cuᵀ + Cu X Cvᵀ + Cv X Cuᵀ + Cv Y Cvᵀ``
    with ``A_ab = Σ m gx² q_a q_b`` (``q`` the quadratic monomials), ``X`` with
    ``gx gy`` and ``Y`` with ``gy²``: one GEMM against the 15 quartic monomials.
    """
    moments = (level.g2 * m[:, None]) @ level.mono.T  # (B, 3, 15)
    index = torch.tensor(_PAIR, device=m.device).flatten()
    a, x, y = moments[..., index].unflatten(-1, (6, 6)).unbind(1)  # (B, 6, 6) each
    cu, cv = level.cu, level.cv
    cross = cu @ x @ cv.T
    return cu @ a @ cu.T + cross + cross.mT + cv @ y @ cv.T


def _gn_step(level: _Level, hess: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
    """Δ (B, P) of one inverse-compositional Gauss-Newton step (tiny relative damping).

    ``r`` is already zero outside the valid pixels, so ``Jᵀ r`` is the masked
    gradient: ``Cu (Σ r gx q) + Cv (Σ r gy q)`` with the quadratic monomials ``q``.
    """
    sx = (r * level.gx).sum(1) if r.shape[1] > 1 else (r * level.gx)[:, 0]  # (B, h w)
    sy = (r * level.gy).sum(1) if r.shape[1] > 1 else (r * level.gy)[:, 0]
    quad = level.mono[:6].T  # (h w, 6)
    grad = (sx @ quad) @ level.cu.T + (sy @ quad) @ level.cv.T  # (B, P)
    p = hess.shape[-1]
    eye = torch.eye(p, dtype=hess.dtype, device=hess.device)
    trace = hess.diagonal(dim1=-2, dim2=-1).sum(-1)
    damp = 1e-9 * torch.where(trace > 0, trace, torch.ones_like(trace)) / p
    sol, _ = torch.linalg.solve_ex(hess + damp[:, None, None] * eye, grad)
    # a singular system of finite values takes no step; NaN images give a NaN step
    finite = torch.isfinite(hess).all(-1).all(-1) & torch.isfinite(grad).all(-1)
    return torch.where(torch.isfinite(sol) | ~finite[:, None], sol, torch.zeros_like(sol))


def _corner_motion(step: torch.Tensor, h: int, w: int) -> torch.Tensor:
    """Largest displacement (B,) of the image corners by the pixel matrices step (B, 3, 3)."""
    c = step.new_tensor([[0.0, 0.0, 1.0], [w - 1.0, 0.0, 1.0], [w - 1.0, h - 1.0, 1.0],
                         [0.0, h - 1.0, 1.0]])
    moved = _project(step, c)
    return (moved - c[:, :2]).norm(dim=-1).amax(-1).nan_to_num(math.inf)


def _exp_step(level: _Level, delta: torch.Tensor) -> torch.Tensor:
    """Pixel matrices (B, 3, 3) of ``N⁻¹ exp(Σ Δ_k E_k) N``."""
    gen = (delta @ level.gens.flatten(1)).unflatten(-1, (3, 3))
    return torch.linalg.solve(level.norm, torch.linalg.matrix_exp(gen) @ level.norm)


def _subset(level: _Level, keep: torch.Tensor) -> _Level:
    """The level restricted to the images ``keep`` (bool (B,))."""
    return level._replace(template=level.template[keep], target=level.target[keep],
                          mask=level.mask[keep], gx=level.gx[keep], gy=level.gy[keep],
                          g2=level.g2[keep])


def _run_gn(level: _Level, matrix, loss, iterations, tol, history):
    """Inverse-compositional Gauss-Newton at one level: ``W ← W ∘ W(Δ)⁻¹``.

    Images whose step moved no corner by ``tol`` stop (they leave the batch; their
    loss is repeated in ``history``).
    """
    h, w = level.template.shape[-2:]
    done = torch.zeros(matrix.shape[0], dtype=torch.bool, device=matrix.device)
    last = torch.full_like(matrix[:, 0, 0], math.nan)
    idx = torch.arange(matrix.shape[0], device=matrix.device)
    hess, counted = None, None
    for _ in range(iterations):
        r, m, value = _residual(level, matrix[idx], loss)
        last = last.index_copy(0, idx, value)
        history.append(last)
        count = m.sum(-1)
        # the fixed point only depends on the gradient Jᵀ r; the matrix is rebuilt
        # when the set of valid pixels has changed by more than 1%
        if hess is None or bool(((count - counted).abs() > 0.01 * counted).any()):
            hess, counted = _hessian(level, m), count
        step = _exp_step(level, -_gn_step(level, hess, r))  # W(Δ)⁻¹ = exp(-Σ Δ E)
        new = matrix[idx] @ step
        matrix = matrix.index_copy(0, idx, new / new[:, 2:, 2:])
        moved = _corner_motion(step, h, w) < tol
        done = done.index_copy(0, idx, moved)
        if bool(moved.all()):
            break
        if bool(moved.any()):
            keep = ~moved
            idx, level, hess, counted = idx[keep], _subset(level, keep), hess[keep], count[keep]
    return matrix, done


def _run_adam(level: _Level, matrix, loss, iterations, tol, history, lr):
    """Adam on ``θ`` with ``W = W₀ · exp(Σ θ_k E_k)``, through the differentiable warp."""
    h, w = level.template.shape[-2:]
    theta = matrix.new_zeros(matrix.shape[0], level.gens.shape[0], requires_grad=True)
    opt = torch.optim.Adam([theta], lr=lr)
    previous = matrix
    # the ssd is in intensity units squared: descend ssd / mean(template²), unit-free, so
    # Adam's absolute eps (1e-8) does not stall images of small intensities
    unit = level.template.square().mean((1, 2, 3)) if loss == "ssd" else None
    unit = None if unit is None else torch.where(unit > 0, unit, torch.ones_like(unit))
    for _ in range(iterations):
        with torch.enable_grad():
            current = matrix @ _exp_step(level, theta)
            _, _, value = _residual(level, current, loss)
            opt.zero_grad()
            (value if unit is None else value / unit).sum().backward()
        opt.step()
        history.append(value.detach())
        previous = current.detach()
    with torch.no_grad():
        final = matrix @ _exp_step(level, theta)
        moved = _corner_motion(torch.linalg.solve(previous, final), h, w) < tol
    return final / final[:, 2:, 2:], moved


def _check_inputs(source, target, init, mask):
    sizes = check_shape(source, ["B", "C", "H", "W"], "source")
    check_float(source, "source")
    check_shape(target, [str(sizes["B"]), str(sizes["C"]), "H2", "W2"], "target")
    check_float(target, "target")
    if target.dtype != source.dtype:
        raise TypeError(f"target: expected the dtype of source ({source.dtype}), "
                        f"got {target.dtype}")
    if min(source.shape[-2:]) < 4 or min(target.shape[-2:]) < 4:
        raise ShapeError(f"source, target: expected H, W >= 4, got {tuple(source.shape)} "
                         f"and {tuple(target.shape)}")
    b = source.shape[0]
    if init is None:
        init = torch.eye(3, dtype=source.dtype, device=source.device).expand(b, 3, 3)
    else:
        check_float(init, "init")
        if init.dim() == 2:
            check_shape(init, ["3", "3"], "init")
        init = init.to(source.dtype).expand(b, 3, 3) if init.dim() == 2 else init
        check_shape(init, [str(b), "3", "3"], "init")
    if mask is not None:
        check_shape(mask, [str(b), "1", *map(str, source.shape[-2:])], "mask")
        mask = mask.bool()
    return init.to(source.dtype), mask


def _iterations(iterations, levels: int, optimizer: str) -> list[int]:
    if iterations is None:
        iterations = 50 if optimizer == "gn" else 100
    its = [iterations] * levels if isinstance(iterations, int) else list(iterations)
    if len(its) != levels or any(isinstance(i, bool) or not isinstance(i, int) or i < 0
                                 for i in its):
        raise ValueError(f"iterations: expected an int >= 0 or {levels} of them (coarse to "
                         f"fine), got {iterations!r}")
    return its


def register_images(
    source: torch.Tensor,
    target: torch.Tensor,
    model: str = "homography",
    levels: int = 3,
    iterations: int | list[int] | None = None,
    init: torch.Tensor | None = None,
    mask: torch.Tensor | None = None,
    loss: str = "ssd",
    optimizer: str = "gn",
    tol: float = 5e-2,
    lr: float = 1e-3,
) -> RegistrationResult:
    """Fit ``target(matrix · p) ≈ source(p)`` over an image pyramid, batched.

    Coarse to fine over ``levels`` 2x box-filtered levels (fewer if the
    coarsest would be under 8 pixels): at each level, inverse-compositional
    Gauss-Newton steps (``optimizer="gn"``) or Adam steps on the warp
    parameters (``"adam"``, through :func:`warp_image`), until the step moves
    every image corner by less than ``tol`` pixels (per image; coarser levels
    stop at ``max(tol, 0.1)`` of their pixels) or the level's iterations run
    out. See the module docstring for the method.

    Convention:
        Pixel coordinates x right, y down, centres at integers (module
        docstring, which also gives the y-up conversion); ``matrix`` is
        ``target_from_source``, column vectors. Only source pixels inside
        ``mask`` whose image lies inside ``target`` count. ``loss="ssd"``
        minimizes the mean squared intensity difference; ``loss="ncc"``
        matches the warped target to the source up to a per-image gain and
        offset (fitted by least squares over the valid pixels at every step),
        which makes the result invariant to a global brightness and contrast
        change, and reports ``1 - ZNCC``. Not differentiable (the steps run
        without autograd); differentiate :func:`warp_image` instead.
        float16/bfloat16 images are registered in float32 and the results
        returned in their dtype.

    Args:
        source: ``(B, C, H, W)`` float images (the template, sampled on its grid).
        target: ``(B, C, H2, W2)`` float images, same B and C and dtype.
        model: one of :data:`REGISTRATION_MODELS` (``"homography"``, ``"affine"``,
            ``"similarity"``, ``"euclidean"``, ``"translation"``).
        levels: pyramid levels, >= 1.
        iterations: steps per level, an int or one per level (coarse to fine);
            default 50 (gn) or 100 (adam).
        init: optional ``(B, 3, 3)`` or ``(3, 3)`` starting ``target_from_source``.
        mask: optional ``(B, 1, H, W)`` bool, the source pixels that count.
        loss: ``"ssd"`` or ``"ncc"``.
        optimizer: ``"gn"`` or ``"adam"``.
        tol: convergence threshold on the corner motion of one step, pixels of
            the level (default 0.05: near the optimum each step shrinks the error
            about 5x, so what is left after the last step is ~0.01 px).
        lr: Adam's learning rate (normalized units: 1 is half the image size); Adam
            descends the ssd divided by the template's mean square, so the result does
            not depend on the intensity units.

    Returns:
        :class:`RegistrationResult` ``(matrix (B, 3, 3), loss (B,),
        history (steps + 1, B), converged (B,))``.

    Example:
        >>> yy, xx = torch.meshgrid(torch.arange(64.0), torch.arange(64.0), indexing="ij")
        >>> source = torch.exp(-((xx - 30) ** 2 + (yy - 34) ** 2) / 60)[None, None]
        >>> shift = torch.tensor([[1.0, 0.0, 2.5], [0.0, 1.0, -1.5], [0.0, 0.0, 1.0]])
        >>> target = warp_image(source, torch.linalg.inv(shift)).image
        >>> fit = register_images(source, target, model="translation")
        >>> fit.matrix[0, :2, 2].round(decimals=3), bool(fit.converged[0])
        (tensor([ 2.5000, -1.5000]), True)
    """
    check_choice(model, REGISTRATION_MODELS, "model")
    check_choice(loss, ("ssd", "ncc"), "loss")
    check_choice(optimizer, ("gn", "adam"), "optimizer")
    if isinstance(levels, bool) or not isinstance(levels, int) or levels < 1:
        raise ValueError(f"levels: expected an int >= 1, got {levels!r}")
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol: expected a finite positive number of pixels, got {tol!r}")
    init, mask = _check_inputs(source, target, init, mask)
    if working_dtype(source.dtype) != source.dtype:  # float16/bfloat16: fitted in float32
        work = working_dtype(source.dtype)
        fit = register_images(source.to(work), target.to(work), model, levels, iterations,
                              init.to(work), mask, loss, optimizer, tol, lr)
        return fit._replace(**{k: cast_back(getattr(fit, k), source.dtype)
                               for k in ("matrix", "loss", "history")})
    its = _iterations(iterations, levels, optimizer)
    while levels > 1 and min(source.shape[-2:]) >> (levels - 1) < 8:
        levels -= 1
    its = its[len(its) - levels:]
    sources, targets = _pyramid(source, levels), _pyramid(target, levels)
    if mask is None:
        masks = [torch.ones_like(s[:, :1], dtype=torch.bool) for s in sources]
    else:
        masks = [m == 1 for m in _pyramid(mask.to(source.dtype), levels)]
    gens = _generators(model, source)
    scale = _level_scale(source)
    down = torch.linalg.matrix_power(scale, levels - 1)
    matrix = torch.linalg.solve(down, init @ down)  # the coarsest level's pixels
    history: list[torch.Tensor] = []
    final = None
    with torch.no_grad():
        for lvl in reversed(range(levels)):
            level = _make_level(sources[lvl], targets[lvl], masks[lvl], gens)
            level_tol = tol if lvl == 0 else max(tol, 0.1)  # the finer level refines
            if optimizer == "gn":
                matrix, done = _run_gn(level, matrix, loss, its[levels - 1 - lvl], level_tol,
                                       history)
            else:
                matrix, done = _run_adam(level, matrix, loss, its[levels - 1 - lvl], level_tol,
                                         history, lr)
            if lvl > 0:
                matrix = scale @ torch.linalg.solve(scale.mT, matrix.mT).mT  # S M S⁻¹
        if not history or optimizer == "adam" or not bool(done.all()):
            history.append(_residual(level, matrix, loss)[2])
    final = history[-1]  # converged GN: the loss before the last step (< tol px)
    return RegistrationResult(matrix, final, torch.stack(history), done)
