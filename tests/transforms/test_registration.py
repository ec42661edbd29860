"""Tests for torchgeo_cg.transforms.registration: warp_image and register_images."""

from __future__ import annotations

import pytest
import torch

import torchgeo_cg.transforms.registration as registration
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.transforms import inverse, register_images, transform_points, warp_image

kornia_tf = pytest.importorskip("kornia.geometry.transform")


@pytest.fixture(autouse=True)
def one_thread():
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def corners(size):
    s = size - 1.0
    return torch.tensor([[0.0, 0.0], [s, 0.0], [s, s], [0.0, s]])


def camera_pairs(b, gen, size=256, move=8.0, noise=0.0, dtype=torch.float32):
    """Crops of skimage's camera (512 px) and targets with ``target(H p) = source(p)``.

    The target is made by kornia from the full image, so every target pixel has
    data: ``target(q) = big(T_off H⁻¹ q)``, i.e. kornia's
    ``warp_perspective(big, H T_off⁻¹)`` (kornia samples ``in(M⁻¹ q)``).
    """
    data = pytest.importorskip("skimage.data")
    big = torch.from_numpy(data.camera()).to(dtype)[None, None] / 255
    off = (512 - size) // 2
    c = corners(size).to(dtype)
    moved = c + move * (torch.rand(b, 4, 2, generator=gen, dtype=dtype) * 2 - 1)
    h = kornia_tf.get_perspective_transform(c.expand(b, 4, 2), moved)
    t_off = torch.tensor([[1.0, 0, off], [0, 1, off], [0, 0, 1]], dtype=dtype)
    source = big[..., off:off + size, off:off + size].expand(b, 1, size, size).contiguous()
    target = kornia_tf.warp_perspective(big.expand(b, 1, 512, 512), h @ torch.linalg.inv(t_off),
                                        (size, size), align_corners=True)
    if noise:
        target = target + noise * torch.randn(target.shape, generator=gen, dtype=dtype)
    return source, target, h


def corner_error(estimate, truth, size):
    c = corners(size).double().expand(truth.shape[0], 4, 2)
    return (transform_points(estimate.double(), c) - transform_points(truth.double(), c)).norm(
        dim=-1).mean(-1)


def test_public_surface():
    assert set(registration.__all__) == {"WarpedImage", "RegistrationResult",
                                         "REGISTRATION_MODELS", "warp_image", "register_images"}
    assert registration.RegistrationResult._fields == ("matrix", "loss", "history", "converged")


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_warp_matches_kornia_warp_perspective(dtype):
    gen = torch.Generator().manual_seed(0)
    image = torch.rand(4, 3, 20, 30, generator=gen, dtype=dtype)
    c = torch.tensor([[0.0, 0], [29, 0], [29, 19], [0, 19]], dtype=dtype)
    moved = c + 3 * torch.randn(4, 4, 2, generator=gen, dtype=dtype)
    m = kornia_tf.get_perspective_transform(c.expand(4, 4, 2), moved)  # kornia: out(p) = in(M⁻¹p)
    theirs = kornia_tf.warp_perspective(image, m, (18, 25), align_corners=True)
    ours = warp_image(image, inverse(m), (18, 25))
    assert ours.image.shape == (4, 3, 18, 25) and ours.valid.shape == (4, 1, 18, 25)
    tol = 1e-4 if dtype == torch.float32 else 1e-10
    # kornia fills outside with 0 too, so the images agree everywhere
    assert torch.allclose(ours.image, theirs, atol=tol)
    # valid: exactly the pixels whose sample point lies inside the input
    pts = transform_points(inverse(m)[:, None], torch.stack(torch.meshgrid(
        torch.arange(25.0, dtype=dtype), torch.arange(18.0, dtype=dtype), indexing="xy"), -1))
    inside = (pts[..., 0] >= -1e-4) & (pts[..., 0] <= 29 + 1e-4) & (pts[..., 1] >= -1e-4) & (
        pts[..., 1] <= 19 + 1e-4)
    assert (ours.valid[:, 0] == inside).float().mean() > 0.999


@pytest.mark.grad
def test_warp_gradcheck():
    gen = torch.Generator().manual_seed(1)
    image = torch.rand(2, 2, 6, 7, generator=gen, dtype=torch.float64, requires_grad=True)
    m = torch.eye(3, dtype=torch.float64) + 0.05 * torch.randn(2, 3, 3, generator=gen,
                                                              dtype=torch.float64)
    m[:, 2, :2] *= 0.05
    m[:, :2, 2] += torch.tensor([0.37, -0.21], dtype=torch.float64)  # off the integer kinks
    m.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda i, a: warp_image(i, a).image, (image, m))


@pytest.mark.slow
def test_homography_registration_of_camera_pairs_is_subpixel():
    gen = torch.Generator().manual_seed(2)
    source, target, truth = camera_pairs(16, gen)
    fit = register_images(source, target)
    err = corner_error(fit.matrix, truth, 256)
    assert err.median() <= 0.1
    assert (err <= 0.5).float().mean() >= 0.95
    assert fit.converged.all() and torch.isfinite(fit.loss).all()
    assert fit.history.shape[1] == 16 and (fit.loss < fit.history[0]).all()


