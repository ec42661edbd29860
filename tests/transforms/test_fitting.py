"""Tests for torchgeo_cg.transforms.fitting: gradient-descent fitting and HomographyModel."""

from __future__ import annotations

import inspect

import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

import torchgeo_cg.transforms.parametrization as parametrization
from torchgeo_cg.core.check import ShapeError
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.transforms import (
    HomographyModel,
    LossOptions,
    SolverOptions,
    find_affine,
    find_euclidean,
    find_homography_dlt,
    find_similarity,
    find_translation,
    fit_transform,
    matrix_to_parameters,
    parameters_to_matrix,
    report_shapes,
    reprojection_error,
    transform_points,
)


def random_problem(batch, n, gen, noise=0.0, dtype=torch.float64):
    src = torch.rand(batch, n, 2, generator=gen, dtype=dtype) * 200
    h = torch.eye(3, dtype=dtype) + 0.1 * torch.randn(batch, 3, 3, generator=gen, dtype=dtype)
    h[:, 2, :2] *= 0.003
    h[:, :2, 2] *= 100
    h = h / h[:, 2:, 2:]
    dst = transform_points(h, src)
    if noise:
        dst = dst + noise * torch.randn(dst.shape, generator=gen, dtype=dtype)
    return src, dst, h


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


# ------------------------------------------------------------------ quality targets


@pytest.fixture(scope="module")
def noisy_4096():
    previous = torch.get_num_threads()
    torch.set_num_threads(1)  # module scope runs before the autouse one_thread fixture
    gen = torch.Generator().manual_seed(0)
    src, dst, _ = random_problem(4096, 8, gen, noise=0.5, dtype=torch.float32)
    dlt_cost = reprojection_error(find_homography_dlt(src, dst).matrix, src, dst)
    torch.set_num_threads(previous)
    return src, dst, dlt_cost


@pytest.mark.parametrize("optimizer,steps", [("adam", 200), ("lm", 10)])
def test_4096_noisy_problems_reach_closed_form_cost(noisy_4096, optimizer, steps):
    src, dst, dlt_cost = noisy_4096
    fit = fit_transform(src, dst, solver=SolverOptions(optimizer, steps=steps))
    assert fit.history.shape[0] <= steps + 1
    cost = reprojection_error(fit.matrix, src, dst)
    assert_close(fit.loss, cost, rtol=1e-4, atol=1e-6)
    within = (cost <= 1.01 * dlt_cost).float().mean()
    assert within >= 0.99, within


@pytest.mark.parametrize("parametrization", ["entries", "corners", "sl3"])
def test_report_shapes_recovered_by_every_parametrization(parametrization):
    shapes = report_shapes(dtype=torch.float64)
    src = shapes.start.expand(8, -1, -1)
    # sl3 from the identity needs ~18 LM iterations for F's R(-135°)
    steps = 30 if parametrization == "sl3" else 10
    fit = fit_transform(src, shapes.targets, "homography", parametrization=parametrization,
                        solver=SolverOptions("lm", steps=steps))
    assert (fit.matrix - shapes.matrices).abs().max() < 1e-6
    affine = fit_transform(src[:7], shapes.targets[:7], "affine", solver=SolverOptions("lm"))
    assert (affine.matrix - shapes.matrices[:7]).abs().max() < 1e-6


def test_report_shapes_trs_model_recovers_a_to_f():
    shapes = report_shapes(dtype=torch.float64)
    src = shapes.start.expand(6, -1, -1)
    fit = fit_transform(src, shapes.targets[:6], "trs", solver=SolverOptions("lm", steps=30))
    assert (fit.matrix - shapes.matrices[:6]).abs().max() < 1e-6


def test_raw_entries_in_pixels_do_not_converge_but_normalized_do():
    # why parametrisations matter: plain gradient descent on raw entries in pixel units stalls
    gen = torch.Generator().manual_seed(1)
    src, dst, h = random_problem(16, 8, gen, noise=0.5)
    theta = torch.zeros(16, 8, dtype=torch.float64, requires_grad=True)
    opt = torch.optim.Adam([theta], lr=0.05)
    eye = torch.eye(3, dtype=torch.float64).flatten()[:8]
    for _ in range(200):
        opt.zero_grad()
        m = torch.cat([theta + eye, torch.ones(16, 1, dtype=torch.float64)], -1).unflatten(-1,
                                                                                          (3, 3))
        loss = reprojection_error(m, src, dst).sum()
        loss.backward()
        opt.step()
    raw = reprojection_error(m.detach(), src, dst)
    ours = fit_transform(src, dst, solver=SolverOptions("adam", steps=200)).loss
    assert (raw > 10 * ours).float().mean() > 0.9


