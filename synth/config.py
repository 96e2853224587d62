"""The typed dataset configuration: dataclasses with documented defaults that mirror the
Cafca paper, read from TOML and overridable with dotted ``--set section.key=value``.

Every section is a :func:`synth.configkit.section`: per field a default, its one-line doc
right under it and, on its type, optional inclusive ``Bounds`` (applied to every number of a
tuple) and ``Choices``. The machinery (types, TOML, overrides, did-you-mean, the reference
table) is :mod:`synth.configkit`; this module holds the sections, the render presets and the
cross-field rules (:func:`check_cross`), which run once after every override is applied.
``synth config show --explain`` prints the table; docs/config.md is generated from it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

from synth import configkit
from synth.assets import classes as asset_classes
from synth.configkit import Bounds, Choices, ConfigError, Unordered, section
from synth.seeds import MAX_SEED

# The render presets live here and nowhere else (the plan records the resolved settings).
RENDER_PRESETS: dict[str, dict[str, Any]] = {
    "ci": {"resolution": (64, 64), "samples": 4, "denoise": False, "adaptive_sampling": False,
           "adaptive_threshold": 0.0},
    "preview": {"resolution": (256, 256), "samples": 16, "denoise": True, "adaptive_sampling": False,
                "adaptive_threshold": 0.0},
    # chosen by the render-cost study (docs/performance.md): within 0.5 dB and 0.01 LPIPS of production-max on its
    # frames and crops at about 0.8 of its CPU time; path guiding is CPU-only, so on a GPU it renders 192 plain samples
    "production": {"resolution": (512, 512), "samples": 192, "denoise": True, "adaptive_sampling": True,
                   "adaptive_threshold": 0.01, "path_guiding": True},
    # 256 samples, no path guiding: on a GPU (which has no path guiding) the error production reaches on the CPU
    "production-max": {"resolution": (512, 512), "samples": 256, "denoise": True, "adaptive_sampling": True,
                       "adaptive_threshold": 0.01},
}


Seed = Annotated[int, Bounds(0, MAX_SEED)]  #: a seed of the project's seed scheme (synth.seeds)
Interval = tuple[float, float]  #: [low, high], low <= high (checked)


@section
class DatasetConfig:
    seed: Seed = 0
    """run seed (0 .. 2**64-1); `synth plan --seed` overrides it"""
    identities_per_shard: Annotated[int, Bounds(1, 100000)] = 1
    """identities in one shard (one worker job)"""
    expressions_per_identity: Annotated[int, Bounds(1, 1000)] = 13
    """expressions sampled per identity (paper: 13)"""
    views_per_expression: Annotated[int, Bounds(1, 100000)] = 30
    """viewpoints rendered per expression (paper: 30)"""
    environments_per_expression: Annotated[int, Bounds(1, 100)] = 1
    """lighting environments each expression's views are rendered in: environment 0 is lighting's (the same for
    every identity with the default studio), environments 1.. are drawn per (identity, expression, environment)
    from lighting.hdri_files when lighting.environment = 'hdri', else procedural studios at a random rotation
    (the Cafca release: 3)"""
    shard_format: Annotated[str, Choices("dir", "tar")] = "dir"
    """how a committed shard is stored: 'dir' = a directory of KEY.exr/KEY.json; 'tar' = one tar of them, for
    WebDataset-style streaming (docs/shard-format.md)"""


@section
class CameraConfig:
    azimuth_deg: Annotated[Interval, Bounds(-360.0, 360.0)] = (-180.0, 180.0)
    """azimuth range; 0 = in front of the face, + toward the subject's left"""
    elevation_deg: Annotated[Interval, Bounds(-90.0, 90.0)] = (-45.0, 70.0)
    """elevation range; +90 = above the head"""
    radius_m: Annotated[Interval, Bounds(1e-3, 1e3)] = (0.9, 1.3)
    """distance from the look-at target (metres) when camera.distance = 'range'"""
    distance: Annotated[str, Choices("fit", "range")] = "fit"
    """'fit': per view, the distance at which the head's bounding sphere fills camera.head_fill of the half field
    of view (shorter image side); 'range': drawn from camera.radius_m"""
    head_fill: Annotated[Interval, Bounds(0.05, 1.0)] = (0.75, 0.95)
    """with distance = 'fit': the head sphere's angular radius over the half field of view, drawn uniformly"""
    head_margin_m: Annotated[float, Bounds(0.0, 1.0)] = 0.03
    """added to the radius of each head's bounding sphere (expressions, the jaw), besides the reach of its
    planned hair and headwear"""
    elevation_sampling: Annotated[str, Choices("area", "angle")] = "area"
    """'area': uniform over the sphere patch; 'angle': uniform in elevation degrees"""
    min_separation_deg: Annotated[float, Bounds(0.0, 180.0)] = 25.0
    """minimum angle between the viewing directions of two views of one expression (paper: 25)"""
    focal_length_mm: Annotated[float, Bounds(0.1, 10000.0)] = 85.0
    """lens focal length (with sensor_width_mm; ignored if fov_deg is set)"""
    sensor_width_mm: Annotated[float, Bounds(0.1, 1000.0)] = 36.0
    """sensor width; the sensor spans the image width"""
    fov_deg: Annotated[float | None, Bounds(0.01, 179.0)] = None
    """horizontal field of view; overrides the focal length if set"""
    near_m: Annotated[float, Bounds(1e-6, 1e6)] = 0.05
    """near clipping distance (metres)"""
    far_m: Annotated[float, Bounds(1e-6, 1e6)] = 10.0
    """far clipping distance (metres)"""
    target: Annotated[str, Choices("head", "eyes", "landmarks", "origin")] = "head"
    """look-at point: 'head' = centre of the identity's head bounding box (neck and shoulders excluded), 'eyes' =
    midpoint of the four eye corners (ibug68), 'landmarks' = centroid of all ibug68 landmarks, 'origin' =
    world origin"""
    target_offset_m: Annotated[tuple[float, float, float], Bounds(-10.0, 10.0)] = (0.0, 0.0, 0.0)
    """added to the look-at point (world)"""
    roll_deg: Annotated[Interval, Bounds(-180.0, 180.0)] = (0.0, 0.0)
    """camera roll about the optical axis"""
    principal_point_jitter_px: Annotated[float, Bounds(0.0, 1e4)] = 0.0
    """principal point offset drawn uniformly in +-this (pixels)"""
    max_candidates: Annotated[int, Bounds(1, 10**8)] = 20000
    """viewpoint candidates tried per expression before giving up"""
    restarts: Annotated[int, Bounds(0, 10**4)] = 8
    """fresh restarts when the greedy sampler jams (within max_candidates)"""


