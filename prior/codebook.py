"""The auto-decoder codebook: one learned latent ``w`` per training identity (Preface /
Cafca; 1,500 x 64 in the paper), a dense embedding optimised with the field."""

from __future__ import annotations

import torch
from torch import nn


class Codebook(nn.Module):
    """``num_latents`` rows of size ``dim``, initialised N(0, init_std^2) from ``generator``
    (no global RNG). ``codebook(ids)`` returns the rows of a (N,) long tensor of ids."""

    def __init__(self, num_latents: int, dim: int, init_std: float = 0.01,
                 generator: torch.Generator | None = None):
        super().__init__()
        if num_latents < 1 or dim < 1:
            raise ValueError(f"a codebook needs at least one row and column, got {num_latents} x {dim}")
        self.embedding = nn.Embedding(num_latents, dim)
        with torch.no_grad():
            nn.init.normal_(self.embedding.weight, 0.0, init_std, generator=generator)

    @property
    def num_latents(self) -> int:
        return self.embedding.num_embeddings

    @property
    def dim(self) -> int:
        return self.embedding.embedding_dim

    def forward(self, ids: torch.Tensor) -> torch.Tensor:
        return self.embedding(ids)

    def mean_latent(self) -> torch.Tensor:
        """The mean row (dim,), detached: a neutral starting point for fitting a new face."""
        return self.embedding.weight.detach().mean(dim=0)
