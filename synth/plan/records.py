"""Typed records of what a shard spec carries: the plan -> worker boundary.

A shard spec (``DIR/shards/shard_NNNNNN.json``, docs/plan-format.md) is read once into a
:class:`ShardSpec` (:meth:`ShardSpec.from_json`: checked, one SynthError line on a bad spec)
and everything downstream (the worker, the scene, the rigs, :mod:`synth.assets.fit`) reads
attributes of these frozen records instead of looking keys up with defaults of its own. The
defaults live once: in the records here and the per-class parameter records of
:mod:`synth.assets.params` (filled when a record is made, from the catalogue's values and the
project's ``DEFAULT_*`` constants).

JSON stays the wire format. ``to_json()`` gives back exactly the JSON the record was read
from (the same keys in the same order, the values unchanged), so the plan's bytes, its hash
and every frame JSON are what they were: ``orjson.dumps(ShardSpec.from_json(s).to_json())``
is the shard file (``tests/plan/test_records.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from synth.assets.jsonrecord import as_object, of_type, record_from_json, record_to_json, required, spec_error
from synth.assets.params import AssetPick, SkinParams, assets_from_json

Vec = tuple[float, ...]
Mat = tuple[tuple[float, ...], ...]


def _num(d: Mapping, key: str, where: str) -> float:
    return required(d, key, (int, float), where)


def _vec(d: Mapping, key: str, where: str, n: int | None = None) -> Vec:
    v = required(d, key, list, where)
    if (n is not None and len(v) != n) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        raise spec_error(f"'{key}' is not a list of {n or 'some'} numbers", where)
    return tuple(v)


def _mat(d: Mapping, key: str, where: str, n: int) -> Mat:
    rows = required(d, key, list, where)
    if len(rows) != n:
        raise spec_error(f"'{key}' is not a {n}x{n} matrix", where)
    return tuple(_vec({key: r}, key, where, n) for r in rows)


# --------------------------------------------------------------------------- lighting


@dataclass(frozen=True)
class UniformLight:
    """A constant environment."""

    strength: float
    color: Vec = (1.0, 1.0, 1.0)
    environment: str = "uniform"

    def to_json(self) -> dict[str, Any]:
        return {"environment": "uniform", "strength": self.strength, "color": self.color}


@dataclass(frozen=True)
class StudioLight:
    """The procedural studio (synth.appearance.lighting.Studio) at ``strength`` x ``color``."""

    strength: float
    color: Vec
    key_deg: Vec
    key_size_deg: float
    key_share: float
    fill_deg: Vec
    fill_size_deg: float
    fill_share: float
    rotation_deg: float = 0.0
    environment: str = "studio"

    def studio(self):
        from synth.appearance.lighting import Studio

        return Studio(key_deg=self.key_deg, key_size_deg=float(self.key_size_deg), key_share=float(self.key_share),
                      fill_deg=self.fill_deg, fill_size_deg=float(self.fill_size_deg),
                      fill_share=float(self.fill_share), rotation_deg=float(self.rotation_deg))

    def to_json(self) -> dict[str, Any]:
        return {"environment": "studio", "strength": self.strength, "color": self.color, "key_deg": self.key_deg,
                "key_size_deg": self.key_size_deg, "key_share": self.key_share, "fill_deg": self.fill_deg,
                "fill_size_deg": self.fill_size_deg, "fill_share": self.fill_share, "rotation_deg": self.rotation_deg}


@dataclass(frozen=True)
class HdriLight:
    """An HDR environment map turned by ``rotation_deg`` about the vertical."""

    file: str
    rotation_deg: float
    strength: float
    environment: str = "hdri"

    def to_json(self) -> dict[str, Any]:
        return {"environment": "hdri", "file": self.file, "rotation_deg": self.rotation_deg, "strength": self.strength}


Lighting = UniformLight | StudioLight | HdriLight


def lighting_from_json(d: Any, where: str) -> Lighting:
    """A plan's lighting record (synth.plan.assets.sample_lighting / sample_environment)."""
    d = as_object(d, where)
    kind = required(d, "environment", str, where)
    s = _num(d, "strength", where)
    if kind == "uniform":
        out: Lighting = UniformLight(s, _vec(d, "color", where, 3))
    elif kind == "studio":
        out = StudioLight(s, _vec(d, "color", where, 3), _vec(d, "key_deg", where, 2), _num(d, "key_size_deg", where),
                          _num(d, "key_share", where), _vec(d, "fill_deg", where, 2), _num(d, "fill_size_deg", where),
                          _num(d, "fill_share", where), _num(d, "rotation_deg", where))
    elif kind == "hdri":
        out = HdriLight(required(d, "file", str, where), _num(d, "rotation_deg", where), s)
    else:
        raise spec_error(f"unknown environment '{kind}' (uniform, studio or hdri)", where)
    if list(out.to_json()) != list(d):
        raise spec_error(f"lighting keys {list(d)} are not the {kind} environment's {list(out.to_json())}", where)
    return out