@section
class IdentityConfig:
    truncation_quantile: Annotated[float, Bounds(0.01, 1.0)] = 0.995
    """truncate identity codes at the Mahalanobis radius (to their prior component) that holds this fraction of
    the untruncated prior: sqrt(chi2.ppf(q, dims)); 1 = no truncation"""
    max_mahalanobis: Annotated[float | None, Bounds(0.01, 1000.0)] = None
    """truncation radius in absolute terms (overrides the quantile)"""
    head_shape: Annotated[str, Choices("auto", "anthropometric", "none")] = "auto"
    """'anthropometric': a code whose neutral head leaves one of the ranges below (head breadth and length, face
    height and width, cephalic and facial index) is redrawn, up to head_shape_attempts times (docs/plan-format.md,
    docs/realism.md 'Head shapes'); 'auto': the same where the model's mean head lies inside every range (else
    every draw is kept: a model not of adult heads at their size); 'none': every draw is kept"""
    head_breadth_mm: Annotated[Interval, Bounds(1.0, 1000.0)] = (131.0, 180.0)
    """range of the head breadth (eurion-eurion, mm): the smallest and largest of ANSUR II's 6,068 adults"""
    head_length_mm: Annotated[Interval, Bounds(1.0, 1000.0)] = (168.0, 225.0)
    """range of the head length (glabella-opisthocranion, mm): ANSUR II's smallest and largest"""
    face_height_mm: Annotated[Interval, Bounds(1.0, 1000.0)] = (91.0, 156.0)
    """range of the face height (sellion-menton, mm): ANSUR II's smallest and largest"""
    face_width_mm: Annotated[Interval, Bounds(1.0, 1000.0)] = (116.0, 174.0)
    """range of the face width (bizygomatic, mm): ANSUR II's smallest and largest"""
    cephalic_index: Annotated[Interval, Bounds(1.0, 1000.0)] = (70.0, 90.0)
    """range of 100 x head breadth / head length (adults: 77.5 at ANSUR II's means)"""
    facial_index: Annotated[Interval, Bounds(1.0, 1000.0)] = (65.0, 100.0)
    """range of 100 x face height / face width (adults: 85.5 at ANSUR II's means; the default model's template
    has 73.7, so the lower end sits below the adults')"""
    head_shape_attempts: Annotated[int, Bounds(1, 1000)] = 32
    """redraws per identity; if all leave the ranges, the draw closest to them is kept"""


