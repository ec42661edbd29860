"""The optimizers of iterative transform fitting: Levenberg-Marquardt (unrolled), Adam and
L-BFGS (detached, with one implicit-gradient Gauss-Newton step), batched per problem.
"""

from __future__ import annotations

import math

import torch
from torch.func import jacrev, vmap

from torchgeo_cg.transforms._objective import Problem, loss_terms, normal_system
from torchgeo_cg.transforms.parametrization import parameters_to_matrix


class ParamFn:
    """θ -> Ĥ for one model, with ``linear`` telling whether d vec(Ĥ)/dθ is constant."""

    def __init__(self, model: str, parametrization: str, base: torch.Tensor | None):
        self.model, self.parametrization, self.base = model, parametrization, base
        self.linear = model in ("affine", "similarity", "translation") or (
            model == "homography" and parametrization == "entries")

    def __call__(self, theta: torch.Tensor, with_base: bool = True) -> torch.Tensor:
        base = self.base if with_base else None
        return parameters_to_matrix(theta, self.model, self.parametrization, base)


def _param_jacobian(fn, theta: torch.Tensor) -> torch.Tensor:
    """d vec(fn(θ)) / dθ, (B, 9, P), batched with torch.func (row-major vec)."""
    jac = vmap(jacrev(lambda t: fn(t[None], with_base=False)[0].flatten()))(theta)
    if fn.base is None:
        return jac
    # d vec(base · E) = base applied to each column block of d vec(E)
    return torch.einsum("bik,bkjp->bijp", fn.base, jac.unflatten(1, (3, 3))).flatten(1, 2)


