"""The few-shot fitting configuration (``synth prior fit``): landmark fitting, the warm-up
inversion of ``w`` and the fine-tuning, with presets and TOML / ``--set`` overrides.

A fit's config is built as ``preset <- TOML file <- --set section.key=value`` (later wins),
validated and saved with the fit (``FIT/fit.json``). The override machinery is the training
config's (:mod:`prior.train.config`: ``parse_set``, ``read_toml``, the value coercion); the
model and sampling come from the prior run, not from here. Sections: ``landmarks``
(:class:`LandmarkConfig`), ``inversion`` (:class:`InversionConfig`), ``finetune``
(:class:`FinetuneConfig`). ``docs/prior.md`` lists every key (:func:`reference`).

Presets: ``paper`` (Cafca's supplementary "Inference Details": 1,500 inversion steps on four
32x32 patches, 50,000 fine-tuning steps of 4,096 random rays, Adam as the prior's) and
``small`` (CPU-sized: fewer steps and rays).
"""

from __future__ import annotations

import dataclasses
import difflib
import typing
from dataclasses import dataclass, field
from typing import Any

from prior.train import config as run_config
from synth.errors import SynthError


@dataclass
class LandmarkConfig:
    """Head-model and camera fitting to 2D landmarks (``prior/fit/landmarks_fit.py``)."""

    #: one expression code (and jaw/eye pose) per image, held near their mean (paper: in the wild); False = one shared
    per_image_expression: bool = True
    #: sigma (pixels) of landmarks read from a synth frame's JSON (--landmarks json)
    sigma_px: float = 1.0
    #: Gaussian noise (pixels per axis) added to JSON landmarks, seeded by the frame's indices (experiments)
    noise_px: float = 0.0
    #: initial horizontal field of view (degrees) of the shared focal length, which is fitted
    fov_init_deg: float = 50.0
    #: known focal length in pixels (e.g. from EXIF) instead of fitting one; 0 = fit it
    focal_px: float = 0.0


@dataclass
class InversionConfig:
    """Warm-up: only the latent ``w`` moves (codes, cameras, network frozen), on the inputs downscaled
    to the prior's resolution, L1 + lpips_weight * LPIPS on random square patches (paper Eq. 6)."""

    steps: int = 1500
    #: side of the random square patches (pixels of the downscaled images)
    patch_size: int = 32
    #: patches per step (paper: 4 x 32 x 32 = 4,096 rays)
    patches: int = 4
    #: weight of the LPIPS term; 0 = L1 only
    lpips_weight: float = 0.1
    #: LPIPS backbone: vgg or alex
    lpips_net: str = "vgg"
    #: learning rate of w, log-linear from lr_init to lr_final over the steps
    lr_init: float = 1e-2
    lr_final: float = 1e-3
    #: downscale the inputs so that their longer side is this many times the prior's (1 = the prior's resolution)
    resolution_factor: float = 1.0


@dataclass
class FinetuneConfig:
    """Model fitting: every network parameter and w (paper Eq. 7), random rays of all input views at
    their own resolution, targets multiplied by the foreground masks."""

    steps: int = 50_000
    #: random rays per step, drawn uniformly over the pixels of all input views
    rays_per_step: int = 4096
    #: learning rate: warm-up from lr_init * warmup_start over warmup_steps, then log-linear to lr_final
    lr_init: float = 2e-3
    lr_final: float = 2e-5
    warmup_steps: int = 100
    warmup_start: float = 0.01
    #: Adam's moment decays and epsilon (the prior's)
    adam_beta1: float = 0.9
    adam_beta2: float = 0.999
    adam_eps: float = 1e-8
    #: gradient-norm clipping per group (proposal MLP, NeRF MLP, w); 0 = off (paper 1e-3)
    grad_clip: float = 1e-3
    #: loss weights: L1 + proposal + normal consistency + view-branch L2 + distortion (the paper gives no values)
    proposal_weight: float = 1.0
    normal_weight: float = 3e-4
    view_weight: float = 1e-4
    distortion_weight: float = 1e-2
    #: bf16 autocast for the MLPs (compositing and losses stay float32)
    bf16: bool = False


@dataclass
class FitConfig:
    landmarks: LandmarkConfig = field(default_factory=LandmarkConfig)
    inversion: InversionConfig = field(default_factory=InversionConfig)
    finetune: FinetuneConfig = field(default_factory=FinetuneConfig)
    #: seed of every random draw of the fit (patches, rays, stratified jitter, landmark noise)
    seed: int = 0
    #: rays per chunk when rendering whole images
    render_chunk: int = 4096

    def to_dict(self) -> dict[str, Any]:
        return run_config._plain(dataclasses.asdict(self))


SECTIONS: dict[str, type] = {"landmarks": LandmarkConfig, "inversion": InversionConfig, "finetune": FinetuneConfig}
#: top-level keys (not sections) and their types
TOP_KEYS: dict[str, type] = {"seed": int, "render_chunk": int}


def _small() -> FitConfig:
    return FitConfig(inversion=InversionConfig(steps=100, patch_size=16, patches=2),
                     finetune=FinetuneConfig(steps=300, rays_per_step=1024, warmup_steps=20))


PRESETS = {"small": _small, "paper": FitConfig}


def preset(name: str) -> FitConfig:
    if name not in PRESETS:
        raise SynthError(f"unknown preset {name!r}", "--preset", f"choose one of {', '.join(PRESETS)}")
    return PRESETS[name]()


