"""The identity prior of a head model: a Gaussian mixture over identity codes (log-likelihood,
sampling, EM fitting). Stored in model files as ``prior_weights``/``prior_means``/``prior_covs``.

All densities are evaluated in float64 through Cholesky factors and log-sum-exp, so the
log-likelihood stays finite (and decreases monotonically) arbitrarily far from the data.

The parameters are plain arrays so that other frameworks can evaluate the same density
(the code fitting of the NeRF prior does it in torch). With the per-component arrays of
:meth:`GaussianMixture.parameters`::

    z_m    = (x - means[m]) @ precision_cholesky[m]            # (D,) whitened offset
    log p  = logsumexp_m( log_norm[m] - 0.5 * |z_m|^2 )
    nll    = -log p

where ``precision_cholesky[m]`` is upper triangular with ``precision_cholesky[m] @
precision_cholesky[m].T == inv(covs[m])`` (scikit-learn's ``precisions_cholesky_``
convention) and ``log_norm[m] = log weights[m] - 0.5 (D log 2 pi + log det covs[m])``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from synth.geometry import exact

_LOG2PI = float(np.log(2.0 * np.pi))


@dataclass
class GaussianMixture:
    """``weights`` (M,) summing to 1, ``means`` (M, D), ``covs`` (M, D, D) symmetric positive definite."""

    weights: np.ndarray  # (M,)
    means: np.ndarray  # (M, D)
    covs: np.ndarray  # (M, D, D)

    def __post_init__(self):
        self.weights = np.asarray(self.weights, np.float64)
        self.means = np.asarray(self.means, np.float64)
        self.covs = np.asarray(self.covs, np.float64)
        self._chol = np.linalg.cholesky(self.covs)  # raises if not positive definite
        self._chol_exact = None  # sample()'s machine-independent factor, made on first use
        self._logdet = 2.0 * np.sum(np.log(np.diagonal(self._chol, axis1=1, axis2=2)), axis=1)

    @classmethod
    def from_model(cls, model) -> "GaussianMixture":
        """The identity prior stored in a :class:`synth.model.format.HeadModelData`."""
        return cls(model.prior_weights, model.prior_means, model.prior_covs)

    @property
    def dim(self) -> int:
        return int(self.means.shape[1])

    @property
    def cholesky(self) -> np.ndarray:
        """(M, D, D) lower-triangular L with covs = L L^T."""
        return self._chol.copy()

    @property
    def precision_cholesky(self) -> np.ndarray:
        """(M, D, D) upper-triangular U = L^-T, so inv(covs) = U U^T and the squared
        Mahalanobis distance is |(x - mean) U|^2 (a plain matrix product)."""
        from scipy.linalg import solve_triangular

        eye = np.eye(self.dim)
        return np.stack([solve_triangular(c, eye, lower=True).T for c in self._chol])

    @property
    def log_norm(self) -> np.ndarray:
        """(M,) log weight plus log normalising constant of each component."""
        return np.log(self.weights) - 0.5 * (self._logdet + self.dim * _LOG2PI)

    def parameters(self) -> dict[str, np.ndarray]:
        """Everything needed to evaluate the density elsewhere (see the module docstring), float64."""
        return {"weights": self.weights.copy(), "means": self.means.copy(), "covs": self.covs.copy(),
                "precision_cholesky": self.precision_cholesky, "log_norm": self.log_norm}

    def mahalanobis_sq(self, x: np.ndarray) -> np.ndarray:
        """(N, M) squared Mahalanobis distances to each component."""
        from scipy.linalg import solve_triangular

        x = np.atleast_2d(np.asarray(x, np.float64))
        out = np.empty((x.shape[0], len(self.weights)))
        for m in range(len(self.weights)):
            z = solve_triangular(self._chol[m], (x - self.means[m]).T, lower=True)
            out[:, m] = np.sum(z * z, axis=0)
        return out

    def component_log_pdf(self, x: np.ndarray) -> np.ndarray:
        d2 = self.mahalanobis_sq(x)
        return -0.5 * (d2 + self._logdet[None] + self.dim * _LOG2PI) + np.log(self.weights)[None]

    def log_likelihood(self, x: np.ndarray) -> np.ndarray:
        """(N,) log p(x)."""
        return logsumexp(self.component_log_pdf(x), axis=1)

    def nll(self, x: np.ndarray) -> np.ndarray:
        """(N,) negative log-likelihood -log p(x) (the regulariser of code fitting)."""
        return -self.log_likelihood(x)

    def sample(self, rng: np.random.Generator, n: int, max_mahalanobis: float | None = None,
               max_tries: int = 1000) -> np.ndarray:
        """Draw n codes. With ``max_mahalanobis`` r, each draw is truncated to the ball of
        radius r around its own component (rejection per draw, bounded; after ``max_tries``
        the draw is radially clamped onto the ball, which keeps it on the prior's support)."""
        comps = rng.choice(len(self.weights), size=n, p=self.weights)
        z = rng.standard_normal((n, self.dim))
        if max_mahalanobis is not None:
            r2 = float(max_mahalanobis) ** 2
            for _ in range(max_tries):
                bad = np.sum(z * z, axis=1) > r2
                if not bad.any():
                    break
                z[bad] = rng.standard_normal((int(bad.sum()), self.dim))
            norms = np.linalg.norm(z, axis=1, keepdims=True)
            z = np.where(norms > max_mahalanobis, z * (max_mahalanobis / np.maximum(norms, 1e-300)), z)
        # the factor and the product in a fixed order (synth.geometry.exact): plans are the same bits
        # on every machine, whatever LAPACK/BLAS kernels would have computed
        if self._chol_exact is None:
            self._chol_exact = exact.cholesky(self.covs)
        L = self._chol_exact[comps]
        out = self.means[comps].copy()
        for j in range(self.dim):
            out += L[:, :, j] * z[:, j, None]
        return out

    def mean(self) -> np.ndarray:
        return self.weights @ self.means

    def covariance(self) -> np.ndarray:
        mu = self.mean()
        d = self.means - mu
        return np.einsum("m,mij->ij", self.weights, self.covs) + np.einsum("m,mi,mj->ij", self.weights, d, d)


def fit_gmm(x: np.ndarray, n_components: int, rng: np.random.Generator, iters: int = 100,
            reg: float = 1e-3, tol: float = 1e-6) -> GaussianMixture:
    """Full-covariance EM with k-means++ initialisation; ``reg`` is added to every
    covariance diagonal so they stay positive definite."""
    x = np.asarray(x, np.float64)
    N, D = x.shape
    M = int(n_components)
    if N < M:
        raise ValueError(f"need at least {M} samples to fit {M} components, got {N}")
    # k-means++ seeding
    centers = [x[rng.integers(N)]]
    for _ in range(1, M):
        d2 = np.min(((x[:, None, :] - np.array(centers)[None]) ** 2).sum(-1), axis=1)
        p = d2 / d2.sum() if d2.sum() > 0 else np.full(N, 1.0 / N)
        centers.append(x[rng.choice(N, p=p)])
    means = np.array(centers)
    resp = np.zeros((N, M))
    resp[np.arange(N), np.argmin(((x[:, None] - means[None]) ** 2).sum(-1), axis=1)] = 1.0
    prev = -np.inf
    gmm = None
    for _ in range(iters):
        nk = resp.sum(0) + 1e-10
        weights = nk / N
        means = (resp.T @ x) / nk[:, None]
        covs = np.empty((M, D, D))
        for m in range(M):
            d = x - means[m]
            covs[m] = (resp[:, m, None] * d).T @ d / nk[m] + reg * np.eye(D)
            covs[m] = 0.5 * (covs[m] + covs[m].T)
        gmm = GaussianMixture(weights / weights.sum(), means, covs)
        lp = gmm.component_log_pdf(x)
        ll = logsumexp(lp, axis=1)
        resp = np.exp(lp - ll[:, None])
        cur = float(ll.mean())
        if abs(cur - prev) < tol * max(1.0, abs(cur)):
            break
        prev = cur
    return gmm
