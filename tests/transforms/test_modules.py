"""The thin modules equal their functions, with the same defaults, and follow .to()."""

import inspect

import torch

from torchgeo_cg.transforms import (
    HomogeneousTransform,
    TRSTransform,
    compose_trs,
    homography,
    transform_points,
)


def test_trs_module_equals_function(dtype, device):
    kw = {"dtype": dtype, "device": device}
    offset, angle, scale = (
        torch.tensor([4.0, 14.0], **kw),
        torch.tensor(-135.0, **kw),
        torch.tensor([0.4, 0.8], **kw),
    )
    pts = torch.randn(10, 2, **kw)
    module = TRSTransform(offset, angle, scale)
    torch.testing.assert_close(
        module(pts), transform_points(compose_trs(offset, angle, scale), pts)
    )
    assert {n for n, _ in module.named_parameters()} == {"offset", "angle", "scale"}


def test_trs_module_defaults_match_function():
    fn = inspect.signature(compose_trs).parameters
    mod = inspect.signature(TRSTransform.__init__).parameters
    assert mod["degrees"].default == fn["degrees"].default
    fn_tp = inspect.signature(transform_points).parameters
    assert (
        inspect.signature(HomogeneousTransform.__init__).parameters["eps"].default
        == fn_tp["eps"].default
    )


def test_trs_module_fits_by_gradient_descent():
    """A learnable T·S·R recovers a known transform from point pairs."""
    torch.manual_seed(0)
    src = torch.randn(32, 2, dtype=torch.float64)
    target = compose_trs(
        torch.tensor([2.0, -1.0], dtype=torch.float64),
        torch.tensor(40.0, dtype=torch.float64),
        torch.tensor(1.5, dtype=torch.float64),
    )
    dst = transform_points(target, src)
    module = TRSTransform(
        torch.zeros(2, dtype=torch.float64),
        torch.tensor(0.0, dtype=torch.float64),
        torch.tensor(1.0, dtype=torch.float64),
    )
    opt = torch.optim.LBFGS(
        module.parameters(),
        max_iter=500,
        line_search_fn="strong_wolfe",
        tolerance_grad=1e-14,
        tolerance_change=1e-16,
    )

    def closure():
        opt.zero_grad()
        loss = (module(src) - dst).pow(2).mean()
        loss.backward()
        return loss

    opt.step(closure)
    torch.testing.assert_close(module.matrix().detach(), target, atol=1e-6, rtol=0)


def test_homogeneous_module_to_moves_buffers():
    h = homography(torch.tensor([1.0, 0.1, 0, 0, 1, 0, 0.01, 0]))
    module = HomogeneousTransform(h).to(torch.float64)
    assert module.matrix.dtype == torch.float64
    pts = torch.randn(5, 2, dtype=torch.float64)
    torch.testing.assert_close(module(pts), transform_points(h.double(), pts))
    learn = HomogeneousTransform(h, learnable=True)
    assert [n for n, _ in learn.named_parameters()] == ["matrix"]