# ------------------------------------------------------------------ models vs closed forms


@pytest.mark.parametrize("model,closed_form", [
    ("affine", find_affine), ("similarity", find_similarity),
    ("euclidean", find_euclidean), ("translation", find_translation),
])
def test_models_reach_their_closed_form_optimum(model, closed_form, device, dtype):
    gen = torch.Generator().manual_seed(2)
    src, dst, _ = random_problem(8, 10, gen, noise=2.0)
    src, dst = src.to(device, dtype), dst.to(device, dtype)
    fit = fit_transform(src, dst, model=model, solver=SolverOptions("lm", steps=30, tol=0.0))
    assert fit.matrix.dtype == dtype and fit.matrix.device.type == device.type
    assert fit.params.shape == (8, parametrization.MODELS[model])
    # translations are ~100 px: absolute tolerances follow
    tols = {"rtol": 1e-7, "atol": 1e-6} if dtype == torch.float64 else {"rtol": 1e-4,
                                                                          "atol": 1e-2}
    assert_close(fit.matrix, closed_form(src, dst).matrix, **tols)


@pytest.mark.parametrize("optimizer", ["adam", "lbfgs", "lm"])
def test_every_optimizer_improves_and_records_history(optimizer):
    gen = torch.Generator().manual_seed(3)
    src, dst, _ = random_problem(4, 8, gen, noise=0.5)
    fit = fit_transform(src, dst, solver=SolverOptions(optimizer))
    assert fit.history.shape[1:] == (4,)
    assert (fit.history[-1] < 0.01 * fit.history[0]).all()
    assert_close(fit.history[-1], fit.loss)


def test_early_stopping_on_exact_data():
    gen = torch.Generator().manual_seed(4)
    src, dst, h = random_problem(3, 8, gen)
    lm = fit_transform(src, dst, solver=SolverOptions("lm", steps=50))
    assert lm.history.shape[0] < 15
    assert_close(lm.matrix, h, rtol=1e-9, atol=1e-9)
    adam = fit_transform(src, dst, solver=SolverOptions("adam", steps=2000, patience=10))
    assert adam.history.shape[0] < 2001


def test_symmetric_loss():
    gen = torch.Generator().manual_seed(5)
    src, dst, h = random_problem(4, 8, gen)
    exact = fit_transform(src, dst, loss=LossOptions(symmetric=True))
    assert_close(exact.matrix, h, rtol=1e-8, atol=1e-8)
    src, dst, _ = random_problem(16, 8, gen, noise=1.0)
    sym = fit_transform(src, dst, solver=SolverOptions(steps=30), loss=LossOptions(symmetric=True))
    one_way = fit_transform(src, dst, solver=SolverOptions(steps=30))
    assert_close(sym.loss, reprojection_error(sym.matrix, src, dst, symmetric=True))
    sym_cost = reprojection_error(sym.matrix, src, dst, symmetric=True)
    other = reprojection_error(one_way.matrix, src, dst, symmetric=True)
    # the symmetric fit is optimal in normalized units; in pixels it is at least close
    assert (sym_cost <= other * 1.05).all()


def test_weights_match_point_removal():
    gen = torch.Generator().manual_seed(6)
    src, dst, _ = random_problem(2, 9, gen, noise=1.0)
    w = torch.ones(2, 9, dtype=torch.float64)
    w[:, 4] = 0
    keep = [i for i in range(9) if i != 4]
    a = fit_transform(src, dst, weights=w, solver=SolverOptions(steps=20)).matrix
    b = fit_transform(src[:, keep], dst[:, keep], solver=SolverOptions(steps=20)).matrix
    assert_close(a, b, rtol=1e-8, atol=1e-8)