def _unknown(kind: str, name: str, known: list[str], where: str, prefix: str = "") -> SynthError:
    near = difflib.get_close_matches(name, known, n=1)
    hint = f"did you mean '{prefix}{near[0]}'? " if near else ""
    return SynthError(f"unknown config {kind} '{prefix}{name}'", where, hint + f"known: {', '.join(known)}")


def apply(cfg: FitConfig, data: dict, where: str) -> FitConfig:
    """A copy of ``cfg`` with ``{section: {key: value}}`` (and top-level keys) applied."""
    if not isinstance(data, dict):
        raise SynthError("config must be a table of sections", where, f"sections: {', '.join(SECTIONS)}")
    top, sections = {}, {name: getattr(cfg, name) for name in SECTIONS}
    for sec, values in data.items():
        if sec in TOP_KEYS:
            top[sec] = run_config._coerce(values, TOP_KEYS[sec], sec, where)
            continue
        if sec not in SECTIONS:
            raise _unknown("section", sec, [*SECTIONS, *TOP_KEYS], where)
        if not isinstance(values, dict):
            raise SynthError(f"config section '{sec}' must be a table", where, f"write [{sec}] and key = value lines")
        hints = typing.get_type_hints(SECTIONS[sec])
        for k in values:
            if k not in hints:
                raise _unknown("key", k, list(hints), where, prefix=f"{sec}.")
        kw = {k: run_config._coerce(v, hints[k], f"{sec}.{k}", where) for k, v in values.items()}
        sections[sec] = dataclasses.replace(sections[sec], **kw)
    return dataclasses.replace(cfg, **sections, **top)


def validate(cfg: FitConfig, where: str) -> FitConfig:
    """Raise a one-line SynthError for values that cannot fit."""
    lm, inv, ft = cfg.landmarks, cfg.inversion, cfg.finetune
    checks = [
        (lm.sigma_px > 0 and lm.noise_px >= 0, "landmarks.sigma_px must be > 0 and noise_px >= 0"),
        (0 < lm.fov_init_deg < 180 and lm.focal_px >= 0, "landmarks.fov_init_deg in (0, 180), focal_px >= 0"),
        (inv.steps >= 0 and ft.steps >= 0, "inversion.steps and finetune.steps must be >= 0"),
        (inv.patch_size >= 8 and inv.patches >= 1, "inversion.patch_size >= 8 and inversion.patches >= 1"),
        (inv.lpips_weight >= 0 and inv.lpips_net in ("vgg", "alex"), "inversion.lpips_weight >= 0, lpips_net vgg|alex"),
        (0 < inv.lr_final <= inv.lr_init, "inversion.lr_final must lie in (0, lr_init]"),
        (inv.resolution_factor > 0, "inversion.resolution_factor must be > 0"),
        (ft.rays_per_step >= 1, "finetune.rays_per_step must be >= 1"),
        (0 < ft.lr_final <= ft.lr_init, "finetune.lr_final must lie in (0, lr_init]"),
        (ft.warmup_steps >= 0 and 0 < ft.warmup_start <= 1, "finetune.warmup_steps >= 0, warmup_start in (0, 1]"),
        (0 <= ft.adam_beta1 < 1 and 0 <= ft.adam_beta2 < 1 and ft.adam_eps > 0, "finetune.adam_* out of range"),
        (min(ft.grad_clip, ft.proposal_weight, ft.normal_weight, ft.view_weight, ft.distortion_weight) >= 0,
         "finetune.grad_clip and the loss weights must be >= 0"),
        (cfg.seed >= 0 and cfg.render_chunk >= 1, "seed must be >= 0 and render_chunk >= 1"),
    ]
    for ok, msg in checks:
        if not ok:
            raise SynthError(f"config: {msg}", where, "fix the value")
    return cfg


def load(preset_name: str = "small", path=None, sets=()) -> FitConfig:
    """preset <- TOML file <- ``--set`` overrides, validated."""
    cfg = preset(preset_name)
    if path is not None:
        cfg = apply(cfg, run_config.read_toml(path), str(path))
    for item in sets:
        cfg = apply(cfg, _parse_set(item), f"--set {item}")
    return validate(cfg, "--set" if sets else str(path or f"preset {preset_name}"))


def _parse_set(item: str) -> dict:
    """``section.key=value`` or a top-level ``key=value`` (seed, render_chunk)."""
    lhs = item.partition("=")[0].strip()
    if lhs in TOP_KEYS:
        return run_config.parse_set(f"top.{item.strip()}")["top"]
    return run_config.parse_set(item)


def from_dict(data: dict, where: str) -> FitConfig:
    """A saved config back into a FitConfig."""
    return validate(apply(FitConfig(), data, where), where)


def reference() -> str:
    """A markdown table of every config key: type, small / paper defaults, meaning."""
    small, paper = preset("small").to_dict(), preset("paper").to_dict()
    rows = ["| key | type | small | paper | meaning |", "|---|---|---|---|---|"]
    top_docs = run_config._field_docs(FitConfig)
    for k, tp in TOP_KEYS.items():
        rows.append(f"| `{k}` | {tp.__name__} | `{small[k]}` | `{paper[k]}` | {top_docs.get(k, '')} |")
    for sec, cls in SECTIONS.items():
        hints, docs = typing.get_type_hints(cls), run_config._field_docs(cls)
        for k in small[sec]:
            tp = getattr(hints[k], "__name__", str(hints[k]))
            rows.append(f"| `{sec}.{k}` | {tp} | `{small[sec][k]}` | `{paper[sec][k]}` | {docs.get(k, '')} |")
    return "\n".join(rows)
