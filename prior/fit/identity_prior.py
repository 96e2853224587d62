"""Negative log-likelihood of identity codes under the head model's Gaussian mixture, in torch.

The mixture is the one the planner samples identities from (``prior_weights``,
``prior_means``, ``prior_covs`` of the model file; numpy twin in
:class:`synth.model.prior.GaussianMixture`). With L_m the Cholesky factor of component m's
covariance (computed once, in float64):

    z_m  = L_m^-1 (x - mu_m)
    nll  = -logsumexp_m( log w_m - 0.5 (D log 2 pi + log det C_m) - 0.5 |z_m|^2 )

which stays finite and smooth arbitrarily far from the data (log-sum-exp).
"""

from __future__ import annotations

import numpy as np
import torch

from synth.model.format import HeadModelData


class TorchGMM:
    def __init__(self, weights, means, covs, dtype: torch.dtype = torch.float64, device="cpu"):
        w = np.asarray(weights, np.float64)
        mu = np.asarray(means, np.float64)
        C = np.asarray(covs, np.float64)
        L = np.linalg.cholesky(C)
        Linv = np.linalg.inv(L)  # (M, D, D) lower triangular
        D = mu.shape[1]
        logdet = 2.0 * np.log(np.diagonal(L, axis1=1, axis2=2)).sum(1)
        log_norm = np.log(w) - 0.5 * (D * np.log(2.0 * np.pi) + logdet)
        t = lambda a: torch.as_tensor(a, dtype=dtype, device=device)  # noqa: E731
        self.weights, self.means, self.whiten, self.log_norm = t(w), t(mu), t(Linv), t(log_norm)
        self.dim = D

    @classmethod
    def from_model(cls, data: HeadModelData, dtype: torch.dtype = torch.float64, device="cpu") -> "TorchGMM":
        return cls(data.prior_weights, data.prior_means, data.prior_covs, dtype, device)

    def mean(self) -> torch.Tensor:
        """(D,) mean of the mixture."""
        return self.weights @ self.means

    def mode_component(self) -> int:
        """Index of the component with the highest density at its own mean."""
        return int(torch.argmax(self.log_norm))

    def nll(self, x: torch.Tensor) -> torch.Tensor:
        """(B,) -log p(x) for codes (B, D) (or (D,) -> ())."""
        single = x.dim() == 1
        x = x.unsqueeze(0) if single else x
        d = x.unsqueeze(1) - self.means  # (B, M, D)
        z = torch.einsum("mij,bmj->bmi", self.whiten, d)
        out = -torch.logsumexp(self.log_norm - 0.5 * (z * z).sum(-1), dim=1)
        return out[0] if single else out

    def responsibilities(self, x: torch.Tensor) -> torch.Tensor:
        """(M,) posterior component probabilities of one code x (D,)."""
        z = torch.einsum("mij,mj->mi", self.whiten, x - self.means)
        return torch.softmax(self.log_norm - 0.5 * (z * z).sum(-1), 0)

    def curvature(self, x: torch.Tensor) -> torch.Tensor:
        """(D, D) positive semi-definite curvature of nll at x: the responsibility-weighted
        precisions sum_m r_m C_m^-1 (the exact Hessian drops a covariance-of-gradients term
        that can make it indefinite between components)."""
        r = self.responsibilities(x.detach())
        return torch.einsum("m,mki,mkj->ij", r, self.whiten, self.whiten)