# --------------------------------------------------------------------------- frames and expressions


@dataclass(frozen=True)
class Camera:
    """A frame's camera (OpenCV convention, docs/conventions.md)."""

    K: Mat
    world_to_camera: Mat
    camera_to_world: Mat
    width: int
    height: int
    near: float
    far: float
    azimuth_deg: float
    elevation_deg: float
    radius_m: float
    target: Vec

    @classmethod
    def from_json(cls, d: Any, where: str) -> Camera:
        def mat(n: int):
            return lambda d, key, where: _mat(d, key, where, n)

        readers = {"K": mat(3), "world_to_camera": mat(4), "camera_to_world": mat(4), "width": of_type(int),
                   "height": of_type(int), "near": _num, "far": _num, "azimuth_deg": _num, "elevation_deg": _num,
                   "radius_m": _num, "target": lambda d, key, where: _vec(d, key, where, 3)}
        return record_from_json(cls, d, where, readers)

    def to_json(self) -> dict[str, Any]:
        return record_to_json(self)


@dataclass(frozen=True)
class Frame:
    """One planned frame: its key, indices, render seed and camera. ``environment_index`` is
    None in plans of one environment per expression (the key is then left out of the JSON)."""

    frame_id: str
    identity_index: int
    expression_index: int
    environment_index: int | None
    view_index: int
    seed: int
    camera: Camera

    @classmethod
    def from_json(cls, d: Any, where: str) -> Frame:
        readers = {"environment_index": lambda d, key, where: required(d, key, int, where) if key in d else None}
        readers |= {k: of_type(str if k == "frame_id" else int)
                    for k in ("frame_id", "identity_index", "expression_index", "view_index", "seed")}
        readers["camera"] = lambda d, key, where: Camera.from_json(d.get(key), f"{where}/{key}")
        return record_from_json(cls, d, where, readers)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"frame_id": self.frame_id, "identity_index": self.identity_index,
                               "expression_index": self.expression_index}
        if self.environment_index is not None:
            out["environment_index"] = self.environment_index
        out.update(view_index=self.view_index, seed=self.seed, camera=self.camera.to_json())
        return out


@dataclass(frozen=True)
class CameraSampling:
    """How many candidates the view sampler drew for an expression, and its restarts."""

    candidates: int
    restarts: int

    def to_json(self) -> dict[str, int]:
        return record_to_json(self)


@dataclass(frozen=True)
class Expression:
    """One planned expression: the model's expression code, joint rotations (axis-angle,
    radians, joints not listed are not rotated), the pose it was drawn as, and its frames;
    ``environments`` (plans of more than one per expression): the lighting of each."""

    expression_index: int
    kind: str
    preset: str | None
    expression_code: Vec
    joint_rotations: Mapping[str, Vec]
    pose: Mapping[str, float]
    camera_sampling: CameraSampling | None
    environments: tuple[Lighting, ...] | None
    frames: tuple[Frame, ...]

    @classmethod
    def from_json(cls, d: Any, where: str) -> Expression:
        d = as_object(d, where)
        kind = required(d, "kind", str, where)
        if kind not in ("neutral", "preset", "random"):
            raise spec_error(f"expression kind '{kind}' is not neutral, preset or random", where)
        if "preset" not in d or not isinstance(d["preset"], (str, type(None))):
            raise spec_error("'preset' is missing or not a string/null", where)
        rots = as_object(required(d, "joint_rotations", dict, where), where)
        pose = required(d, "pose", dict, where)
        cs = d.get("camera_sampling")
        envs = d.get("environments")
        return cls(required(d, "expression_index", int, where), kind, d["preset"], _vec(d, "expression_code", where),
                   {k: _vec(rots, k, f"{where}/joint_rotations", 3) for k in rots},
                   {k: _num(pose, k, f"{where}/pose") for k in pose},
                   None if cs is None else CameraSampling(required(cs, "candidates", int, where),
                                                          required(cs, "restarts", int, where)),
                   None if envs is None else tuple(lighting_from_json(e, f"{where}/environments/{k}")
                                                   for k, e in enumerate(envs)),
                   tuple(Frame.from_json(f, f"{where}/frames/{k}")
                         for k, f in enumerate(required(d, "frames", list, where))))

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"expression_index": self.expression_index, "kind": self.kind, "preset": self.preset,
                               "expression_code": self.expression_code,
                               "joint_rotations": dict(self.joint_rotations), "pose": dict(self.pose)}
        if self.camera_sampling is not None:
            out["camera_sampling"] = self.camera_sampling.to_json()
        if self.environments is not None:
            out["environments"] = [e.to_json() for e in self.environments]
        out["frames"] = [f.to_json() for f in self.frames]
        return out


# --------------------------------------------------------------------------- identities and shards


