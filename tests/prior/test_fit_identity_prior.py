"""prior.fit.identity_prior against the numpy mixture the planner samples from and scipy."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from scipy.special import logsumexp  # noqa: E402
from scipy.stats import multivariate_normal  # noqa: E402

from prior.fit.identity_prior import TorchGMM  # noqa: E402
from synth.plan.identities import prior_of  # noqa: E402


@pytest.fixture(scope="module")
def data(default_model):
    return default_model


def _points(data, rng):
    g = prior_of(data)
    x = g.sample(rng, 20)
    far = g.mean() + rng.normal(0, 1, (4, g.dim)) * np.array([[10.0], [30.0], [100.0], [300.0]])
    return np.concatenate([x, far, g.means, np.zeros((1, g.dim))])


def test_matches_planner_mixture(data):
    rng = np.random.default_rng(0)
    x = _points(data, rng)
    ref = -prior_of(data).log_likelihood(x)
    got = TorchGMM.from_model(data).nll(torch.tensor(x)).numpy()
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-8)
    assert np.all(np.isfinite(got))  # log-sum-exp keeps it finite 300 sd away


def test_matches_scipy(data):
    rng = np.random.default_rng(1)
    x = prior_of(data).sample(rng, 10)
    comp = np.stack([np.log(w) + multivariate_normal(m, c).logpdf(x)
                     for w, m, c in zip(data.prior_weights, data.prior_means, data.prior_covs)], 1)
    np.testing.assert_allclose(TorchGMM.from_model(data).nll(torch.tensor(x)).numpy(), -logsumexp(comp, 1),
                               rtol=1e-9)


def test_gradient_and_single(data):
    g = TorchGMM.from_model(data)
    x = torch.tensor(prior_of(data).sample(np.random.default_rng(2), 3), requires_grad=True)
    assert torch.autograd.gradcheck(g.nll, (x,), fast_mode=True)
    assert g.nll(x[0]).shape == ()
    np.testing.assert_allclose(g.mean().numpy(), prior_of(data).mean(), atol=1e-12)


def test_curvature_is_responsibility_weighted_precision(data):
    g = TorchGMM.from_model(data)
    x = prior_of(data).sample(np.random.default_rng(3), 2)
    for xi in x:
        lp = prior_of(data).component_log_pdf(xi[None])[0]
        r = np.exp(lp - logsumexp(lp))
        ref = np.einsum("m,mij->ij", r, np.linalg.inv(data.prior_covs))
        np.testing.assert_allclose(g.curvature(torch.tensor(xi)).numpy(), ref, rtol=1e-8, atol=1e-10)
    # one component: the curvature is the exact Hessian of the nll (the precision)
    from synth.model.identity_gmm import GaussianMixture

    A = np.random.default_rng(4).normal(size=(5, 5))
    one = TorchGMM(GaussianMixture(np.ones(1), np.zeros((1, 5)), (A @ A.T + np.eye(5))[None]))
    x5 = torch.tensor(np.random.default_rng(5).normal(size=5))
    H = torch.autograd.functional.hessian(one.nll, x5)
    np.testing.assert_allclose(one.curvature(x5).numpy(), H.numpy(), rtol=1e-10)
