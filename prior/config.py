"""Configs of the conditional NeRF face prior: the field (:class:`ModelConfig`) and the
ray sampling (:class:`SamplingConfig`), each a frozen dataclass with documented defaults.

Two presets (:data:`PRESETS`):

- ``paper``: the sizes of Cafca's supplementary "Prior Model Details": a proposal MLP of
  depth 4 / width 256 evaluated at two proposal levels, a NeRF MLP of depth 8 / width
  1024 with a skip connection at layer 4, a colour bottleneck of 256 and one
  view-conditioned layer of 128; 12 positional-encoding levels for positions, 4 (plus the
  raw direction) for directions; 128 samples per level; a 64-d latent ``w``.
- ``small``: the same architecture, narrow enough to train on a laptop CPU.

Each is a :func:`synth.configkit.section`: per field a default, its one-line doc right under
it and its bounds on the type (the aliases below); the TOML / ``--set`` machinery is
:mod:`synth.configkit` and the run config that adds the data and training sections is
:mod:`prior.train.config`. ``validate`` checks the bounds and the rules between
fields and raises :class:`synth.configkit.ConfigError` (a ``ValueError``).
"""

from __future__ import annotations

from typing import Annotated

from synth.configkit import Bounds, Choices, ConfigError, check_section, section
from synth.seeds import MAX_SEED

# The bounded types the prior's configs share (also prior.train.config and prior.fit.config):
Size = Annotated[int, Bounds(1)]  #: at least one (layer, unit, step)
Samples = Annotated[int, Bounds(2)]  #: at least two samples per ray
Count = Annotated[int, Bounds(0)]  #: a whole number, 0 allowed
NonNegative = Annotated[float, Bounds(0)]  #: a number, not negative
Positive = Annotated[float, Bounds(gt=0.0)]  #: a number above 0 (learning rates, lengths)
Decay = Annotated[float, Bounds(0.0, lt=1.0)]  #: a decay rate in [0, 1) (Adam's betas)
Seed = Annotated[int, Bounds(0, MAX_SEED)]  #: a seed of the project's seed scheme (synth.seeds)
Switch = Annotated[bool | str, Choices(False, True, "auto")]  #: on, off, or chosen per machine (prior.precision)


@section
class ModelConfig:
    """The conditional field. Conditioning per ray: ``codes`` (beta || psi, size read from
    the dataset) concatenated with the learned latent ``w`` (``latent_dim``)."""

    latent_dim: Size = 64
    """size of the learned per-identity latent code w"""
    latent_init_std: NonNegative = 0.01
    """std of the normal initialisation of the latent codebook rows (auto-decoders start near 0)"""
    scene_center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """centre of the scene sphere (metres, world); positions are encoded as (x - scene_center) / scene_radius, so
    the heads should lie inside that sphere"""
    scene_radius: Positive = 0.3
    """radius of the scene sphere (metres)"""
    pos_levels: Size = 12
    """levels of the integrated positional encoding of positions: frequencies 2**0 .. 2**(pos_levels-1)"""
    dir_levels: Count = 4
    """levels of the positional encoding of view directions: frequencies 2**0 .. 2**(dir_levels-1), plus the raw
    direction"""
    proposal_depth: Size = 4
    """layers of the proposal MLP"""
    proposal_width: Size = 256
    """units per layer of the proposal MLP"""
    distinct_proposal: bool = False
    """one proposal MLP per proposal level (true) or one shared by all levels (false, as in the paper)"""
    nerf_depth: Size = 8
    """layers of the NeRF MLP's trunk"""
    nerf_width: Size = 1024
    """units per layer of the NeRF MLP's trunk"""
    skip_layer: Count = 4
    """trunk layer (0-based, below nerf_depth) whose input also gets the encoded position; 0 = no skip
    connection, since layer 0 sees it anyway"""
    bottleneck_width: Size = 256
    """width of the linear colour bottleneck after the trunk"""
    view_width: Size = 128
    """units of the one view-conditioned colour layer"""
    density_bias: float = -1.0
    """density = softplus(raw + density_bias), as in mip-NeRF 360"""
    rgb_padding: float = 0.001
    """colour = sigmoid(raw) * (1 + 2 rgb_padding) - rgb_padding, as in mip-NeRF"""
    init_seed: Seed = 0
    """seed of the weight and codebook initialisation (no global RNG is used)"""

    def validate(self, where: str | None = "model config") -> None:
        """Raise :class:`ConfigError` (a ValueError) on values that cannot build a model."""
        check_section(self, "model", where)
        if not self.skip_layer < self.nerf_depth:
            raise ConfigError(f"config value model.skip_layer = {self.skip_layer} must lie below model.nerf_depth "
                              f"= {self.nerf_depth}", where, "lower skip_layer (0: no skip connection)")


@section
class SamplingConfig:
    """How each ray is sampled: proposal levels, then one NeRF level (mip-NeRF 360)."""

    proposal_samples: Annotated[tuple[int, ...], Bounds(2)] = (128, 128)
    """samples (intervals) per ray of each proposal level, in order; the paper has two levels"""
    nerf_samples: Samples = 128
    """samples per ray of the final NeRF level"""
    anneal_slope: NonNegative = 10.0
    """proposal weights are raised to bias(train_frac, anneal_slope) before resampling (mip-NeRF 360: slope 10);
    0 turns annealing off"""
    dilation_bias: NonNegative = 0.0025
    """the proposal intervals are dilated, in normalised ray distance s in [0, 1], by dilation_bias +
    dilation_multiplier / (product of the sample counts of the levels so far)"""
    dilation_multiplier: NonNegative = 0.5
    """see dilation_bias"""
    resample_padding: NonNegative = 0.0
    """added to the proposal weights before annealing (0 = mip-NeRF 360's default)"""
    single_jitter: bool = False
    """stratified sampling draws one jitter per ray (true) or one per sample (false)"""

    def validate(self, where: str | None = "sampling config") -> None:
        """Raise :class:`ConfigError` (a ValueError) on values that cannot sample."""
        check_section(self, "sampling", where)

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