def test_init_is_used():
    gen = torch.Generator().manual_seed(7)
    src, dst, h = random_problem(2, 8, gen)
    for par in parametrization.PARAMETRIZATIONS:
        fit = fit_transform(src, dst, init=h, parametrization=par,
                            solver=SolverOptions("adam", steps=0))
        assert_close(fit.matrix, h, rtol=1e-9, atol=1e-9)
        assert fit.history.shape == (1, 2)
        # from a perturbed start, every parametrization (sl3: Ĥ = base·exp) reaches h
        start = h.clone()
        start[:, :2, 2] += 3.0
        fit = fit_transform(src, dst, init=start, parametrization=par,
                            solver=SolverOptions("lm", steps=20))
        assert_close(fit.matrix, h, rtol=1e-8, atol=1e-8)


# ------------------------------------------------------------------ gradients


@pytest.mark.parametrize("parametrization", ["entries", "corners"])
def test_gradcheck_one_lm_step(parametrization):
    gen = torch.Generator().manual_seed(8)
    src, dst, _ = random_problem(2, 6, gen, noise=0.5)
    src.requires_grad_(True)
    dst.requires_grad_(True)

    def fn(s, d):
        return fit_transform(s, d, parametrization=parametrization,
                             solver=SolverOptions("lm", steps=1)).matrix

    assert torch.autograd.gradcheck(fn, (src, dst), eps=1e-6, atol=1e-5, rtol=1e-4)


def test_gradcheck_lm_euclidean_nonlinear_parametrization():
    gen = torch.Generator().manual_seed(9)
    src, dst, _ = random_problem(1, 5, gen, noise=0.5)
    dst.requires_grad_(True)

    def fn(d):
        return fit_transform(src, d, model="euclidean", solver=SolverOptions("lm", steps=2)).matrix

    assert torch.autograd.gradcheck(fn, (dst,), eps=1e-6, atol=1e-5, rtol=1e-4)


def test_implicit_gradient_of_adam_matches_unrolled_lm_at_exact_optimum():
    gen = torch.Generator().manual_seed(10)
    src, dst, _ = random_problem(2, 8, gen)
    grads = []
    for optimizer in ("lm", "lbfgs", "adam"):
        d = dst.clone().requires_grad_(True)
        fit = fit_transform(src, d,
                            solver=SolverOptions(optimizer, steps=20 if optimizer == "lm" else 300))
        (fit.matrix * torch.arange(9, dtype=torch.float64).view(3, 3)).sum().backward()
        grads.append(d.grad)
    assert_close(grads[1], grads[0], rtol=1e-4, atol=1e-6)
    assert_close(grads[2], grads[0], rtol=1e-3, atol=1e-5)


def test_degenerate_input_no_nan_forward_or_backward():
    src = torch.tensor([[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0], [4.0, 4.0]]],
                       dtype=torch.float64, requires_grad=True)
    dst = (src.detach() * 2).requires_grad_(True)
    for optimizer in ("lm", "adam"):
        fit = fit_transform(src, dst, solver=SolverOptions(optimizer, steps=5))
        assert torch.isfinite(fit.matrix).all() and torch.isfinite(fit.loss).all()
        fit.matrix.sum().backward()
        assert torch.isfinite(src.grad).all() and torch.isfinite(dst.grad).all()


@given(
    st.lists(st.floats(-0.3, 0.3), min_size=6, max_size=6),
    st.floats(-2e-3, 2e-3),
    st.floats(-2e-3, 2e-3),
    st.integers(0, 2**16),
)
def test_property_fit_recovers_m(lin, g, h, seed):
    gen = torch.Generator().manual_seed(seed)
    m = torch.tensor([[1 + lin[0], lin[1], 50 * lin[2]], [lin[3], 1 + lin[4], 50 * lin[5]],
                      [g, h, 1.0]], dtype=torch.float64)
    src = torch.tensor([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]],
                       dtype=torch.float64)
    src = torch.cat([src, torch.rand(4, 2, generator=gen, dtype=torch.float64) * 100])
    fit = fit_transform(src, transform_points(m, src), solver=SolverOptions("lm", steps=20))
    assert_close(fit.matrix, m, rtol=1e-8, atol=1e-8)


# ------------------------------------------------------------------ parametrizations


