"""The typed dataset configuration: dataclasses with documented defaults that mirror the
Cafca paper, read from TOML and overridable with dotted ``--set section.key=value``.

Every field is a :func:`synth.configkit.setting`: a one-line doc, optional inclusive
``range`` (applied to every number of a tuple) and ``choices``. The machinery (types,
TOML, overrides, did-you-mean, the reference table) is :mod:`synth.configkit`; this module
holds the sections, the render presets and the cross-field rules (:func:`check_cross`),
which run once after every override is applied. ``synth config show --explain`` prints the
table; docs/config.md is generated from it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from synth import configkit
from synth.assets import classes as asset_classes
from synth.configkit import ConfigError
from synth.configkit import setting as _f  # a documented field: default, doc, range, choices
from synth.seeds import MAX_SEED

# The render presets live here and nowhere else (the plan records the resolved settings).
RENDER_PRESETS: dict[str, dict[str, Any]] = {
    "ci": {"resolution": (64, 64), "samples": 4, "denoise": False, "adaptive_sampling": False,
           "adaptive_threshold": 0.0},
    "preview": {"resolution": (256, 256), "samples": 16, "denoise": True, "adaptive_sampling": False,
                "adaptive_threshold": 0.0},
    "production": {"resolution": (512, 512), "samples": 256, "denoise": True, "adaptive_sampling": True,
                   "adaptive_threshold": 0.01},
}


U64 = (0, MAX_SEED)


@dataclass(frozen=True)
class DatasetConfig:
    seed: int = _f(0, "run seed (0 .. 2**64-1); `synth plan --seed` overrides it", U64)
    identities_per_shard: int = _f(1, "identities in one shard (one worker job)", (1, 100000))
    expressions_per_identity: int = _f(13, "expressions sampled per identity (paper: 13)", (1, 1000))
    views_per_expression: int = _f(30, "viewpoints rendered per expression (paper: 30)", (1, 100000))
    shard_format: str = _f("dir", "how a committed shard is stored: 'dir' = a directory of KEY.exr/KEY.json; "
                           "'tar' = one tar of them, for WebDataset-style streaming (docs/shard-format.md)",
                           choices=("dir", "tar"))


@dataclass(frozen=True)
class CameraConfig:
    azimuth_deg: tuple[float, float] = _f((-180.0, 180.0), "azimuth range; 0 = in front of the face, "
                                          "+ toward the subject's left", (-360.0, 360.0))
    elevation_deg: tuple[float, float] = _f((-45.0, 70.0), "elevation range; +90 = above the head",
                                            (-90.0, 90.0))
    radius_m: tuple[float, float] = _f((0.9, 1.3), "distance from the look-at target (metres)", (1e-3, 1e3))
    elevation_sampling: str = _f("area", "'area': uniform over the sphere patch; 'angle': uniform in "
                                 "elevation degrees", choices=("area", "angle"))
    min_separation_deg: float = _f(25.0, "minimum angle between the viewing directions of two views of "
                                   "one expression (paper: 25)", (0.0, 180.0))
    focal_length_mm: float = _f(85.0, "lens focal length (with sensor_width_mm; ignored if fov_deg is set)",
                                (0.1, 10000.0))
    sensor_width_mm: float = _f(36.0, "sensor width; the sensor spans the image width", (0.1, 1000.0))
    fov_deg: float | None = _f(None, "horizontal field of view; overrides the focal length if set",
                               (0.01, 179.0))
    near_m: float = _f(0.05, "near clipping distance (metres)", (1e-6, 1e6))
    far_m: float = _f(10.0, "far clipping distance (metres)", (1e-6, 1e6))
    target: str = _f("eyes", "look-at point: 'eyes' = midpoint of the four eye corners (ibug68), "
                     "'landmarks' = centroid of all ibug68 landmarks, 'origin' = world origin",
                     choices=("eyes", "landmarks", "origin"))
    target_offset_m: tuple[float, float, float] = _f((0.0, 0.0, 0.0), "added to the look-at point (world)",
                                                     (-10.0, 10.0))
    roll_deg: tuple[float, float] = _f((0.0, 0.0), "camera roll about the optical axis", (-180.0, 180.0))
    principal_point_jitter_px: float = _f(0.0, "principal point offset drawn uniformly in +-this (pixels)",
                                          (0.0, 1e4))
    max_candidates: int = _f(20000, "viewpoint candidates tried per expression before giving up",
                             (1, 10**8))
    restarts: int = _f(8, "fresh restarts when the greedy sampler jams (within max_candidates)", (0, 10**4))


@dataclass(frozen=True)
class IdentityConfig:
    truncation_quantile: float = _f(0.995, "truncate identity codes at the Mahalanobis radius (to their "
                                    "prior component) that holds this fraction of the untruncated "
                                    "prior: sqrt(chi2.ppf(q, dims)); 1 = no truncation", (0.01, 1.0))
    max_mahalanobis: float | None = _f(None, "truncation radius in absolute terms (overrides the quantile)",
                                       (0.01, 1000.0))


@dataclass(frozen=True)
class ExpressionConfig:
    neutral_weight: float = _f(0.08, "relative probability of the neutral expression", (0.0, 1e6))
    preset_weight: float = _f(0.46, "relative probability of a named preset", (0.0, 1e6))
    random_weight: float = _f(0.46, "relative probability of a random sparse combination", (0.0, 1e6))
    presets: tuple[str, ...] = _f((), "preset names to draw from (empty = all built-in presets)")
    preset_intensity: tuple[float, float] = _f((0.6, 1.0), "scale applied to a preset", (0.0, 2.0))
    random_active: tuple[int, int] = _f((2, 6), "number of active components in a random combination",
                                        (1, 10000))
    random_amplitude: tuple[float, float] = _f((0.2, 1.0), "amplitude of each active component",
                                               (0.0, 100.0))
    random_symmetry: float = _f(0.6, "chance that a random combination mirrors its left/right components",
                                (0.0, 1.0))
    max_total_activation: float = _f(3.0, "random combinations are scaled down to this summed activation",
                                     (0.0, 1e6))
    code_range: tuple[float, float] = _f((0.0, 1.0), "every expression coefficient is clipped to this",
                                         (-100.0, 100.0))
    exclude: tuple[str, ...] = _f(("tongueOut", "eyeLook*"), "expression names (glob) never activated by "
                                  "random combinations (gaze is a joint rotation)")
    jaw_via: str = _f("auto", "how a preset's jaw opening is realised: 'blendshape' (jawOpen), 'joint' "
                      "(jaw rotation), 'auto' = blendshape if the model has jawOpen",
                      choices=("auto", "blendshape", "joint"))
    jaw_open_deg: tuple[float, float] = _f((0.0, 25.0), "anatomical limits of the jaw opening (joint)",
                                           (-10.0, 45.0))
    jaw_lateral_deg: tuple[float, float] = _f((-4.0, 4.0), "anatomical limits of the sideways jaw swing",
                                              (-15.0, 15.0))
    random_jaw_probability: float = _f(0.3, "chance that a random combination opens the jaw", (0.0, 1.0))
    gaze_yaw_deg: tuple[float, float] = _f((-25.0, 25.0), "eye gaze yaw limits (+ = subject's left)",
                                           (-50.0, 50.0))
    gaze_pitch_deg: tuple[float, float] = _f((-15.0, 15.0), "eye gaze pitch limits (+ = up)", (-45.0, 45.0))
    vergence_deg: tuple[float, float] = _f((0.0, 2.0), "each eye turns inward by this much", (0.0, 10.0))


@dataclass(frozen=True)
class AssetsConfig:
    manifest_dir: str = _f("", "asset catalogue folder (empty = the repository's assets_manifest/)")
    disabled_classes: tuple[str, ...] = _f((), "asset classes never used (ablations: e.g. hair, glasses)",
                                           choices=asset_classes.NAMES)


@dataclass(frozen=True)
class LightingConfig:
    environment: str = _f("uniform", "'uniform' (paper: one uniform well-lit environment) or 'hdri'",
                          choices=("uniform", "hdri"))
    strength: float = _f(1.0, "environment strength", (0.0, 1e4))
    color: tuple[float, float, float] = _f((1.0, 1.0, 1.0), "uniform environment colour (linear RGB)",
                                           (0.0, 1e4))
    hdri_files: tuple[str, ...] = _f((), "environment maps drawn per identity when environment = 'hdri'")
    hdri_rotation_deg: tuple[float, float] = _f((-180.0, 180.0), "rotation of the map about Z", (-360.0, 360.0))


@dataclass(frozen=True)
class RenderConfig:
    preset: str = _f("preview", "ci = 64x64, 4 spp; preview = 256x256, 16 spp, denoised; "
                     "production = 512x512, adaptive sampling, denoised", choices=tuple(RENDER_PRESETS))
    resolution: tuple[int, int] | None = _f(None, "width, height in pixels (unset = preset)", (1, 65536),
                                                ordered=False)
    samples: int | None = _f(None, "samples per pixel (unset = preset)", (1, 1 << 20))
    denoise: bool | None = _f(None, "denoise (unset = preset)")
    adaptive_sampling: bool | None = _f(None, "adaptive sampling (unset = preset)")
    adaptive_threshold: float | None = _f(None, "adaptive sampling noise threshold (unset = preset)",
                                          (0.0, 1.0))
    device: str = _f("auto", "render device", choices=("auto", "cpu", "gpu"))


@dataclass(frozen=True)
class Config:
    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    identity: IdentityConfig = field(default_factory=IdentityConfig)
    expression: ExpressionConfig = field(default_factory=ExpressionConfig)
    assets: AssetsConfig = field(default_factory=AssetsConfig)
    lighting: LightingConfig = field(default_factory=LightingConfig)
    render: RenderConfig = field(default_factory=RenderConfig)

    def resolved(self) -> Config:
        """Fill the render settings left unset from the render preset."""
        p = RENDER_PRESETS[self.render.preset]
        r = dataclasses.replace(self.render, **{k: (getattr(self.render, k) if getattr(self.render, k) is not None
                                                    else v) for k, v in p.items()})
        return dataclasses.replace(self, render=r)

    @property
    def fov_deg(self) -> float:
        from synth.conventions import fov_from_focal

        c = self.camera
        return c.fov_deg if c.fov_deg is not None else fov_from_focal(c.focal_length_mm, c.sensor_width_mm)


SECTIONS: dict[str, type] = configkit.sections(Config)


def check_cross(cfg: Config, where: str) -> None:
    """The rules between fields, checked once on the final configuration."""
    c, e = cfg.camera, cfg.expression
    if c.azimuth_deg[1] - c.azimuth_deg[0] > 360.0:
        raise ConfigError(f"config value camera.azimuth_deg = {list(c.azimuth_deg)} spans more than 360 degrees",
                          where, "use a range at most 360 wide, e.g. [-180, 180]")
    if not c.near_m < c.radius_m[0]:
        raise ConfigError(f"config value camera.near_m = {c.near_m} must be below camera.radius_m's low end "
                          f"{c.radius_m[0]}", where, "lower near_m or raise radius_m")
    if not c.radius_m[1] < c.far_m:
        raise ConfigError(f"config value camera.far_m = {c.far_m} must exceed camera.radius_m's high end "
                          f"{c.radius_m[1]}", where, "raise far_m or lower radius_m")
    if e.neutral_weight + e.preset_weight + e.random_weight <= 0:
        raise ConfigError("config values expression.*_weight are all zero", where,
                          "give neutral_weight, preset_weight or random_weight a positive value")
    if cfg.lighting.environment == "hdri" and not cfg.lighting.hdri_files:
        raise ConfigError("config value lighting.hdri_files is empty but lighting.environment = 'hdri'", where,
                          "list environment maps in lighting.hdri_files or use environment = 'uniform'")
    from synth.plan.expressions import PRESETS

    for p in e.presets:
        if p not in PRESETS:
            raise ConfigError(f"config value expression.presets names an unknown preset '{p}'", where,
                              f"choose from {', '.join(PRESETS)}")


def load_config(path: str | Path | None = None, overrides: list[str] | tuple[str, ...] = ()) -> Config:
    """Defaults <- TOML file <- every ``--set`` override (in order), then validated once (so
    the order of overrides does not matter); the render preset is not yet applied."""
    return configkit.load(Config(), path, overrides, check_cross)


def to_dict(cfg: Config, drop_none: bool = True) -> dict[str, dict[str, Any]]:
    """Nested plain dict (tuples as lists); unset optional values are dropped (TOML has no null)."""
    return configkit.to_dict(cfg, drop_none)


def to_toml(cfg: Config) -> str:
    """TOML text of a configuration (unset optional values omitted), one line per key."""
    return configkit.to_toml(cfg)


def explain() -> list[tuple[str, ...]]:
    """(key, type, default, doc with range/choices) for every field."""
    return configkit.reference({"default": Config()})


def markdown() -> str:
    """The key reference of docs/config.md (regenerate: python -c "import synth.config as c; print(c.markdown())")."""
    return configkit.markdown({"default": Config()})