@section
class ExpressionConfig:
    neutral_weight: Annotated[float, Bounds(0.0, 1e6)] = 0.08
    """relative probability of the neutral expression"""
    preset_weight: Annotated[float, Bounds(0.0, 1e6)] = 0.46
    """relative probability of a named preset"""
    random_weight: Annotated[float, Bounds(0.0, 1e6)] = 0.46
    """relative probability of a random sparse combination"""
    presets: tuple[str, ...] = ()
    """preset names to draw from (empty = all built-in presets)"""
    preset_intensity: Annotated[Interval, Bounds(0.0, 2.0)] = (0.6, 1.0)
    """scale applied to a preset"""
    random_active: Annotated[tuple[int, int], Bounds(1, 10000)] = (2, 6)
    """number of active components in a random combination"""
    random_amplitude: Annotated[Interval, Bounds(0.0, 100.0)] = (0.2, 1.0)
    """amplitude of each active component"""
    random_symmetry: Annotated[float, Bounds(0.0, 1.0)] = 0.6
    """chance that a random combination mirrors its left/right components"""
    max_total_activation: Annotated[float, Bounds(0.0, 1e6)] = 3.0
    """random combinations are scaled down to this summed activation"""
    code_range: Annotated[Interval, Bounds(-100.0, 100.0)] = (0.0, 1.0)
    """every expression coefficient is clipped to this"""
    exclude: tuple[str, ...] = ("tongueOut", "eyeLook*")
    """expression names (glob) never activated by random combinations (gaze is a joint rotation)"""
    jaw_via: Annotated[str, Choices("auto", "blendshape", "joint")] = "auto"
    """how a preset's jaw opening is realised: 'blendshape' (jawOpen), 'joint' (jaw rotation), 'auto' =
    blendshape if the model has jawOpen"""
    jaw_open_deg: Annotated[Interval, Bounds(-10.0, 45.0)] = (0.0, 25.0)
    """anatomical limits of the jaw opening (joint)"""
    jaw_lateral_deg: Annotated[Interval, Bounds(-15.0, 15.0)] = (-4.0, 4.0)
    """anatomical limits of the sideways jaw swing"""
    random_jaw_probability: Annotated[float, Bounds(0.0, 1.0)] = 0.3
    """chance that a random combination opens the jaw"""
    gaze_yaw_deg: Annotated[Interval, Bounds(-50.0, 50.0)] = (-25.0, 25.0)
    """eye gaze yaw limits (+ = subject's left)"""
    gaze_pitch_deg: Annotated[Interval, Bounds(-45.0, 45.0)] = (-15.0, 15.0)
    """eye gaze pitch limits (+ = up)"""
    gaze_distribution: Annotated[str, Choices("normal", "uniform")] = "normal"
    """how gaze yaw and pitch are drawn within their limits: 'normal' (centred on the primary position,
    standard deviations gaze_sd_deg, truncated to the limits; most eye-in-head directions lie near it) or
    'uniform'"""
    gaze_sd_deg: Annotated[tuple[float, float], Bounds(0.1, 90.0)] = (6.0, 6.0)
    """standard deviations of gaze yaw and pitch before truncation (gaze_distribution = 'normal')"""
    vergence_deg: Annotated[Interval, Bounds(0.0, 10.0)] = (0.0, 2.0)
    """each eye turns inward by this much"""


