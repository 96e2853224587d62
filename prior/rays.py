"""The rays that :class:`prior.model.PriorField` renders, as one record.

A :class:`RayBundle` holds N rays and their conditioning: origins, unit directions, the bounds
``[near, far]`` (the head's bounding sphere), the cone radii, the per-ray codes (beta || psi)
and the latent, either codebook rows (``latent_ids``) or explicit vectors (``latents``, a
fitted face). Options of a render that are not per ray (sampling randomness, the annealing
fraction, normals) stay keywords of ``PriorField.forward``.

It is a frozen dataclass of tensors: ``torch.compile`` traces its attribute reads (one graph
per combination of present fields), and DDP passes it through to the module unchanged (its
tensors must already be on the module's device).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import torch


@dataclass(frozen=True)
class RayBundle:
    origins: torch.Tensor  # (N, 3)
    directions: torch.Tensor  # (N, 3) unit
    near: torch.Tensor  # (N,)
    far: torch.Tensor  # (N,)
    codes: torch.Tensor  # (N, C) conditioning codes (beta || psi)
    latent_ids: torch.Tensor | None = None  # (N,) long: codebook rows
    latents: torch.Tensor | None = None  # (N, latent_dim): replaces the codebook lookup when given
    #: (N,) cone radius at unit distance (pixel footprint, e.g. ``2 / sqrt(12) / fx`` for unit
    #: directions); None = thin rays (plain encoding)
    radii: torch.Tensor | None = None

    @classmethod
    def from_numpy(cls, origins, directions, near, far, codes, *, latent_ids=None, radii=None,
                   device="cpu") -> "RayBundle":
        """A bundle of numpy arrays (or anything ``torch.as_tensor`` takes) on ``device``: float32,
        ``latent_ids`` int64."""
        def T(a, dt=torch.float32):
            return None if a is None else torch.as_tensor(a, dtype=dt).to(device, non_blocking=True)

        return cls(T(origins), T(directions), T(near), T(far), T(codes), latent_ids=T(latent_ids, torch.long),
                   radii=T(radii))

    def __len__(self) -> int:
        return int(self.origins.shape[0])

    @property
    def valid(self) -> torch.Tensor:
        """(N,) 1.0 for rays that cross their bounding sphere (``far > near``), else 0.0."""
        return (self.far > self.near).float()

    def map(self, fn: Callable[[torch.Tensor], torch.Tensor]) -> "RayBundle":
        """The bundle with ``fn`` applied to every tensor it holds (absent fields stay None)."""
        return dataclasses.replace(self, **{f.name: fn(v) for f in dataclasses.fields(self)
                                            if (v := getattr(self, f.name)) is not None})

    def __getitem__(self, index) -> "RayBundle":
        """The rays ``index`` selects (a slice, an index array or a mask), every field alike."""
        if isinstance(index, np.ndarray):
            index = torch.as_tensor(index, device=self.origins.device)
        return self.map(lambda x: x[index])

    def to(self, device) -> "RayBundle":
        return self.map(lambda x: x.to(device))

    def chunks(self, size: int) -> Iterator["RayBundle"]:
        """Consecutive bundles of at most ``size`` rays, in order."""
        for a in range(0, len(self), size):
            yield self[a:a + size]

    def with_latent(self, latent: torch.Tensor) -> "RayBundle":
        """Every ray conditioned on the one latent vector ``latent`` ((latent_dim,) or
        (1, latent_dim); broadcast, not copied, so gradients flow back to it) instead of a
        codebook row."""
        return dataclasses.replace(self, latent_ids=None, latents=latent.expand(len(self), -1))
