"""A small dense Levenberg-Marquardt solver in torch for energies of the form

    E(theta) = 0.5 |rho(theta)|^2 + phi(theta)

with rho a residual vector (Jacobian by forward-mode autodiff) and phi a smooth scalar
whose gradient comes from autograd and whose curvature is supplied as a positive
semi-definite matrix (for the identity GMM: the responsibility-weighted precisions).

Each step solves (H + lambda diag(H)) delta = -g with H = J^T J + H_phi (Marquardt's
scaling makes the step invariant to the units of each parameter: metres, radians, codes),
accepts it if E decreases (then lambda shrinks) and otherwise raises lambda. On an optional
block of parameters (``curved``) H also gets the residuals' own curvature sum_i r_i Hess(r_i),
which Gauss-Newton drops: where parameters are weakly determined (their J^T J is about the
size of a regulariser's) and the residuals bend with them, that term dominates; without it
the steps overshoot, get rejected, and the damping they leave behind makes every other
direction crawl (the eyelid rig's lids riding on the pitched cornea, prior.fit.landmarks_fit). Sizes here
are ~100-300 parameters and ~1,000 residuals, so the dense solve costs nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import torch
from torch.func import jacfwd


@dataclass
class LMReport:
    iterations: int
    converged: bool
    energy: float
    grad_norm: float
    history: list[float] = field(default_factory=list)


def levenberg_marquardt(residuals: Callable[[torch.Tensor], torch.Tensor],
                        scalar: Callable[[torch.Tensor], torch.Tensor],
                        scalar_curvature: Callable[[torch.Tensor], torch.Tensor],
                        theta: torch.Tensor, *, lower: torch.Tensor | None = None, upper: torch.Tensor | None = None,
                        accept: Callable[[torch.Tensor], torch.Tensor] | None = None,
                        max_iters: int = 200, rel_tol: float = 1e-12, lam: float = 1e-3,
                        curved: torch.Tensor | None = None) -> tuple[torch.Tensor, LMReport]:
    """Minimise 0.5 |residuals(theta)|^2 + scalar(theta) from ``theta``, optionally within
    bounds ``lower <= theta <= upper`` (tensors like theta, +-inf where unbounded).

    Bounds use an active set: a parameter on a bound whose gradient points outward is held
    for the step; the others take the damped Gauss-Newton step, and any of them that would
    leave the box is stopped on its bound and held while the rest re-solve (see
    :func:`_bounded_step`). ``accept(theta)`` (optional) is called on every accepted iterate and
    returns the parameters to continue from (used to re-centre rotation parameters).
    ``curved`` (optional, indices into theta): the block that gets the residuals' own curvature
    (module docstring), projected onto the positive semi-definite matrices; keep it small (it
    costs a Hessian of the residuals over the block per iteration).
    Converged when an accepted step lowers E by at most ``rel_tol`` relatively, or the
    projected gradient vanishes.
    """
    def energy(th):
        r = residuals(th)
        return 0.5 * (r * r).sum() + scalar(th)

    inf = torch.full_like(theta, float("inf"))
    lo = -inf if lower is None else lower.to(theta)
    hi = inf if upper is None else upper.to(theta)
    theta = torch.minimum(torch.maximum(theta.detach().clone(), lo), hi)
    with torch.no_grad():
        E = float(energy(theta))
    history = [E]
    gnorm = float("inf")
    for it in range(1, max_iters + 1):
        r = residuals(theta).detach()
        J = jacfwd(residuals)(theta).detach()
        th = theta.clone().requires_grad_(True)
        phi = scalar(th)
        g_phi = torch.autograd.grad(phi, th)[0] if phi.requires_grad else torch.zeros_like(theta)
        g = J.T @ r + g_phi
        held = ((theta <= lo) & (g > 0)) | ((theta >= hi) & (g < 0))
        free = ~held
        gnorm = float(g[free].norm())
        if gnorm <= 1e-12 * max(1.0, abs(E)):
            return theta, LMReport(it - 1, True, E, gnorm, history)
        H = J.T @ J + scalar_curvature(theta)
        if curved is not None and curved.numel():
            H[curved[:, None], curved[None, :]] += _residual_curvature(residuals, theta, r, curved)
        d = H.diagonal().clamp_min(1e-12 * float(H.diagonal().max()) + 1e-30)
        while True:
            cand = theta + _bounded_step(H + lam * torch.diag(d), g, theta, lo, hi, free)
            with torch.no_grad():
                E_new = float(energy(cand))
            if E_new <= E:
                break
            lam *= 4.0
            if lam > 1e16:  # no descent along any damped step: at a minimum to machine precision
                return theta, LMReport(it - 1, True, E, gnorm, history)
        lam = max(lam / 3.0, 1e-12)
        theta = accept(cand) if accept is not None else cand
        decrease, E = E - E_new, E_new
        history.append(E)
        if decrease <= rel_tol * max(abs(E), 1.0):
            return theta, LMReport(it, True, E, gnorm, history)
    return theta, LMReport(max_iters, False, E, gnorm, history)


def _residual_curvature(residuals, theta: torch.Tensor, r: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """sum_i r_i Hess(r_i) over the parameters ``idx`` (the Hessian of r . residuals with r held),
    with its negative eigenvalues set to 0 so that H stays positive semi-definite."""
    def weighted(x):
        return (r * residuals(theta.index_put((idx,), x))).sum()

    C = torch.func.hessian(weighted)(theta[idx]).detach()
    w, V = torch.linalg.eigh(0.5 * (C + C.T))
    return (V * w.clamp_min(0.0)) @ V.T


def _bounded_step(A: torch.Tensor, g: torch.Tensor, theta: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor,
                  free: torch.Tensor) -> torch.Tensor:
    """Minimise the model 0.5 s^T A s + g^T s over steps s that keep theta + s in [lo, hi]
    and leave the held (non-free) parameters alone, by repeated solves: parameters whose
    unconstrained step crosses a bound are moved onto it and fixed, the remaining free ones
    are re-solved given those fixed moves (at most one pass per parameter; usually one or two)."""
    step = torch.zeros_like(theta)
    fixed = ~free
    for _ in range(theta.numel()):
        f = ~fixed
        if not f.any():
            break
        rhs = g[f] + A[f][:, fixed] @ step[fixed]
        step[f] = -torch.linalg.solve(A[f][:, f], rhs)
        cand = theta + step
        out = f & ((cand < lo) | (cand > hi))
        if not out.any():
            break
        step[out] = torch.where(cand[out] < lo[out], lo[out], hi[out]) - theta[out]
        fixed = fixed | out
    return torch.minimum(torch.maximum(theta + step, lo), hi) - theta