@section
class AssetsConfig:
    manifest_dir: str = ""
    """asset catalogue folder (empty = the repository's assets_manifest/)"""
    disabled_classes: Annotated[tuple[str, ...], Choices(*asset_classes.NAMES)] = ()
    """asset classes never used (ablations: e.g. hair, glasses)"""


@section
class SkinConfig:
    ita_weights: Annotated[tuple[float, ...], Bounds(0.0, 1e6)] = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    """relative probability of the six ITA skin-tone categories, lightest first: very light (> 55 deg), light
    (41-55), intermediate (28-41), tan (10-28), brown (-30-10), dark (< -30); uniform in ITA within a category"""
    ita_limits_deg: Annotated[Interval, Bounds(-80.0, 80.0)] = (-55.0, 62.0)
    """ITA range of all skin tones: the low end of 'dark', the high end of 'very light'"""


@section
class LightingConfig:
    environment: Annotated[str, Choices("studio", "uniform", "hdri")] = "studio"
    """'studio' (one soft procedural environment, the same for every identity: key, fill and ambient; the paper's
    single environment chosen to minimize shadows on the face), 'uniform' (constant radiance: no shading) or
    'hdri' (environment maps from lighting.hdri_files)"""
    strength: Annotated[float, Bounds(0.0, 1e4)] = 1.0
    """environment strength"""
    color: Annotated[tuple[float, float, float], Bounds(0.0, 1e4)] = (1.0, 1.0, 1.0)
    """colour of the uniform and studio environments (linear RGB)"""
    studio_key_deg: Annotated[tuple[float, float], Bounds(-360.0, 360.0), Unordered()] = (-35.0, 30.0)
    """studio key light direction (azimuth, elevation), camera convention: azimuth 0 in front of the face, + toward
    the subject's left"""
    studio_key_size_deg: Annotated[float, Bounds(5.0, 90.0)] = 25.0
    """angular spread of the studio key light"""
    studio_key_share: Annotated[float, Bounds(0.0, 1.0)] = 0.45
    """share of the studio environment's power in the key light"""
    studio_fill_deg: Annotated[tuple[float, float], Bounds(-360.0, 360.0), Unordered()] = (60.0, 5.0)
    """studio fill light direction (azimuth, elevation)"""
    studio_fill_size_deg: Annotated[float, Bounds(5.0, 90.0)] = 45.0
    """angular spread of the studio fill light"""
    studio_fill_share: Annotated[float, Bounds(0.0, 1.0)] = 0.2
    """share of the studio environment's power in the fill light (the rest is ambient, sky brighter than floor)"""
    studio_rotation_deg: Annotated[Interval, Bounds(-360.0, 360.0)] = (0.0, 0.0)
    """rotation of the studio environment about the vertical, drawn per identity ([0, 0]: the same for all)"""
    hdri_files: tuple[str, ...] = ()
    """environment maps drawn per identity when environment = 'hdri'"""
    hdri_rotation_deg: Annotated[Interval, Bounds(-360.0, 360.0)] = (-180.0, 180.0)
    """rotation of the map about Z"""


