"""Configs of the conditional NeRF face prior: the field (:class:`ModelConfig`) and the
ray sampling (:class:`SamplingConfig`), each a plain dataclass with defaults.

Two presets (:data:`PRESETS`):

- ``paper``: the sizes of Cafca's supplementary "Prior Model Details": a proposal MLP of
  depth 4 / width 256 evaluated at two proposal levels, a NeRF MLP of depth 8 / width
  1024 with a skip connection at layer 4, a colour bottleneck of 256 and one
  view-conditioned layer of 128; 12 positional-encoding levels for positions, 4 (plus the
  raw direction) for directions; 128 samples per level; a 64-d latent ``w``.
- ``small``: the same architecture, narrow enough to train on a laptop CPU.

The TOML / ``--set`` override machinery and the training config live elsewhere
(``prior/train``); these classes hold only plain values so they round-trip through
``dataclasses.asdict``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass


@dataclass
class ModelConfig:
    """The conditional field. Conditioning per ray: ``codes`` (beta || psi, size read from
    the dataset) concatenated with the learned latent ``w`` (``latent_dim``)."""

    latent_dim: int = 64
    #: std of the normal initialisation of the codebook rows (auto-decoders start near 0)
    latent_init_std: float = 0.01
    #: positions are mapped to ``(x - scene_center) / scene_radius`` before the encoding, so
    #: the head's bounding sphere should lie inside the unit ball (metres)
    scene_center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scene_radius: float = 0.3
    #: integrated positional encoding of positions: frequencies 2**0 .. 2**(pos_levels-1)
    pos_levels: int = 12
    #: positional encoding of directions: 2**0 .. 2**(dir_levels-1), plus the raw direction
    dir_levels: int = 4
    proposal_depth: int = 4
    proposal_width: int = 256
    #: one proposal MLP per proposal level (True) or one shared by all levels (paper: shared)
    distinct_proposal: bool = False
    nerf_depth: int = 8
    nerf_width: int = 1024
    #: the encoded position is concatenated to the input of this trunk layer (0-based;
    #: 0 = no skip connection, since layer 0 sees it anyway)
    skip_layer: int = 4
    bottleneck_width: int = 256
    view_width: int = 128
    #: density = softplus(raw + density_bias) (mip-NeRF 360)
    density_bias: float = -1.0
    #: rgb = sigmoid(raw) * (1 + 2 p) - p (mip-NeRF)
    rgb_padding: float = 0.001
    #: seed of the weight and codebook initialisation (no global RNG is used)
    init_seed: int = 0

    def validate(self) -> None:
        """Raise ValueError on sizes that cannot build a model."""
        ints = {"latent_dim": self.latent_dim, "pos_levels": self.pos_levels,
                "proposal_depth": self.proposal_depth, "proposal_width": self.proposal_width,
                "nerf_depth": self.nerf_depth, "nerf_width": self.nerf_width,
                "bottleneck_width": self.bottleneck_width, "view_width": self.view_width}
        for name, value in ints.items():
            if int(value) < 1:
                raise ValueError(f"model.{name} = {value} must be at least 1")
        if self.dir_levels < 0:
            raise ValueError(f"model.dir_levels = {self.dir_levels} must be at least 0")
        if not 0 <= self.skip_layer < self.nerf_depth:
            raise ValueError(f"model.skip_layer = {self.skip_layer} must lie in [0, nerf_depth) "
                             "(0: no skip connection)")
        if not self.scene_radius > 0:
            raise ValueError(f"model.scene_radius = {self.scene_radius} must be positive")
        if not self.latent_init_std >= 0:
            raise ValueError(f"model.latent_init_std = {self.latent_init_std} must be >= 0")


@dataclass
class SamplingConfig:
    """How each ray is sampled: proposal levels, then one NeRF level (mip-NeRF 360)."""

    #: samples (intervals) of each proposal level, in order; the paper samples twice
    proposal_samples: tuple[int, ...] = (128, 128)
    nerf_samples: int = 128
    #: proposal weights are raised to bias(train_frac, anneal_slope) before resampling
    #: (mip-NeRF 360: slope 10); 0 turns annealing off (exponent 1 throughout)
    anneal_slope: float = 10.0
    #: dilation of the proposal intervals in normalised ray distance s in [0, 1]:
    #: bias + multiplier / (product of the sample counts of the levels so far)
    dilation_bias: float = 0.0025
    dilation_multiplier: float = 0.5
    #: added to the proposal weights before annealing (0 = mip-NeRF 360's default)
    resample_padding: float = 0.0
    #: one jitter per ray (True) or one per sample (False) in stratified mode
    single_jitter: bool = False

    def validate(self) -> None:
        counts = (*self.proposal_samples, self.nerf_samples)
        if any(int(n) < 2 for n in counts):
            raise ValueError(f"sampling counts {counts} must each be at least 2")
        for name in ("anneal_slope", "dilation_bias", "dilation_multiplier", "resample_padding"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"sampling.{name} = {getattr(self, name)} must be >= 0")

    @property
    def samples_per_level(self) -> tuple[int, ...]:
        return (*(int(n) for n in self.proposal_samples), int(self.nerf_samples))


def paper_preset() -> tuple[ModelConfig, SamplingConfig]:
    """Cafca's prior (supplementary, "Prior Model Details")."""
    return ModelConfig(), SamplingConfig()


def small_preset() -> tuple[ModelConfig, SamplingConfig]:
    """Same architecture, CPU-sized: trunk widths 128 (NeRF) and 64 (proposal), 32 samples
    per level."""
    model = ModelConfig(proposal_depth=2, proposal_width=64, nerf_depth=4, nerf_width=128,
                        skip_layer=2, bottleneck_width=64, view_width=32)
    sampling = SamplingConfig(proposal_samples=(32, 32), nerf_samples=32)
    return model, sampling


PRESETS = {"paper": paper_preset, "small": small_preset}


def preset(name: str) -> tuple[ModelConfig, SamplingConfig]:
    """Fresh (model, sampling) configs of a preset; ValueError names the known presets."""
    try:
        return PRESETS[name]()
    except KeyError:
        raise ValueError(f"unknown preset {name!r}; known: {', '.join(sorted(PRESETS))}") from None


def to_dict(cfg) -> dict:
    """A JSON-ready dict of a config (tuples become lists)."""
    return dataclasses.asdict(cfg)