@pytest.mark.parametrize("model", list(parametrization.MODELS))
def test_parameter_round_trip(model):
    gen = torch.Generator().manual_seed(11)
    params = 0.2 * torch.randn(5, parametrization.MODELS[model], generator=gen, dtype=torch.float64)
    pars = parametrization.PARAMETRIZATIONS[:2] if model == "homography" else ("entries",)
    for par in pars:
        m = parameters_to_matrix(params, model, par)
        assert_close(matrix_to_parameters(m, model, par), params)


def test_parametrizations_hand_values():
    # corners: moving every corner by (1, 0) is T(1, 0)
    m = parameters_to_matrix(torch.tensor([1.0, 0.0] * 4, dtype=torch.float64),
                             parametrization="corners")
    assert_close(m, torch.tensor([[1.0, 0, 1], [0, 1, 0], [0, 0, 1]], dtype=torch.float64))
    # sl3: the translation generators exponentiate to a translation; det is 1
    m = parameters_to_matrix(torch.tensor([2.0, 3.0, 0, 0, 0, 0, 0, 0], dtype=torch.float64),
                             parametrization="sl3")
    assert_close(m, torch.tensor([[1.0, 0, 2], [0, 1, 3], [0, 0, 1]], dtype=torch.float64))
    m = parameters_to_matrix(torch.rand(8, dtype=torch.float64), parametrization="sl3")
    assert_close(torch.linalg.det(m), torch.tensor(1.0, dtype=torch.float64))
    # trs: T(1, 2)·R(90°)·S(e, 1)
    m = parameters_to_matrix(torch.tensor([1.0, 2.0, torch.pi / 2, 1.0, 0.0],
                                          dtype=torch.float64), "trs")
    e = torch.e
    assert_close(m, torch.tensor([[0.0, -1, 1], [e, 0, 2], [0, 0, 1]], dtype=torch.float64),
                 atol=1e-12, rtol=0)


# ------------------------------------------------------------------ module


def test_module_equals_function_and_defaults_match():
    sig_fn = inspect.signature(fit_transform).parameters
    sig_mod = inspect.signature(HomographyModel).parameters
    assert sig_fn["parametrization"].default == sig_mod["parametrization"].default
    gen = torch.Generator().manual_seed(12)
    src, dst, _ = random_problem(3, 8, gen, noise=0.5)
    for par in parametrization.PARAMETRIZATIONS:
        fit = fit_transform(src, dst, parametrization=par, solver=SolverOptions(steps=20))
        model = HomographyModel(par, batch_shape=(3,), src=src, dst=dst)
        with torch.no_grad():
            model.params.copy_(fit.params)
        if par == "sl3":  # sl3 from the identity: base is None in both
            assert model.base is None
        assert_close(model.matrix(), fit.matrix)
        assert_close(model(src), transform_points(fit.matrix, src))


def test_module_trains_and_moves():
    gen = torch.Generator().manual_seed(13)
    src, dst, h = random_problem(2, 8, gen)
    model = HomographyModel("corners", batch_shape=(2,), src=src, dst=dst)
    opt = torch.optim.Adam(model.parameters(), lr=0.05)
    first = None
    for _ in range(100):
        opt.zero_grad()
        loss = (model(src) - dst).square().mean()
        first = float(loss.detach()) if first is None else first
        loss.backward()
        opt.step()
    assert float(loss.detach()) < 0.01 * first
    assert {n for n, _ in model.named_buffers()} == {"src_transform", "dst_transform"}
    assert model.state_dict().keys() == {"params"}
    model = model.to(torch.float32)
    assert model.src_transform.dtype == torch.float32 and model.params.dtype == torch.float32
    init = HomographyModel("sl3", batch_shape=(2,), init=h)
    assert_close(init.matrix().detach(), h)
    assert init.base.shape == (2, 3, 3)


def test_progress_bar(capsys):
    gen = torch.Generator().manual_seed(14)
    src, dst, _ = random_problem(1, 8, gen)
    fit_transform(src, dst, solver=SolverOptions("lm", steps=3, progress=True))
    assert "fit homography (lm)" in capsys.readouterr().err


# ------------------------------------------------------------------ errors