@section
class RenderConfig:
    preset: Annotated[str, Choices(*RENDER_PRESETS)] = "preview"
    """ci = 64x64, 4 spp; preview = 256x256, 16 spp, denoised; production = 512x512, 192 spp adaptive, path guided,
    denoised; production-max = 512x512, 256 spp adaptive, denoised"""
    resolution: Annotated[tuple[int, int] | None, Bounds(1, 65536), Unordered()] = None
    """width, height in pixels (unset = preset)"""
    samples: Annotated[int | None, Bounds(1, 1 << 20)] = None
    """samples per pixel (unset = preset)"""
    denoise: bool | None = None
    """denoise (unset = preset)"""
    adaptive_sampling: bool | None = None
    """adaptive sampling (unset = preset)"""
    adaptive_threshold: Annotated[float | None, Bounds(0.0, 1.0)] = None
    """adaptive sampling noise threshold (unset = preset)"""
    device: Annotated[str, Choices("auto", "cpu", "gpu")] = "auto"
    """render device"""
    diffuse_bounces: Annotated[int | None, Bounds(0, 1024)] = None
    """diffuse bounces of a light path (unset = preset; Cycles' 4 where the preset leaves it)"""
    glossy_bounces: Annotated[int | None, Bounds(0, 1024)] = None
    """glossy bounces of a light path (unset = preset; Cycles' 4 where the preset leaves it)"""
    transmission_bounces: Annotated[int | None, Bounds(0, 1024)] = None
    """transmission bounces: glasses' lenses, the eyes' cornea (unset = preset; Cycles' 12 where the preset leaves it)"""
    transparent_bounces: Annotated[int | None, Bounds(0, 1024)] = None
    """transparent bounces: strands and lashes seen through each other (unset = preset; Cycles' 8 where the preset
    leaves it)"""
    hair_shape: Annotated[str | None, Choices("ribbons", "thick")] = None
    """hair, beard, brow and lash curves as flat camera-facing ribbons or round 3D curves (unset = preset; ribbons
    where the preset leaves it)"""
    light_tree: bool | None = None
    """Cycles' light tree for many lights (unset = preset; on where the preset leaves it)"""
    caustics: bool | None = None
    """reflective and refractive caustics (unset = preset; on where the preset leaves it)"""
    denoise_prefilter: Annotated[str | None, Choices("accurate", "fast", "none")] = None
    """prefilter of the denoiser's albedo and normal guides (unset = preset; accurate where the preset leaves it)"""
    denoise_quality: Annotated[str | None, Choices("high", "balanced", "fast")] = None
    """OpenImageDenoise quality (unset = preset; high where the preset leaves it)"""
    path_guiding: bool | None = None
    """Cycles' path guiding on surfaces, deterministic training (CPU only: a GPU renders without it; unset = preset;
    off where the preset leaves it)"""


@dataclass(frozen=True)
class Config:
    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    identity: IdentityConfig = field(default_factory=IdentityConfig)
    expression: ExpressionConfig = field(default_factory=ExpressionConfig)
    assets: AssetsConfig = field(default_factory=AssetsConfig)
    skin: SkinConfig = field(default_factory=SkinConfig)
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
    w, lim = cfg.skin.ita_weights, cfg.skin.ita_limits_deg
    if len(w) != 6 or sum(w) <= 0:
        raise ConfigError(f"config value skin.ita_weights = {list(w)} must hold 6 weights, not all zero", where,
                          "give one weight per ITA category, lightest first, e.g. [1, 1, 1, 1, 1, 1]")
    if not (lim[0] < -30.0 and lim[1] > 55.0):
        raise ConfigError(f"config value skin.ita_limits_deg = {list(lim)} must reach below -30 and above 55",
                          where, "widen it, e.g. [-55, 62] (use skin.ita_weights to drop a category)")
    if cfg.lighting.studio_key_share + cfg.lighting.studio_fill_share > 1.0:
        raise ConfigError(f"config values lighting.studio_key_share + studio_fill_share = "
                          f"{cfg.lighting.studio_key_share + cfg.lighting.studio_fill_share:g} exceed 1", where,
                          "lower them: their sum is the share of the environment's power in the two lights")
    if cfg.lighting.environment == "hdri" and not cfg.lighting.hdri_files:
        raise ConfigError("config value lighting.hdri_files is empty but lighting.environment = 'hdri'", where,
                          "list environment maps in lighting.hdri_files or use environment = 'studio' or 'uniform'")
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
