"""prior.fit.lm against scipy.optimize.least_squares (unbounded, bounded, with a scalar term)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from scipy.optimize import least_squares  # noqa: E402

from prior.fit.lm import levenberg_marquardt  # noqa: E402

X = np.linspace(0.0, 2.0, 40)
Y = 1.5 * np.exp(-1.2 * X) + 0.3 + 0.01 * np.random.default_rng(0).standard_normal(40)


def _res_np(p):
    return p[0] * np.exp(p[1] * X) + p[2] - Y


def _res_t(p):
    x = torch.as_tensor(X)
    return p[0] * torch.exp(p[1] * x) + p[2] - torch.as_tensor(Y)


def _zero(p):
    return (p * 0.0).sum()


def _no_curv(p):
    return torch.zeros(p.numel(), p.numel(), dtype=p.dtype)


def test_unbounded_matches_scipy():
    p0 = np.array([1.0, -0.5, 0.0])
    ref = least_squares(_res_np, p0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    got, rep = levenberg_marquardt(_res_t, _zero, _no_curv, torch.tensor(p0), rel_tol=1e-15)
    assert rep.converged
    np.testing.assert_allclose(got.numpy(), ref, rtol=1e-7, atol=1e-9)


def test_bounds_match_scipy():
    p0 = np.array([1.0, -2.0, 0.0])
    lo, hi = np.array([-np.inf, -np.inf, -np.inf]), np.array([np.inf, -1.5, 0.2])  # both active at the optimum
    ref = least_squares(_res_np, p0, bounds=(lo, hi), method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    got, rep = levenberg_marquardt(_res_t, _zero, _no_curv, torch.tensor(p0), lower=torch.tensor(lo),
                                   upper=torch.tensor(hi), rel_tol=1e-15)
    assert rep.converged
    assert got[1] == pytest.approx(-1.5) and got[2] == pytest.approx(0.2)
    np.testing.assert_allclose(got.numpy(), ref, rtol=1e-6, atol=1e-8)


def test_scalar_term_equals_extra_residuals():
    """phi = 0.5 p^T A p with curvature A is the same problem as residuals [r, L^T p] (A = L L^T)."""
    A = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])
    L = np.linalg.cholesky(A)
    p0 = np.array([1.0, -0.5, 0.0])
    ref = least_squares(lambda p: np.concatenate([_res_np(p), L.T @ p]), p0, method="lm", xtol=1e-15,
                        ftol=1e-15, gtol=1e-15).x
    At = torch.tensor(A)
    got, rep = levenberg_marquardt(_res_t, lambda p: 0.5 * p @ At @ p, lambda p: At, torch.tensor(p0),
                                   rel_tol=1e-15)
    assert rep.converged
    np.testing.assert_allclose(got.numpy(), ref, rtol=1e-6, atol=1e-8)
    cost = lambda p: 0.5 * np.sum(_res_np(p) ** 2) + 0.5 * p @ A @ p  # noqa: E731
    assert cost(got.numpy()) <= cost(ref) * (1 + 1e-12)  # equal optima to rounding (a flat valley)


def test_rosenbrock_and_accept_hook():
    seen = []

    def accept(p):
        seen.append(p.clone())
        return p

    got, rep = levenberg_marquardt(lambda p: torch.stack([10 * (p[1] - p[0] ** 2), 1 - p[0]]), _zero, _no_curv,
                                   torch.tensor([-1.2, 1.0], dtype=torch.float64), accept=accept, rel_tol=1e-15)
    assert rep.converged and len(seen) == rep.iterations
    np.testing.assert_allclose(got.numpy(), [1.0, 1.0], atol=1e-8)
    assert all(b <= a for a, b in zip(rep.history, rep.history[1:]))  # monotone


def test_residual_curvature_matches_per_residual_hessians():
    """The block's sum_i r_i Hess(r_i), against each residual's Hessian taken one by one
    (torch.autograd.functional.hessian), then projected onto the PSD matrices by numpy."""
    from prior.fit.lm import _residual_curvature

    p = torch.tensor([1.3, -0.7, 0.4, 2.0], dtype=torch.float64)
    idx = torch.tensor([0, 1, 3])

    def res(q):
        return torch.stack([q[0] * q[1] ** 2 - 1.0, torch.sin(q[0] * q[3]) + q[2], torch.exp(q[1]) * q[3] - 3.0])

    r = res(p)
    C = np.zeros((3, 3))
    for i in range(3):
        H = torch.autograd.functional.hessian(lambda x, i=i: res(p.index_put((idx,), x))[i], p[idx]).numpy()
        C += float(r[i]) * H
    w, V = np.linalg.eigh(C)
    assert w.min() < 0  # an indefinite case: the projection matters
    want = (V * np.maximum(w, 0.0)) @ V.T
    got = _residual_curvature(res, p, r, idx).numpy()
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_curved_block_reaches_scipy_optimum():
    p0 = np.array([1.0, -0.5, 0.0])
    ref = least_squares(_res_np, p0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    got, rep = levenberg_marquardt(_res_t, _zero, _no_curv, torch.tensor(p0), rel_tol=1e-15,
                                   curved=torch.tensor([0, 1]))
    assert rep.converged
    np.testing.assert_allclose(got.numpy(), ref, rtol=1e-7, atol=1e-9)
