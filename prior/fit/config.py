"""The few-shot fitting configuration (``synth prior fit``): landmark fitting, the warm-up
inversion of ``w`` and the fine-tuning, with presets and TOML / ``--set`` overrides.

A fit's config is built as ``preset <- TOML file <- --set section.key=value`` (later wins),
every override applied before the checks between fields, and saved with the fit
(``FIT/fit.json``). The machinery is :mod:`synth.configkit`; the model and sampling come from
the prior run, not from here. Sections: ``landmarks`` (:class:`LandmarkConfig`), ``inversion``
(:class:`InversionConfig`), ``finetune`` (:class:`FinetuneConfig`) and ``fit``
(:class:`GeneralConfig`: seed, render chunk). ``docs/prior.md`` lists every key (:func:`reference`).

Presets: ``paper`` (Cafca's supplementary "Inference Details": 1,500 inversion steps on four
32x32 patches, 50,000 fine-tuning steps of 4,096 random rays, Adam as the prior's) and
``small`` (CPU-sized: fewer steps and rays).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

from prior.config import Count, Decay, NonNegative, Positive, Seed, Size, Switch
from prior.train.config import TrainConfig
from synth import configkit
from synth.configkit import Bounds, Choices, ConfigError, section
from synth.errors import SynthError


@section
class LandmarkConfig:
    """Head-model and camera fitting to 2D landmarks (``prior/fit/landmarks_fit.py``)."""

    per_image_expression: bool = True
    """one expression code (and jaw/eye pose) per image, held near their mean (paper: in the wild); false = one
    shared code"""
    sigma_px: Positive = 1.0
    """sigma (pixels) of landmarks read from a synth frame's JSON (--landmarks json)"""
    noise_px: NonNegative = 0.0
    """Gaussian noise (pixels per axis) added to JSON landmarks, seeded by the frame's indices (experiments)"""
    fov_init_deg: Annotated[float, Bounds(gt=0.0, lt=180.0)] = 50.0
    """initial horizontal field of view (degrees) of the shared focal length, which is fitted (photos without an EXIF
    focal length)"""
    exif_focal: bool = True
    """photos' EXIF focal lengths as the initial focal length (an image without one takes the others' median)"""
    focal_px: NonNegative = 0.0
    """known focal length in pixels (e.g. from EXIF) instead of fitting one; 0 = fit it"""


@section
class InversionConfig:
    """Warm-up: only the latent ``w`` moves (codes, cameras, network frozen), on the inputs downscaled
    to the prior's resolution, L1 + lpips_weight * LPIPS on random square patches (paper Eq. 6)."""

    steps: Count = 1500
    """optimisation steps of w"""
    patch_size: Annotated[int, Bounds(8)] = 32
    """side of the random square patches (pixels of the downscaled images)"""
    patches: Size = 4
    """patches per step (paper: 4 x 32 x 32 = 4,096 rays)"""
    lpips_weight: NonNegative = 0.1
    """weight of the LPIPS term; 0 = L1 only"""
    lpips_net: Annotated[str, Choices("vgg", "alex")] = "vgg"
    """LPIPS backbone"""
    lr_init: Positive = 1e-2
    """learning rate of w, log-linear from lr_init to lr_final over the steps"""
    lr_final: Positive = 1e-3
    """learning rate of w at the last step (at most lr_init)"""
    resolution_factor: Positive = 1.0
    """downscale the inputs so that their longer side is this many times the prior's (1 = the prior's resolution)"""


