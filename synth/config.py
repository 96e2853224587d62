"""The typed dataset configuration: dataclasses with documented defaults that mirror the
Cafca paper, read from TOML and overridable with dotted ``--set section.key=value``.

Every field carries ``metadata``: ``doc`` (one line), optional ``range`` (inclusive
numeric bounds, applied to every number of a tuple) and ``choices``. Unknown keys and
out-of-range values raise :class:`synth.errors.SynthError` naming the key.
``synth config show --explain`` prints the table; docs/config.md is generated from it.
"""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from synth.assets import classes as asset_classes
from synth.errors import SynthError

# The render presets live here and nowhere else (the plan records the resolved settings).
RENDER_PRESETS: dict[str, dict[str, Any]] = {
    "ci": {"resolution": (64, 64), "samples": 4, "denoise": False, "adaptive_sampling": False,
           "adaptive_threshold": 0.0},
    "preview": {"resolution": (256, 256), "samples": 16, "denoise": True, "adaptive_sampling": False,
                "adaptive_threshold": 0.0},
    "production": {"resolution": (512, 512), "samples": 256, "denoise": True, "adaptive_sampling": True,
                   "adaptive_threshold": 0.01},
}


def _f(default, doc: str, range=None, choices=None, ordered=True):  # noqa: A002 - metadata key
    """A documented field; a numeric pair is a [low, high] range unless ``ordered=False``."""
    md = {"doc": doc, "ordered": ordered}
    if range is not None:
        md["range"] = range
    if choices is not None:
        md["choices"] = tuple(choices)
    if isinstance(default, (list, tuple)):
        return field(default_factory=lambda d=tuple(default): d, metadata=md)
    return field(default=default, metadata=md)


U64 = (0, (1 << 64) - 1)


@dataclass(frozen=True)
class DatasetConfig:
    seed: int = _f(0, "run seed (0 .. 2**64-1); `synth plan --seed` overrides it", U64)
    identities_per_shard: int = _f(1, "identities in one shard (one worker job)", (1, 100000))
    expressions_per_identity: int = _f(13, "expressions sampled per identity (paper: 13)", (1, 1000))
    views_per_expression: int = _f(30, "viewpoints rendered per expression (paper: 30)", (1, 100000))


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


SECTIONS: dict[str, type] = {f.name: typing.get_type_hints(Config)[f.name] for f in dataclasses.fields(Config)}


# --------------------------------------------------------------------------- validation


def _type_name(tp) -> str:
    return getattr(tp, "__name__", str(tp))


def _coerce(value: Any, tp, key: str, md: dict, where: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and the metadata; return the typed value."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _coerce(value, args[0], key, md, where)

    def bad(what: str, fix: str):
        raise SynthError(f"config value {key} = {value!r} {what}", where, fix)

    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            bad("is not a list", f"write it as a list, e.g. {key}=[...]")
        if len(args) == 2 and args[1] is Ellipsis:
            items = [_coerce(v, args[0], key, {k: v2 for k, v2 in md.items() if k != "doc"}, where) for v in value]
            return tuple(items)
        if len(value) != len(args):
            bad(f"must have {len(args)} elements", f"write [{', '.join(_type_name(a) for a in args)}]")
        items = tuple(_coerce(v, a, key, md, where) for v, a in zip(value, args))
        if len(args) == 2 and md.get("ordered", True) and args[0] in (int, float) and items[0] > items[1]:
            bad("is an empty range (low > high)", "give [low, high] with low <= high")
        return items
    if tp is bool:
        if not isinstance(value, bool):
            bad("is not true or false", "write true or false")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            bad("is not an integer", "write a whole number")
    elif tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            bad("is not a number", "write a number")
        value = float(value)
        if value != value or value in (float("inf"), float("-inf")):
            bad("is not finite", "write a finite number")
    elif tp is str:
        if not isinstance(value, str):
            bad("is not a string", "write it in quotes")
    if "range" in md and tp in (int, float):
        lo, hi = md["range"]
        if not lo <= value <= hi:
            bad(f"is out of range [{lo}, {hi}]", f"choose a value between {lo} and {hi}")
    if "choices" in md and value not in md["choices"]:
        bad("is not allowed", f"choose one of {', '.join(md['choices'])}")
    return value


def _section_fields(name: str) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(SECTIONS[name])}


def build_config(data: dict[str, Any], where: str = "config") -> Config:
    """Validate a nested dict ``{section: {key: value}}`` (missing keys = defaults)."""
    if not isinstance(data, dict):
        raise SynthError("configuration must be a table of sections", where, f"sections: {', '.join(SECTIONS)}")
    sections = {}
    for sec, values in data.items():
        if sec not in SECTIONS:
            near = difflib.get_close_matches(sec, list(SECTIONS), n=1)
            hint = f"did you mean '{near[0]}'? " if near else ""
            raise SynthError(f"unknown config section '{sec}'", where, f"{hint}known sections: {', '.join(SECTIONS)}")
        if not isinstance(values, dict):
            raise SynthError(f"config section '{sec}' must be a table", where, f"write [{sec}] and key = value lines")
        fields = _section_fields(sec)
        hints = typing.get_type_hints(SECTIONS[sec])
        kw = {}
        for k, v in values.items():
            if k not in fields:
                near = difflib.get_close_matches(k, list(fields), n=1)
                hint = f"did you mean '{sec}.{near[0]}'? " if near else ""
                raise SynthError(f"unknown config key '{sec}.{k}'", where,
                                 f"{hint}known keys in [{sec}]: {', '.join(fields)}")
            kw[k] = _coerce(v, hints[k], f"{sec}.{k}", dict(fields[k].metadata), where)
        sections[sec] = SECTIONS[sec](**kw)
    cfg = Config(**sections)
    _check_cross(cfg, where)
    return cfg