@pytest.mark.parametrize("model", ["affine", "similarity", "euclidean", "translation"])
def test_other_models_are_recovered(model):
    gen = torch.Generator().manual_seed(3)
    source, _, _ = camera_pairs(4, gen, size=128)
    angle = {"translation": 0.0}.get(model, 0.03)
    scale = 1.02 if model in ("similarity", "affine") else 1.0
    c, s = scale * torch.cos(torch.tensor(angle)), scale * torch.sin(torch.tensor(angle))
    truth = torch.tensor([[c, -s, 3.2], [s, c, -2.1], [0, 0, 1]]).expand(4, 3, 3).clone()
    if model == "affine":
        truth[:, 0, 1] += 0.02
    target = warp_image(source, inverse(truth)).image  # target(truth p) = source(p) inside
    mask = torch.zeros(4, 1, 128, 128, dtype=torch.bool)
    mask[..., 8:-8, 8:-8] = True  # target pixels with no source data are not compared
    fit = register_images(target, source, model=model, mask=mask)  # source(M q) = target(q)
    assert (corner_error(fit.matrix, inverse(truth), 128) < 0.1).all()


def test_normalized_loss_is_invariant_to_brightness_and_contrast():
    gen = torch.Generator().manual_seed(4)
    source, target, truth = camera_pairs(4, gen, size=128, move=4.0)
    changed = 0.6 * target + 0.25
    ncc = register_images(source, changed, loss="ncc")
    plain = register_images(source, target, loss="ncc")
    assert torch.allclose(ncc.matrix, plain.matrix, atol=1e-3)
    assert (corner_error(ncc.matrix, truth, 128) < 0.1).all()
    assert (ncc.loss < 1e-2).all()  # 1 - ZNCC
    ssd = register_images(source, changed, loss="ssd")
    assert corner_error(ssd.matrix, truth, 128).mean() > corner_error(ncc.matrix, truth,
                                                                       128).mean()


def test_pixels_leaving_the_image_and_masked_pixels_do_not_count():
    gen = torch.Generator().manual_seed(5)
    source, _, _ = camera_pairs(2, gen, size=128)
    truth = torch.tensor([[1.0, 0, 14.3], [0, 1.0, -9.6], [0, 0, 1]]).expand(2, 3, 3)
    target = warp_image(source, inverse(truth)).image  # the target has a black border
    mask = torch.ones(2, 1, 128, 128, dtype=torch.bool)
    mask[..., :12, :] = False  # source rows whose target has no data (y < 9.6)
    mask[..., :, 113:] = False  # columns that leave the target (x > 127 - 14.3)
    # corrupt the source where the mask excludes it: no effect on the fit
    corrupted = source.clone()
    corrupted[..., :12, :] = torch.rand(2, 1, 12, 128, generator=gen)
    fit = register_images(corrupted, target, mask=mask, model="translation")
    assert (corner_error(fit.matrix, truth, 128) < 0.05).all()


@pytest.mark.slow
def test_adam_optimizer_improves_and_agrees():
    gen = torch.Generator().manual_seed(6)
    source, target, truth = camera_pairs(2, gen, size=64, move=1.0)
    fit = register_images(source, target, model="homography", optimizer="adam", levels=2,
                          iterations=[150, 150], lr=2e-3)
    assert (fit.loss < fit.history[0]).all()
    assert corner_error(fit.matrix, truth, 64).median() < 0.3


def test_errors_name_the_argument():
    img = torch.rand(1, 1, 16, 16)
    with pytest.raises(ValueError, match="model"):
        register_images(img, img, model="projective")
    with pytest.raises(ValueError, match="loss"):
        register_images(img, img, loss="mi")
    with pytest.raises(ValueError, match="optimizer"):
        register_images(img, img, optimizer="sgd")
    with pytest.raises(ValueError, match="levels"):
        register_images(img, img, levels=0)
    with pytest.raises(ValueError, match="iterations"):
        register_images(img, img, iterations=[3, 3])
    with pytest.raises(ShapeError, match="target"):
        register_images(img, torch.rand(1, 2, 16, 16))
    with pytest.raises(ShapeError, match="source"):
        register_images(torch.rand(16, 16), img)
    with pytest.raises(TypeError, match="target"):
        register_images(img, img.double())
    with pytest.raises(ShapeError, match="mask"):
        register_images(img, img, mask=torch.ones(1, 1, 8, 8, dtype=torch.bool))
    with pytest.raises(ShapeError, match="matrix"):
        warp_image(img, torch.eye(2))
    with pytest.raises(TypeError, match="matrix"):
        warp_image(img, torch.eye(3, dtype=torch.float64))


def test_y_up_convention_is_the_documented_flip():
    # flipping both images upside down is the change of frame y -> H - 1 - y: F M F
    gen = torch.Generator().manual_seed(7)
    source, target, _ = camera_pairs(2, gen, size=64, move=2.0, dtype=torch.float64)
    fit = register_images(source, target)
    flipped = register_images(source.flip(-2), target.flip(-2))
    f = torch.tensor([[1.0, 0, 0], [0, -1.0, 63.0], [0, 0, 1.0]], dtype=torch.float64)
    expected = f @ fit.matrix @ f
    assert torch.allclose(flipped.matrix, expected / expected[:, 2:, 2:], atol=1e-4)