def test_errors():
    pts = torch.rand(6, 2)
    with pytest.raises(ValueError, match="model"):
        fit_transform(pts, pts, model="projective")
    with pytest.raises(ValueError, match="optimizer"):
        fit_transform(pts, pts, solver=SolverOptions("sgd"))
    with pytest.raises(ValueError, match="parametrization"):
        fit_transform(pts, pts, parametrization="quaternion")
    with pytest.raises(ValueError, match="loss"):
        fit_transform(pts, pts, loss=LossOptions("l1"))
    with pytest.raises(ValueError, match="steps"):
        fit_transform(pts, pts, solver=SolverOptions(steps=-1))
    with pytest.raises(ShapeError, match="init"):
        fit_transform(pts, pts, init=torch.eye(2))
    with pytest.raises(ShapeError, match="dst"):
        fit_transform(pts, torch.rand(5, 2))
    with pytest.raises(ShapeError, match="params"):
        parameters_to_matrix(torch.zeros(3), "affine")
    with pytest.raises(TypeError, match="params"):
        parameters_to_matrix(torch.zeros(8, dtype=torch.long))
    with pytest.raises(ShapeError, match="matrix"):
        matrix_to_parameters(torch.zeros(2, 2))
    with pytest.raises(ValueError, match="parametrization"):
        HomographyModel("euler")
    with pytest.raises(ShapeError, match="src"):
        HomographyModel(batch_shape=(2,), src=torch.rand(3, 5, 2))
    with pytest.raises(ShapeError, match="points"):
        HomographyModel()(torch.rand(5, 3))


# ------------------------------------------------------------------ NaN and degenerate input


def test_nan_weight_propagates_through_fit_transform():
    gen = torch.Generator().manual_seed(30)
    src, dst, _ = random_problem(2, 8, gen)
    w = torch.ones(2, 8, dtype=torch.float64)
    w[0, 3] = float("nan")
    fit = fit_transform(src, dst, weights=w)
    assert torch.isnan(fit.matrix[0]).any() and torch.isnan(fit.loss[0])
    assert torch.isfinite(fit.matrix[1]).all()


def test_zero_points_raise_shape_error_and_empty_batch_is_empty():
    empty = torch.zeros(2, 0, 2, dtype=torch.float64)
    with pytest.raises(ShapeError, match="src.*N >= 1"):
        fit_transform(empty, empty)
    none = torch.zeros(0, 6, 2, dtype=torch.float64)
    fit = fit_transform(none, none)
    assert fit.matrix.shape == (0, 3, 3) and fit.loss.shape == (0,)


def test_homography_model_mixed_dtypes_name_both_arguments():
    with pytest.raises(TypeError, match="dst.*src"):
        HomographyModel(src=torch.rand(5, 2, dtype=torch.float64), dst=torch.rand(5, 2))


@pytest.mark.parametrize("model", sorted(parametrization.MODELS))
def test_matrix_to_parameters_of_nan_is_nan(model):
    m = torch.eye(3, dtype=torch.float64)
    m[2, 2] = float("nan")  # a NaN h33 must not be replaced by 1
    assert torch.isnan(matrix_to_parameters(m, model)).any()
    assert torch.isnan(matrix_to_parameters(torch.full((3, 3), float("nan")), "homography",
                                            "sl3")).all()
    assert (matrix_to_parameters(torch.eye(3), "homography", "sl3") == 0).all()


# ------------------------------------------------------------------ contract regressions -----


@pytest.mark.parametrize("model", ["affine", "similarity", "euclidean", "translation", "trs"])
def test_matrix_to_parameters_nan_anywhere_gives_nan(model):
    # a NaN in an entry the model ignores (here the perspective row) was dropped
    m = torch.eye(3, dtype=torch.float64).repeat(2, 1, 1)
    m[0, 2, 0] = float("nan")
    m[1, 0, 2] = 3.0
    p = matrix_to_parameters(m, model)
    assert torch.isnan(p[0]).all()
    assert_close(parameters_to_matrix(p[1], model), m[1])  # the clean one is exact