@dataclass(frozen=True)
class Identity:
    """One identity: its code, look-at target, assets (every class, None where absent), the
    skin parameters (its skin pick's; the JSON repeats them as ``skin``), its lighting
    (environment 0 of every expression) and expressions."""

    identity_index: int
    identity_code: Vec
    target: Vec
    assets: Mapping[str, AssetPick | None]
    lighting: Lighting
    expressions: tuple[Expression, ...]

    @property
    def skin(self) -> SkinParams:
        """The skin parameters (the defaults where the identity has no skin pick)."""
        pick = self.assets.get("skin")
        return pick.params if pick is not None else SkinParams()

    @classmethod
    def from_json(cls, d: Any, where: str) -> Identity:
        d = as_object(d, where)
        assets = assets_from_json(required(d, "assets", dict, where), f"{where}/assets")
        skin = assets.get("skin")
        if "skin" not in d or d["skin"] != (None if skin is None else skin.params.to_json()):
            raise spec_error("'skin' is not a copy of assets.skin.params", where)
        return cls(required(d, "identity_index", int, where), _vec(d, "identity_code", where),
                   _vec(d, "target", where, 3), assets, lighting_from_json(d.get("lighting"), f"{where}/lighting"),
                   tuple(Expression.from_json(e, f"{where}/expressions/{k}")
                         for k, e in enumerate(required(d, "expressions", list, where))))

    def to_json(self) -> dict[str, Any]:
        skin = self.assets.get("skin")
        return {"identity_index": self.identity_index, "identity_code": self.identity_code, "target": self.target,
                "assets": {c: None if e is None else e.to_json() for c, e in self.assets.items()},
                "skin": None if skin is None else skin.params.to_json(), "lighting": self.lighting.to_json(),
                "expressions": [e.to_json() for e in self.expressions]}

    def frames(self) -> list[Frame]:
        return [f for e in self.expressions for f in e.frames]


SHARD_FORMAT = "synth-plan-shard"
SHARD_FORMAT_VERSION = 1


@dataclass(frozen=True)
class ShardSpec:
    """One shard spec: everything a worker needs to render the shard."""

    shard_id: str
    run_seed: int
    identities: tuple[Identity, ...]

    @classmethod
    def from_json(cls, d: Any, where: str = "shard spec") -> ShardSpec:
        d = as_object(d, where)
        if d.get("format") != SHARD_FORMAT or d.get("format_version") != SHARD_FORMAT_VERSION:
            raise spec_error(f"format {d.get('format')!r} version {d.get('format_version')!r} is not "
                       f"{SHARD_FORMAT!r} version {SHARD_FORMAT_VERSION}", where)
        ids = required(d, "identities", list, where)
        if not ids:
            raise spec_error("no identities", where)
        return cls(required(d, "shard_id", str, where), required(d, "run_seed", int, where),
                   tuple(Identity.from_json(i, f"{where}/identities/{k}") for k, i in enumerate(ids)))

    def to_json(self) -> dict[str, Any]:
        return {"format": SHARD_FORMAT, "format_version": SHARD_FORMAT_VERSION, "shard_id": self.shard_id,
                "run_seed": self.run_seed, "identities": [i.to_json() for i in self.identities]}

    def frames(self) -> list[Frame]:
        return [f for i in self.identities for f in i.frames()]


@dataclass(frozen=True)
class RenderSettings:
    """The render settings of a plan (its header's resolved ``render`` section) with the
    engine's own defaults for what the config does not set (benchmarks set them)."""

    samples: int
    preset: str | None = None
    resolution: tuple[int, int] | None = None
    device: str = "auto"
    adaptive_sampling: bool = False
    adaptive_threshold: float = 0.01  # a threshold of 0 (or none) gives Cycles' 0.01
    denoise: bool = False
    gpu_denoiser: str = "OPTIX"
    max_bounces: int = 8
    clamp_indirect: float = 10.0
    filter_width: float = 1.5
    # Cycles' own values: what a plan that does not set them (every plan made before they were settings) renders with
    diffuse_bounces: int = 4
    glossy_bounces: int = 4
    transmission_bounces: int = 12
    transparent_bounces: int = 8
    hair_shape: str = "ribbons"
    light_tree: bool = True
    caustics: bool = True
    denoise_prefilter: str = "accurate"
    denoise_quality: str = "high"
    path_guiding: bool = False

    @classmethod
    def from_json(cls, d: Any, where: str = "plan.json config.render") -> RenderSettings:
        from dataclasses import fields

        d = dict(as_object(d, where))
        if "adaptive" in d:  # plans that name it by its short form
            d.setdefault("adaptive_sampling", d.pop("adaptive"))
        names = {f.name for f in fields(cls)}
        extra = sorted(set(d) - names)
        if extra:
            raise spec_error(f"unknown render setting(s) {extra}", where)
        required(d, "samples", int, where)
        if d.get("resolution") is not None:
            d["resolution"] = tuple(_vec(d, "resolution", where, 2))
        d["adaptive_threshold"] = float(d.get("adaptive_threshold") or 0.01)
        return cls(**{k: v for k, v in d.items() if v is not None or k in ("preset", "resolution")})
