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
from typing import Any

from prior.config import NONNEG, SEED, SIZE
from synth import configkit
from synth.configkit import ConfigError, setting
from synth.errors import SynthError

POSITIVE = dict(gt=0.0)
DECAY = dict(range=(0.0, None), lt=1.0)


@dataclass(frozen=True)
class LandmarkConfig:
    """Head-model and camera fitting to 2D landmarks (``prior/fit/landmarks_fit.py``)."""

    per_image_expression: bool = setting(True, "one expression code (and jaw/eye pose) per image, held near "
                                         "their mean (paper: in the wild); false = one shared code")
    sigma_px: float = setting(1.0, "sigma (pixels) of landmarks read from a synth frame's JSON (--landmarks json)",
                              **POSITIVE)
    noise_px: float = setting(0.0, "Gaussian noise (pixels per axis) added to JSON landmarks, seeded by the "
                              "frame's indices (experiments)", NONNEG)
    fov_init_deg: float = setting(50.0, "initial horizontal field of view (degrees) of the shared focal length, "
                                  "which is fitted", gt=0.0, lt=180.0)
    focal_px: float = setting(0.0, "known focal length in pixels (e.g. from EXIF) instead of fitting one; "
                              "0 = fit it", NONNEG)


@dataclass(frozen=True)
class InversionConfig:
    """Warm-up: only the latent ``w`` moves (codes, cameras, network frozen), on the inputs downscaled
    to the prior's resolution, L1 + lpips_weight * LPIPS on random square patches (paper Eq. 6)."""

    steps: int = setting(1500, "optimisation steps of w", NONNEG)
    patch_size: int = setting(32, "side of the random square patches (pixels of the downscaled images)", (8, None))
    patches: int = setting(4, "patches per step (paper: 4 x 32 x 32 = 4,096 rays)", SIZE)
    lpips_weight: float = setting(0.1, "weight of the LPIPS term; 0 = L1 only", NONNEG)
    lpips_net: str = setting("vgg", "LPIPS backbone", choices=("vgg", "alex"))
    lr_init: float = setting(1e-2, "learning rate of w, log-linear from lr_init to lr_final over the steps",
                             **POSITIVE)
    lr_final: float = setting(1e-3, "learning rate of w at the last step (at most lr_init)", **POSITIVE)
    resolution_factor: float = setting(1.0, "downscale the inputs so that their longer side is this many times "
                                       "the prior's (1 = the prior's resolution)", **POSITIVE)


@dataclass(frozen=True)
class FinetuneConfig:
    """Model fitting: every network parameter and w (paper Eq. 7), random rays of all input views at
    their own resolution, targets multiplied by the foreground masks."""

    steps: int = setting(50_000, "optimisation steps of the network and w", NONNEG)
    rays_per_step: int = setting(4096, "random rays per step, drawn uniformly over the pixels of all input views",
                                 SIZE)
    lr_init: float = setting(2e-3, "learning rate after the warm-up; log-linear decay to lr_final", **POSITIVE)
    lr_final: float = setting(2e-5, "learning rate at the last step (at most lr_init)", **POSITIVE)
    warmup_steps: int = setting(100, "steps of linear warm-up from lr_init * warmup_start", NONNEG)
    warmup_start: float = setting(0.01, "learning-rate factor at step 0 of the warm-up", (None, 1.0), gt=0.0)
    adam_beta1: float = setting(0.9, "Adam's first moment decay (the prior's)", **DECAY)
    adam_beta2: float = setting(0.999, "Adam's second moment decay (the prior's)", **DECAY)
    adam_eps: float = setting(1e-8, "Adam's epsilon", **POSITIVE)
    grad_clip: float = setting(1e-3, "gradient-norm clipping per group (proposal MLP, NeRF MLP, w); 0 = off "
                               "(paper 1e-3)", NONNEG)
    proposal_weight: float = setting(1.0, "weight of the proposal loss (the paper gives no fitting weights)",
                                     NONNEG)
    normal_weight: float = setting(3e-4, "weight of the normal-consistency loss", NONNEG)
    view_weight: float = setting(1e-4, "weight of the L2 penalty on the view-dependent colour branch", NONNEG)
    distortion_weight: float = setting(1e-2, "weight of the distortion loss", NONNEG)
    bf16: bool = setting(False, "bf16 autocast for the MLPs (compositing and losses stay float32)")


@dataclass(frozen=True)
class GeneralConfig:
    """What every stage shares."""

    seed: int = setting(0, "seed of every random draw of the fit (patches, rays, stratified jitter, landmark "
                        "noise)", SEED)
    render_chunk: int = setting(4096, "rays per chunk when rendering whole images", SIZE)


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
                     finetune=FinetuneConfig(steps=300, rays_per_step=1024, warmup_steps=20))


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
