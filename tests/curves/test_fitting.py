"""Least-squares Bezier fitting against numpy lstsq and exact recovery."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.curves import bernstein_basis, bezier, fit_bezier, fit_parameters


def test_exact_recovery_with_known_parameters(device, dtype):
    cp = torch.randn(4, 5, 2, device=device, dtype=dtype)
    t = torch.linspace(0, 1, 30, device=device, dtype=dtype)
    fit = fit_bezier(bezier(cp, t), 4, parametrization="uniform")
    assert fit.control_points.dtype == dtype
    assert_close(fit.control_points, cp, scale=1e3 if dtype == torch.float32 else 10)
    assert fit.rms.max() < (1e-4 if dtype == torch.float32 else 1e-10)


@pytest.mark.parametrize("parametrization", ["uniform", "chord", "centripetal"])
def test_matches_numpy_lstsq(parametrization):
    rng = np.random.default_rng(0)
    points = torch.tensor(rng.standard_normal((3, 25, 2)).cumsum(1))
    fit = fit_bezier(points, 3, parametrization)
    for b in range(3):
        basis = bernstein_basis(fit.t[b], 3).numpy()
        ref = np.linalg.lstsq(basis, points[b].numpy(), rcond=None)[0]
        assert_close(fit.control_points[b], ref)
        assert_close(fit.rms[b], np.sqrt(((basis @ ref - points[b].numpy()) ** 2).sum() / 25))


def test_parameters_by_hand():
    pts = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 3.0]], dtype=torch.float64)
    assert_close(fit_parameters(pts, "uniform"), [0.0, 0.5, 1.0])
    assert_close(fit_parameters(pts, "chord"), [0.0, 0.25, 1.0])
    assert_close(fit_parameters(pts, "centripetal"), [0.0, 1 / (1 + 3**0.5), 1.0])
    same = torch.zeros(4, 2)
    assert_close(fit_parameters(same, "chord"), torch.linspace(0, 1, 4))


def test_gradient_through_fit():
    points = torch.randn(12, 2, dtype=torch.float64, requires_grad=True)
    # Uniform parameters do not depend on the points, so the full derivative is checked.
    assert torch.autograd.gradcheck(lambda p: fit_bezier(p, 3, "uniform").control_points,
                                    (points,))


def test_bad_input():
    with pytest.raises(ShapeError, match=r"degree \+ 1 = 5 points, got 3"):
        fit_bezier(torch.randn(3, 2), 4)
    with pytest.raises(ValueError, match="parametrization"):
        fit_bezier(torch.randn(8, 2), 3, parametrization="arc")
    with pytest.raises(ShapeError, match="at least 2 points"):
        fit_parameters(torch.randn(1, 2))


# --- parameter correction, weights, ragged batches --------------------------------------

def _noisy_stroke(seed: int, m: int = 40):
    gen = torch.Generator().manual_seed(seed)
    cp = torch.rand(4, 2, generator=gen, dtype=torch.float64)
    t = torch.rand(m, generator=gen, dtype=torch.float64).sort().values
    t = (t - t[0]) / (t[-1] - t[0])
    return bernstein_basis(t, 3) @ cp + 0.01 * torch.randn(m, 2, generator=gen,
                                                           dtype=torch.float64)


def test_correction_reaches_the_joint_optimum_of_scipy():
    from scipy.optimize import least_squares

    points = _noisy_stroke(0)
    fit = fit_bezier(points, 3, correct_parameters=True, tol=1e-10, max_iterations=500)
    start = fit_bezier(points, 3)

    def residual(x):
        cp, t = x[:8].reshape(4, 2), np.clip(x[8:], 0, 1)
        return (bernstein_basis(torch.from_numpy(t), 3).numpy() @ cp - points.numpy()).ravel()

    x0 = np.concatenate([start.control_points.numpy().ravel(), start.t.numpy()])
    ref = least_squares(residual, x0, xtol=1e-14, ftol=1e-14, gtol=1e-14)
    ref_rms = np.sqrt((ref.fun**2).sum() / 40)
    assert float(fit.rms) < 0.5 * float(start.rms)
    assert float(fit.rms) <= ref_rms * (1 + 1e-4)
    # first-order optimality in t: the residual is orthogonal to the tangent
    a = bernstein_basis(fit.t, 3) @ fit.control_points - points
    tangent = bernstein_basis(fit.t, 2) @ (3 * (fit.control_points[1:] - fit.control_points[:-1]))
    inner = (fit.t > 0) & (fit.t < 1)
    scale = float(a.norm(dim=-1).max() * tangent.norm(dim=-1).max())
    assert (a * tangent).sum(-1)[inner].abs().max() < 1e-3 * scale


def test_ragged_list_padded_and_loop_agree():
    strokes = [_noisy_stroke(s, m) for s, m in ((1, 12), (2, 30), (3, 7))]
    loop = [fit_bezier(s, 3, correct_parameters=True) for s in strokes]
    listed = fit_bezier(strokes, 3, correct_parameters=True)
    padded = torch.nn.utils.rnn.pad_sequence(strokes, batch_first=True)
    lengths = torch.tensor([12, 30, 7])
    by_lengths = fit_bezier(padded, 3, correct_parameters=True, lengths=lengths)
    nested = fit_bezier(torch.nested.nested_tensor(strokes), 3, correct_parameters=True)
    for fit in (listed, by_lengths, nested):
        assert fit.control_points.shape == (3, 4, 2) and fit.t.shape == (3, 30)
        for b, ref in enumerate(loop):
            assert_close(fit.control_points[b], ref.control_points, scale=1e3)
            assert_close(fit.t[b, : lengths[b]], ref.t, scale=1e3)
            assert_close(fit.rms[b], ref.rms, scale=1e3)
        assert (fit.t[2, 7:] == 0).all()


def test_weights_equal_repeated_and_removed_samples():
    points = _noisy_stroke(4, 20)
    weights = torch.ones(20, dtype=torch.float64)
    weights[3], weights[10] = 0.0, 3.0
    fit = fit_bezier(points, 3, parametrization="uniform", weights=weights)
    t = torch.linspace(0, 1, 20, dtype=torch.float64)
    keep = torch.cat([torch.arange(20)[weights > 0], torch.tensor([10, 10])])
    basis = bernstein_basis(t[keep], 3)
    ref = torch.linalg.lstsq(basis, points[keep]).solution
    assert_close(fit.control_points, ref)
    r2 = ((bernstein_basis(t, 3) @ ref - points) ** 2).sum(-1)
    assert_close(fit.rms, ((weights * r2).sum() / weights.sum()).sqrt())
    with pytest.raises(ValueError, match="weights"):
        fit_bezier(points, 3, weights=-weights)


def test_progress_bar_and_more_errors(capsys):
    fit_bezier(_noisy_stroke(5), 3, correct_parameters=True, progress=True)
    assert "fit_bezier" in capsys.readouterr().err
    with pytest.raises(ShapeError, match="at least degree"):
        fit_bezier([torch.randn(8, 2), torch.randn(3, 2)], 3)
    with pytest.raises(ValueError, match="lengths"):
        fit_bezier(torch.randn(2, 8, 2), 3, lengths=torch.tensor([8, 9]))
    with pytest.raises(ValueError, match="max_iterations"):
        fit_bezier(torch.randn(8, 2), 3, correct_parameters=True, max_iterations=0)


@pytest.mark.grad
def test_gradient_with_corrected_parameters():
    points = _noisy_stroke(6, 10).requires_grad_(True)
    # the corrected t are constants: the gradient at fixed parameters is checked
    t = fit_bezier(points.detach(), 3, correct_parameters=True).t

    def fn(p):
        return fit_bezier(p, 3, correct_parameters=True).control_points

    assert torch.autograd.gradcheck(lambda p: _fixed_t_fit(p, t), (points,))
    torch.testing.assert_close(fn(points), _fixed_t_fit(points, t))


def _fixed_t_fit(points, t):
    basis = bernstein_basis(t, 3)
    return torch.linalg.lstsq(basis, points).solution


@pytest.mark.parametrize("parametrization", ["chord", "centripetal"])
def test_fit_parameters_nan_point_gives_nan(parametrization):
    # a NaN sample must not fall back to clean uniform parameters
    points = torch.rand(6, 2, dtype=torch.float64)
    points[2, 0] = float("nan")
    t = fit_parameters(points, parametrization)
    assert torch.isnan(t).any()
    # coincident samples (total length exactly 0) still fall back to uniform
    flat = fit_parameters(torch.ones(4, 2, dtype=torch.float64), parametrization)
    torch.testing.assert_close(flat, torch.linspace(0, 1, 4, dtype=torch.float64))


# --- contract regressions ----------------------------------------------------------------


def test_nan_point_gives_nan_stroke_and_leaves_the_others():
    """A NaN point crashed the solver (lstsq 'illegal value'); now its stroke is NaN and
    the other strokes equal their own fits."""
    rng = np.random.default_rng(1)
    points = torch.tensor(rng.standard_normal((3, 7, 2)))
    clean = fit_bezier(points, 2)
    points[1, 3, 0] = float("nan")
    for extra in ({}, {"correct_parameters": True, "max_iterations": 3},
                  {"lengths": torch.tensor([7, 6, 5])}):
        fit = fit_bezier(points, 2, **extra)
        alone = fit_bezier(points[[0, 2]], 2, **{k: v[[0, 2]] if k == "lengths" else v
                                                 for k, v in extra.items()})
        assert fit.control_points[1].isnan().all() and fit.rms[1].isnan()
        assert fit.t[1].isnan().any()  # chord parameters: NaN stays NaN (was uniform)
        assert_close(fit.control_points[[0, 2]], alone.control_points)
    assert_close(fit_bezier(points[[0, 2]], 2).control_points, clean.control_points[[0, 2]])


def test_nan_weight_gives_nan_and_padded_nan_is_ignored():
    points = torch.tensor(np.random.default_rng(2).standard_normal((2, 6, 2)))
    weights = torch.ones(2, 6, dtype=torch.float64)
    weights[0, 2] = float("nan")
    fit = fit_bezier(points, 2, weights=weights)
    assert fit.control_points[0].isnan().all() and fit.rms[0].isnan()
    assert_close(fit.control_points[1], fit_bezier(points[1], 2).control_points)
    padded = points.clone()
    padded[1, 4:] = float("nan")  # rows beyond lengths[1] = 4 are padding
    weights[0, 2] = 1.0
    weights[1, 5] = float("nan")
    lengths = torch.tensor([6, 4])
    fit = fit_bezier(padded, 2, weights=weights, lengths=lengths)
    ref = fit_bezier(points[1, :4], 2)
    assert_close(fit.control_points[1], ref.control_points)
    assert_close(fit.rms[1], ref.rms)


def test_coincident_parameters_give_the_minimum_norm_solution():
    """A repeated sample makes two chord parameters equal, so the normal equations are
    singular; the fallback (lstsq, gelsy driver) returned a non-solution (rms 0.82 where
    an exact fit exists). Reference: numpy's SVD lstsq (minimum norm)."""
    points = torch.tensor([[0.0, 0.0], [0.0, 0.0], [1.0, 1.0], [2.0, 0.0]], dtype=torch.float64)
    batch = torch.stack([points, points.flip(0)])
    for pts in (points, batch):
        fit = fit_bezier(pts, 3)
        for cp, t, p in zip(fit.control_points.reshape(-1, 4, 2), fit.t.reshape(-1, 4),
                            pts.reshape(-1, 4, 2)):
            basis = bernstein_basis(t, 3).numpy()
            ref = np.linalg.lstsq(basis, p.numpy(), rcond=None)[0]
            assert_close(cp, ref)
        assert fit.rms.max() < 1e-12