def test_empty_batch_gives_empty_results():
    out = register_images(torch.zeros(0, 1, 32, 32), torch.zeros(0, 1, 32, 32))
    assert out.matrix.shape == (0, 3, 3) and out.loss.shape == (0,)
    assert warp_image(torch.zeros(0, 2, 8, 8), torch.zeros(0, 3, 3)).image.shape == (0, 2, 8, 8)


# ------------------------------------------------------------------ contract regressions -----


def blobs(b, size, gen, dtype=torch.float64):
    yy, xx = torch.meshgrid(torch.arange(size, dtype=dtype), torch.arange(size, dtype=dtype),
                            indexing="ij")
    c = (0.3 + 0.4 * torch.rand(b, 2, 1, 1, generator=gen, dtype=dtype)) * (size - 1)
    return torch.exp(-((xx - c[:, 0]) ** 2 + (yy - c[:, 1]) ** 2) / (0.1 * size * size))[:, None]


def shifted(image, dx, dy):
    shift = torch.tensor([[1.0, 0, dx], [0, 1.0, dy], [0, 0, 1.0]], dtype=image.dtype)
    return warp_image(image, torch.linalg.inv(shift)).image


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16], ids=["float16", "bfloat16"])
def test_low_precision_warp_and_registration_run_in_float32(low):
    # bfloat16 sample points were off by a pixel at the border (0.13 error); float16
    # registration raised (no LU kernel)
    gen = torch.Generator().manual_seed(23)
    image = blobs(2, 16, gen, torch.float32).to(low)
    m = torch.tensor([[1.0, 0.02, 0.7], [-0.03, 1.0, -0.4], [1e-3, 0.0, 1.0]]).to(low)
    out = warp_image(image, m.expand(2, 3, 3))
    ref = warp_image(image.float(), m.float().expand(2, 3, 3))
    assert out.image.dtype == low and torch.equal(out.valid, ref.valid)
    assert_close(out.image.float(), ref.image.to(low).float())
    target = shifted(image.float(), 0.5, -0.3).to(low)
    fit = register_images(image, target, "translation", levels=1, iterations=5)
    ref_fit = register_images(image.float(), target.float(), "translation", levels=1,
                              iterations=5)
    assert fit.matrix.dtype == low and fit.loss.dtype == low
    assert_close(fit.matrix.float(), ref_fit.matrix.to(low).float())


def test_ncc_loss_has_no_cancellation_in_float32():
    # 1 - ZNCC was computed as 1 - cov / sqrt(var var): one ulp of 1 (6e-8) in a 1e-6 loss
    gen = torch.Generator().manual_seed(24)
    source = blobs(2, 16, gen)
    target = 3 * shifted(source, 0.004, 0.003) + 1  # gain and offset: ncc ignores them
    want = register_images(source, target, "translation", levels=1, iterations=0,
                           loss="ncc").loss
    got = register_images(source.float(), target.float(), "translation", levels=1,
                          iterations=0, loss="ncc").loss
    assert bool((want > 1e-8).all()) and bool((want < 1e-5).all())
    assert_close(got.double(), want, rtol=1e-3, atol=0.0)


def test_nan_pixel_gives_nan_matrix_not_convergence():
    # a NaN step was replaced by no step: the matrix stayed finite and "converged"
    gen = torch.Generator().manual_seed(25)
    source = blobs(2, 16, gen)
    target = shifted(source, 0.5, 0.2)
    source[0, 0, 5, 6] = float("nan")
    fit = register_images(source, target, "translation", levels=1, iterations=5)
    assert torch.isnan(fit.matrix[0]).all() and not bool(fit.converged[0])
    assert_close(fit.matrix[1, :2, 2], torch.tensor([0.5, 0.2], dtype=torch.float64),
                 atol=2e-2, rtol=0)


def test_adam_registration_does_not_depend_on_intensity_units():
    # Adam's absolute eps (1e-8) stalled the ssd descent for intensities ~1e-4 (gradients
    # ~1e-9): the matrix moved 100x less than for the same images in [0, 1]
    gen = torch.Generator().manual_seed(26)
    source = blobs(2, 16, gen)
    target = shifted(source, 0.6, -0.4)
    kwargs = {"model": "translation", "levels": 1, "iterations": 20, "optimizer": "adam",
              "lr": 1e-2}
    ref = register_images(source, target, **kwargs)
    for s in (1e-4, 1e4):
        fit = register_images(source * s, target * s, **kwargs)
        assert_close(fit.matrix, ref.matrix, rtol=1e-9, atol=1e-12)
        assert_close(fit.loss, ref.loss * s * s, rtol=1e-9, atol=0.0)
    assert bool(((ref.matrix[:, :2, 2] - torch.tensor([0.6, -0.4], dtype=torch.float64)).abs()
                 < (torch.tensor([0.6, 0.4], dtype=torch.float64))).all())  # it moved closer