@pytest.mark.parametrize("optimizer", ["lm", "lbfgs", "adam"])
@pytest.mark.parametrize("model", ["similarity", "affine", "translation"])
def test_fit_transform_empty_batch(model, optimizer):
    # lm: the constant parameter Jacobian was taken at theta[:1] (IndexError for B = 0);
    # lbfgs: torch's L-BFGS raised on an empty parameter
    empty = torch.zeros(0, 6, 2, dtype=torch.float64)
    fit = fit_transform(empty, empty, model, solver=SolverOptions(optimizer, steps=2))
    assert fit.matrix.shape == (0, 3, 3) and fit.params.shape == (0, parametrization.MODELS[model])


def test_parameters_to_matrix_sl3_base_dtype_and_low_precision():
    params = 0.1 * torch.randn(2, 8, generator=torch.Generator().manual_seed(20))
    with pytest.raises(TypeError, match="base.*float64.*params.*float32"):
        parameters_to_matrix(params, "homography", "sl3", torch.eye(3, dtype=torch.float64))
    # matrix_exp has no float16 kernel on the CPU: computed in float32, returned in float16
    out = parameters_to_matrix(params.half(), "homography", "sl3")
    p = params.half().float().unbind(-1)
    zero = torch.zeros_like(p[0])
    gen = torch.stack([p[4] + p[5], p[2], p[0], p[3], p[5] - p[4], p[1], p[6], p[7],
                       -2 * p[5] + zero], -1).unflatten(-1, (3, 3))  # documented generators
    ref = torch.linalg.matrix_exp(gen)
    assert out.dtype == torch.float16
    assert_close(out.float(), ref, rtol=2e-3, atol=2e-3)


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16], ids=["float16", "bfloat16"])
def test_fit_transform_low_precision_is_fitted_in_float32(low):
    # raised "value cannot be converted to type c10::Half without overflow" (LM damping)
    gen = torch.Generator().manual_seed(21)
    src, dst, _ = random_problem(2, 8, gen, noise=0.1, dtype=torch.float32)
    src, dst = src.to(low), dst.to(low)
    fit = fit_transform(src, dst, "homography", solver=SolverOptions("lm", steps=4))
    ref = fit_transform(src.float(), dst.float(), "homography", solver=SolverOptions("lm", steps=4))
    assert fit.matrix.dtype == low and fit.history.shape == ref.history.shape
    assert_close(fit.matrix.float(), ref.matrix.to(low).float())


def test_homography_model_of_zero_points_names_the_argument():
    # the Hartley normalization of zero points was 0 / 0: a NaN matrix
    with pytest.raises(ShapeError, match="src.*N >= 1"):
        HomographyModel(src=torch.zeros(0, 2))
    with pytest.raises(ShapeError, match="dst.*N >= 1"):
        HomographyModel(batch_shape=(2,), src=torch.ones(2, 3, 2), dst=torch.zeros(2, 0, 2))


def test_option_bundles_are_keyword_only_validated_and_reach_the_fit():
    import dataclasses
    import inspect

    params = inspect.signature(fit_transform).parameters
    assert [n for n, p in params.items() if p.kind is not inspect.Parameter.KEYWORD_ONLY] == [
        "src", "dst", "model"]
    assert params["solver"].default == SolverOptions() and params["loss"].default == LossOptions()
    assert len(params) == 8  # was 15 loose arguments
    for bad, name in ((dict(optimizer="sgd"), "optimizer"), (dict(steps=-1), "steps"),
                      (dict(tol=float("nan")), "tol")):
        with pytest.raises(ValueError, match=name):
            SolverOptions(**bad)
    for bad, name in ((dict(loss="symmetric"), "loss"), (dict(scale=0.0), "scale")):
        with pytest.raises(ValueError, match=name):
            LossOptions(**bad)
    with pytest.raises(dataclasses.FrozenInstanceError):
        SolverOptions().steps = 3
    src = torch.tensor([[0.0, 0], [4, 0], [4, 5], [0, 5], [2, 1]], dtype=torch.float64)
    with pytest.raises(TypeError, match="loss: expected a LossOptions"):
        fit_transform(src, src, loss="l2")
    with pytest.raises(TypeError, match="optimizer"):  # the loose keyword is gone
        fit_transform(src, src, optimizer="lm")
    fit = fit_transform(src, src + 1.0, "translation", solver=SolverOptions("adam", steps=7))
    assert fit.history.shape[0] <= 8  # the solver bundle's step limit is used