@section
class FinetuneConfig:
    """Model fitting: every network parameter and w (paper Eq. 7), random rays of all input views at
    their own resolution, targets multiplied by the foreground masks. The optimiser's defaults are
    the prior training's (supplementary: "employs the Adam optimizer with the same parameters")."""

    steps: Count = 50_000
    """optimisation steps of the network and w"""
    rays_per_step: Size = 4096
    """random rays per step, drawn uniformly over the pixels of all input views (but face_fraction of them)"""
    face_fraction: Annotated[float, Bounds(0.0, 1.0)] = 0.0
    """share of each step's rays drawn uniformly among the face regions' pixels (the hull of each image's
    landmarks, grown by fit.face_grow); 0 = every ray uniform over all pixels"""
    lr_init: Positive = TrainConfig.lr_init
    """learning rate after the warm-up; log-linear decay to lr_final"""
    lr_final: Positive = TrainConfig.lr_final
    """learning rate at the last step (at most lr_init)"""
    warmup_steps: Count = 100
    """steps of linear warm-up from lr_init * warmup_start"""
    warmup_start: Annotated[float, Bounds(None, 1.0, gt=0.0)] = TrainConfig.warmup_start
    """learning-rate factor at step 0 of the warm-up"""
    adam_beta1: Decay = TrainConfig.adam_beta1
    """Adam's first moment decay (the prior's)"""
    adam_beta2: Decay = TrainConfig.adam_beta2
    """Adam's second moment decay (the prior's)"""
    adam_eps: Positive = TrainConfig.adam_eps
    """Adam's epsilon"""
    grad_clip: NonNegative = TrainConfig.grad_clip
    """gradient-norm clipping per group (proposal MLP, NeRF MLP, w); 0 = off (paper 1e-3)"""
    proposal_weight: NonNegative = 1.0
    """weight of the proposal loss (the paper gives no fitting weights)"""
    normal_weight: NonNegative = 3e-4
    """weight of the normal-consistency loss"""
    view_weight: NonNegative = 1e-4
    """weight of the L2 penalty on the view-dependent colour branch"""
    distortion_weight: NonNegative = 1e-2
    """weight of the distortion loss"""
    bf16: Switch = "auto"
    """bf16 autocast for the MLPs (compositing and losses stay float32); auto: on where the device computes
    bf16 natively, as train.bf16"""


@section
class GeneralConfig:
    """What every stage shares."""

    seed: Seed = 0
    """seed of every random draw of the fit (patches, rays, stratified jitter, landmark noise)"""
    render_chunk: Size = 4096
    """rays per chunk when rendering whole images"""
    face_grow: NonNegative = 0.1
    """the face region (finetune.face_fraction) is the hull of an image's landmarks scaled by 1 + face_grow about
    its centroid"""
    max_side_px: Annotated[int, Bounds(64)] = 2048
    """photos with a longer side are downscaled to it while decoded: every stage (landmarks, masks, fine-tuning)
    sees the downscaled photo"""


@dataclass(frozen=True)
class FitConfig:
    """A fit's config: one section per stage, and what they share (frozen, so defaults may be shared)."""

    landmarks: LandmarkConfig = LandmarkConfig()
    inversion: InversionConfig = InversionConfig()
    finetune: FinetuneConfig = FinetuneConfig()
    fit: GeneralConfig = GeneralConfig()

    def to_dict(self) -> dict[str, Any]:
        return configkit.to_dict(self)


SECTIONS: dict[str, type] = configkit.sections(FitConfig)


def _small() -> FitConfig:
    return FitConfig(inversion=InversionConfig(steps=100, patch_size=16, patches=2),
                     finetune=FinetuneConfig(steps=300, rays_per_step=1024, warmup_steps=20, face_fraction=0.5))


PRESETS = {"small": _small, "paper": FitConfig}


def preset(name: str) -> FitConfig:
    if name not in PRESETS:
        raise SynthError(f"unknown preset {name!r}", "--preset", f"choose one of {', '.join(PRESETS)}")
    return PRESETS[name]()


def _check_cross(cfg: FitConfig, where: str) -> None:
    """The rules between fields (the bounds of each field are checked by configkit)."""
    for sec in ("inversion", "finetune"):
        s = getattr(cfg, sec)
        if s.lr_final > s.lr_init:
            raise ConfigError(f"config value {sec}.lr_final = {s.lr_final} exceeds {sec}.lr_init = {s.lr_init}",
                              where, "choose lr_final <= lr_init")


def load(preset_name: str = "small", path=None, sets=()) -> FitConfig:
    """preset <- TOML file <- every ``--set`` override (in order), then every key's bounds and the
    rules between keys, checked once on the result."""
    return configkit.load(preset(preset_name), path, sets, _check_cross,
                          "--set" if sets else str(path or f"preset {preset_name}"))


def from_dict(data: dict, where: str) -> FitConfig:
    """A saved config (``fit.json``'s ``config``) back into a FitConfig, checked."""
    return configkit.load(configkit.apply(FitConfig(), data, where), cross_check=_check_cross, where=where)


def reference() -> str:
    """A markdown table of every config key: type, small / paper defaults, meaning."""
    return configkit.markdown({"small": preset("small"), "paper": preset("paper")})