def spd_solve(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Solve ``a x = b`` for small SPD ``a`` (B, P, P), ``b`` (B, P) by Cholesky, batch last.

    Loops over the P <= 9 columns only; every operation acts on all B problems at
    once, which beats per-matrix LAPACK calls for thousands of 8x8 systems on CPU.
    Differentiable; a non-positive pivot is clamped (no NaN).
    """
    size = a.shape[-1]
    al, bl = a.permute(1, 2, 0), b.T  # (P, P, B), (P, B)
    tiny = torch.finfo(a.dtype).tiny
    cols = []  # cols[j] = L[j:, j], (P - j, B)
    for j in range(size):
        s = al[j:, j]
        for k in range(j):
            s = s - cols[k][j - k:] * cols[k][j - k]
        cols.append(s / s[0].clamp_min(tiny).sqrt())
    z, r = [], bl  # forward substitution, L z = b
    for j in range(size):
        z.append(r[0] / cols[j][0])
        r = r[1:] - cols[j][1:] * z[j]
    x = [None] * size  # back substitution, Lᵀ x = z
    for i in reversed(range(size)):
        rest = z[i]
        if i + 1 < size:
            rest = rest - (cols[i][1:] * torch.stack(x[i + 1:])).sum(0)
        x[i] = rest / cols[i][0]
    return torch.stack(x, dim=-1)


def damped_step(a: torch.Tensor, g: torch.Tensor, mu: torch.Tensor) -> torch.Tensor:
    """The LM step ``-(A + damp) \\ g`` of normal equations ``A (B, P, P)``, ``g (B, P)``
    with Marquardt's diagonal scaling by ``mu (B,)``; a non-finite step is zero. The
    problems are normalized, so the floors are relative to unit-sized data."""
    diag = a.diagonal(dim1=-2, dim2=-1)
    damp = mu[:, None] * diag + 1e-12 * diag.sum(-1, keepdim=True) + 1e-30
    step = -spd_solve(a + torch.diag_embed(damp), g)
    return torch.where(torch.isfinite(step), step, torch.zeros_like(step))


def lm_update(obj, obj_new, mu, small, tol):
    """Accept the trials that lower the objective, adapt ``mu``, test convergence.

    Returns ``(accept, obj, mu, converged)``, all ``(B,)``; ``small`` says where the step
    was small relative to the parameters.
    """
    accept = obj_new < obj
    decrease = torch.where(accept, obj - obj_new, torch.zeros_like(obj))
    obj = torch.where(accept, obj_new, obj)
    mu = torch.where(accept, mu * 0.1, mu * 10.0).clamp(1e-12, 1e12)
    converged = ((decrease <= tol * obj) & small) | (obj <= 1e-30) | (mu >= 1e12)
    return accept, obj, mu, converged


def levenberg_marquardt(fn, theta, prob, objective, steps, mu0, tol, bar, history):
    """Levenberg-Marquardt (Marquardt's diagonal scaling), per problem, unrolled."""
    constant_jac = None
    mu = torch.full_like(theta[:, 0], mu0)
    obj, loss = loss_terms(fn(theta), prob, objective)
    for _ in bar:
        jtj, jtr = normal_system(fn(theta), prob, objective)  # wrt vec(Ĥ)
        if fn.model == "homography" and fn.parametrization == "entries":
            a, g = jtj[:, :8, :8], jtr[:, :8, None]  # d vec(Ĥ) / dθ selects 8 entries
        elif fn.linear:  # one constant (9, P) Jacobian: plain GEMMs, no tiny bmm
            if constant_jac is None:  # constant: taken at θ = 0 (also for an empty batch)
                constant_jac = _param_jacobian(fn, theta.new_zeros(1, theta.shape[-1]))[0]
            d = constant_jac
            a = (jtj @ d).mT @ d  # (B, P, P)
            g = (jtr @ d)[..., None]  # (B, P, 1)
        else:
            d = _param_jacobian(fn, theta)  # (B, 9, P)
            a = d.mT @ jtj @ d
            g = d.mT @ jtr[..., None]
        step = damped_step(a, g.squeeze(-1), mu)  # (B, P)
        trial = theta + step
        obj_new, loss_new = loss_terms(fn(trial), prob, objective)
        small = step.norm(dim=-1) <= math.sqrt(tol) * (1 + theta.norm(dim=-1))
        accept, obj, mu, converged = lm_update(obj, obj_new, mu, small, tol)
        theta = torch.where(accept[:, None], trial, theta)
        loss = torch.where(accept, loss_new, loss)
        history.append(loss.detach())
        bar.set_postfix(loss=float(loss.detach().mean()))
        if bool(converged.all()):
            break
    return theta


def gauss_newton_step(fn, theta, prob, objective):
    """One Gauss-Newton step from a detached optimum: carries the implicit gradient."""
    theta = theta.detach()
    with torch.no_grad():
        d = _param_jacobian(fn, theta)  # (B, 9, P)
        jtj, _ = normal_system(fn(theta), prob, objective)
        a = d.mT @ jtj @ d
        diag = a.diagonal(dim1=-2, dim2=-1)
        eye = torch.eye(theta.shape[-1], dtype=theta.dtype, device=theta.device)
        chol, _ = torch.linalg.cholesky_ex(a + 1e-12 * diag.sum(-1)[:, None, None] * eye)
    _, jtr = normal_system(fn(theta), prob, objective)  # attached to the inputs
    return theta - torch.cholesky_solve(d.mT @ jtr[..., None], chol).squeeze(-1)


def first_order(kind, fn, theta, prob, objective, steps, lr, tol, patience, bar, history):
    if theta.shape[0] == 0:  # an empty batch: nothing to descend (torch's L-BFGS raises)
        return theta.detach()
    theta = theta.detach().clone().requires_grad_(True)
    prob_d = Problem(*(t.detach() for t in prob))
    objective = objective._replace(c_dst=objective.c_dst.detach(),
                                   c_src=objective.c_src.detach())
    if kind == "adam":
        opt = torch.optim.Adam([theta], lr=lr)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(steps, 1),
                                                           eta_min=lr * 1e-3)
    else:
        # one iteration per step (for the history); max_eval leaves room for the line search
        opt = torch.optim.LBFGS([theta], lr=lr, max_iter=1, max_eval=25, history_size=20,
                                tolerance_grad=0.0, tolerance_change=0.0,
                                line_search_fn="strong_wolfe")
        sched = None
    with torch.no_grad():
        best, _ = loss_terms(fn(theta), prob_d, objective)
    best_theta = theta.detach().clone()
    stale = 0
    for _ in bar:
        def closure():
            opt.zero_grad()
            obj, _ = loss_terms(fn(theta), prob_d, objective)
            total = obj.sum()
            total.backward()
            return total

        with torch.enable_grad():
            opt.step(closure)
        if sched is not None:
            sched.step()
        with torch.no_grad():
            obj, loss = loss_terms(fn(theta), prob_d, objective)
        history.append(loss)
        bar.set_postfix(loss=float(loss.mean()))
        improved = obj < best * (1 - tol)
        lower = obj < best  # keep the best iterate of each problem (Adam may overshoot)
        best_theta = torch.where(lower[:, None], theta.detach(), best_theta)
        best = torch.where(lower, obj, best)
        stale = 0 if bool(improved.any()) else stale + 1
        if stale >= patience or bool((obj <= 1e-30).all()):
            break
    return best_theta