def _check_cross(cfg: Config, where: str) -> None:
    c, e = cfg.camera, cfg.expression
    if c.azimuth_deg[1] - c.azimuth_deg[0] > 360.0:
        raise SynthError(f"config value camera.azimuth_deg = {list(c.azimuth_deg)} spans more than 360 degrees",
                         where, "use a range at most 360 wide, e.g. [-180, 180]")
    if not c.near_m < c.radius_m[0]:
        raise SynthError(f"config value camera.near_m = {c.near_m} must be below camera.radius_m's low end "
                         f"{c.radius_m[0]}", where, "lower near_m or raise radius_m")
    if not c.radius_m[1] < c.far_m:
        raise SynthError(f"config value camera.far_m = {c.far_m} must exceed camera.radius_m's high end "
                         f"{c.radius_m[1]}", where, "raise far_m or lower radius_m")
    if e.neutral_weight + e.preset_weight + e.random_weight <= 0:
        raise SynthError("config values expression.*_weight are all zero", where,
                         "give neutral_weight, preset_weight or random_weight a positive value")
    if cfg.lighting.environment == "hdri" and not cfg.lighting.hdri_files:
        raise SynthError("config value lighting.hdri_files is empty but lighting.environment = 'hdri'", where,
                         "list environment maps in lighting.hdri_files or use environment = 'uniform'")
    from synth.plan.expressions import PRESETS

    for p in e.presets:
        if p not in PRESETS:
            raise SynthError(f"config value expression.presets names an unknown preset '{p}'", where,
                             f"choose from {', '.join(PRESETS)}")


# --------------------------------------------------------------------------- reading


def parse_override(item: str) -> tuple[str, str, Any]:
    """'section.key=value' -> (section, key, value); the value is read as TOML, else as a bare string."""
    if "=" not in item or "." not in item.split("=", 1)[0]:
        raise SynthError(f"bad override '{item}'", "--set", "write --set section.key=value, e.g. camera.fov_deg=30")
    lhs, rhs = item.split("=", 1)
    sec, key = lhs.strip().split(".", 1)
    try:
        value = tomllib.loads(f"v = {rhs.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = rhs.strip()
    return sec, key, value


def read_toml(path: str | Path) -> dict[str, Any]:
    p = Path(path)
    if not p.is_file():
        raise SynthError("config file not found", str(p), "check the --config path")
    try:
        with p.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as err:
        raise SynthError(f"config file is not valid TOML: {err}", str(p), "fix the syntax") from None


def load_config(path: str | Path | None = None, overrides: list[str] | tuple[str, ...] = ()) -> Config:
    """Defaults <- TOML file <- ``--set`` overrides; validated; render preset not yet applied."""
    data: dict[str, Any] = read_toml(path) if path else {}
    build_config(data, str(path) if path else "defaults")  # report file errors against the file
    for item in overrides:
        sec, key, value = parse_override(item)
        if sec in data and not isinstance(data[sec], dict):
            raise SynthError(f"config section '{sec}' must be a table", "--set", "fix the config file")
        data.setdefault(sec, {})[key] = value
        build_config(data, f"--set {item}")
    return build_config(data, "--set" if overrides else (str(path) if path else "defaults"))


# --------------------------------------------------------------------------- output


def to_dict(cfg: Config, drop_none: bool = True) -> dict[str, dict[str, Any]]:
    """Nested plain dict (tuples as lists); unset optional values are dropped (TOML has no null)."""
    out: dict[str, dict[str, Any]] = {}
    for sec in SECTIONS:
        s = getattr(cfg, sec)
        d = {}
        for f in dataclasses.fields(s):
            v = getattr(s, f.name)
            if v is None and drop_none:
                continue
            d[f.name] = list(v) if isinstance(v, tuple) else v
        out[sec] = d
    return out


def _toml_value(v: Any) -> str:
    import json

    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a valid TOML basic string
    return "[" + ", ".join(_toml_value(x) for x in v) + "]"


def to_toml(cfg: Config) -> str:
    """TOML text of a configuration (unset optional values omitted), one line per key."""
    blocks = []
    for sec, values in to_dict(cfg).items():
        blocks.append(f"[{sec}]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in values.items()))
    return "\n".join(blocks)


def explain() -> list[tuple[str, str, str, str]]:
    """(key, type, default, doc with range/choices) for every field."""
    rows = []
    for sec, cls in SECTIONS.items():
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
            md = f.metadata
            doc = md.get("doc", "")
            if "range" in md:
                doc += f" [range {md['range'][0]} .. {md['range'][1]}]"
            if "choices" in md:
                doc += f" [one of: {', '.join(md['choices'])}]"
            tp = hints[f.name]
            t = tp.__name__ if isinstance(tp, type) else str(tp).replace("typing.", "")
            rows.append((f"{sec}.{f.name}", t, "unset" if default is None else repr(
                list(default) if isinstance(default, tuple) else default), doc))
    return rows


def markdown() -> str:
    """The key reference of docs/config.md (regenerate: python -c "import synth.config as c; print(c.markdown())")."""
    lines = ["| key | type | default | meaning |", "|---|---|---|---|"]
    for key, t, default, doc in explain():
        lines.append(f"| `{key}` | {t} | `{default}` | {doc.replace('|', '/')} |")
    return "\n".join(lines) + "\n"
