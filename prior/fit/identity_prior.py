"""Negative log-likelihood of identity codes under the head model's Gaussian mixture, in torch.

The mixture is the one the planner samples identities from (``prior_weights``,
``prior_means``, ``prior_covs`` of the model file), evaluated from the parameters that
:meth:`synth.model.identity_gmm.GaussianMixture.parameters` exports (float64):

    z_m  = U_m^T (x - mu_m)            U_m = precision_cholesky[m], U_m U_m^T = C_m^-1
    nll  = -logsumexp_m( log_norm[m] - 0.5 |z_m|^2 )

which stays finite and smooth arbitrarily far from the data (log-sum-exp).
"""

from __future__ import annotations

import torch

from synth.model.format import HeadModelData
from synth.model.identity_gmm import GaussianMixture


class TorchGMM:
    def __init__(self, gmm: GaussianMixture, dtype: torch.dtype = torch.float64, device="cpu"):
        p = gmm.parameters()
        t = lambda a: torch.as_tensor(a, dtype=dtype, device=device)  # noqa: E731
        self.weights, self.means, self.log_norm = t(p["weights"]), t(p["means"]), t(p["log_norm"])
        self.whiten = t(p["precision_cholesky"]).transpose(-1, -2).contiguous()  # z = whiten @ (x - mu)
        self.dim = gmm.dim

    @classmethod
    def from_model(cls, data: HeadModelData, dtype: torch.dtype = torch.float64, device="cpu") -> "TorchGMM":
        return cls(GaussianMixture.from_model(data), dtype, device)

    def mean(self) -> torch.Tensor:
        """(D,) mean of the mixture."""
        return self.weights @ self.means

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
