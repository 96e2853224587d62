"""An asset pick (:class:`AssetPick`) and its parameters, typed per class: the one home of
their defaults.

A plan's asset choice carries ``params``: the values the catalogue drew for that asset
(``synth/plan/assets.py``). Each class has one frozen record here, whose fields are every
parameter its rig and fit code read (``blender_scripts/assets/``, :mod:`synth.assets.fit`), with
the value a pick gets when its catalogue entry does not draw that parameter. A default that
depends on the asset (a bob's hair length, a bushy brow's thickness) is in the record's
:meth:`Params.asset_defaults`; one that depends on another parameter (the iris's stroma
scatter on its melanin) in ``__post_init__``.

``None`` means "not planned" where the rig then draws the value from its own generator
(``ctx.rng(cls)``: makeup amounts, glasses sizes); those draws are part of the rig's seed
stream, not defaults.

The plan's JSON stays what the catalogue drew: :attr:`Params.given` lists the names the JSON
carries, in its order, and :meth:`Params.to_json` writes exactly those, so a plan read and
written again is the same bytes. :meth:`Params.from_json` refuses a name the class does not
read and a value of the wrong type (SynthError, one line).
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, ClassVar, Mapping

from synth.appearance.skin import DEFAULT_HAEMOGLOBIN, DEFAULT_MELANIN
from synth.appearance.skin_optics import DEFAULT_WRINKLE_DEPTH
from synth.assets.classes import CLASSES, NAMES
from synth.assets.jsonrecord import as_object, of_type, record_from_json, record_to_json, required, spec_error
from synth.errors import SynthError

UNKNOWN_PARAMETER_FIX = "remove it from the catalogue or add it to the class's record in synth/assets/params.py"


#: The beard's cheek line (0 low, 1 high; synth.assets.fit.masks.cheek_line) where none is planned,
#: and the line of a shaved beard's shadow on an identity without a beard.
DEFAULT_REACH = 0.3

#: A parameter value as the plan's JSON holds it (an HSV colour is a list of three numbers).
Value = float | int | bool | str | tuple[float, ...] | None


def planned_or(*values):
    """The first value that is not None: a planned value before the rig's own (its draws are
    made whether used or not, so they stay aligned)."""
    return next(v for v in values if v is not None)


@dataclass(frozen=True, kw_only=True)
class Params:
    """Base of the per-class parameter records (see the module docstring)."""

    given: tuple[str, ...] = field(default=(), repr=False)

    CLASS: ClassVar[str] = ""

    @classmethod
    def asset_defaults(cls, asset_id: str) -> dict[str, Value]:
        """Defaults of this class that depend on the asset id (over the fields' own)."""
        return {}

    @classmethod
    def from_json(cls, asset_id: str, params: Mapping, where: str) -> Params:
        """The record of a plan's ``params`` object (checked: names and value types)."""
        if not isinstance(params, Mapping):
            raise SynthError(f"{cls.CLASS} params are {type(params).__name__}, not an object", where,
                             "re-run 'synth plan'")
        kinds = _kinds(cls)
        values = dict(cls.asset_defaults(asset_id))
        for name, v in params.items():
            if name not in kinds or name == "given":
                raise SynthError(f"{cls.CLASS} asset '{asset_id}' has parameter '{name}', which its rig does not "
                                 f"read (known: {', '.join(sorted(cls.names()))})", where, UNKNOWN_PARAMETER_FIX)
            values[name] = _checked(v, kinds[name], f"{where} params.{name}")
        return cls(given=tuple(params), **values)

    @classmethod
    def of(cls, asset_id: str, params: Params | Mapping | None = None) -> Params:
        """``params`` as this record (a record is returned as it is): for callers that build a
        pick by hand (tests, benchmarks)."""
        if isinstance(params, cls):
            return params
        return cls.from_json(asset_id, params or {}, f"{cls.CLASS} asset '{asset_id}'")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The parameters of this class (what its rig reads), in field order."""
        return tuple(k for k in _kinds(cls) if k != "given")

    def to_json(self) -> dict[str, Value]:
        """The planned values, in the plan's order (tuples are written as JSON arrays)."""
        return {k: getattr(self, k) for k in self.given}

    def planned(self, name: str) -> bool:
        """Whether the plan drew ``name`` (else the record holds its default)."""
        return name in self.given


@lru_cache(maxsize=None)
def _kinds(cls: type) -> dict[str, tuple[type, ...]]:
    """Field name -> the Python types its values may have."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        args = typing.get_args(hints[f.name]) or (hints[f.name],)
        out[f.name] = tuple(type(None) if a is None else (typing.get_origin(a) or a) for a in args)
    return out


def _checked(v, kinds: tuple[type, ...], where: str) -> Value:
    if isinstance(v, (list, tuple)) and tuple in kinds:
        if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            return tuple(v)
    elif isinstance(v, bool):
        if bool in kinds:
            return v
    elif isinstance(v, int) and (int in kinds or float in kinds):
        return v  # an int stays an int (the plan's bytes)
    elif isinstance(v, (float, str, type(None))) and type(v) in kinds:
        return v
    names = "/".join("null" if k is type(None) else "list of numbers" if k is tuple else k.__name__ for k in kinds)
    raise SynthError(f"parameter value {v!r} is not a {names}", where, "re-run 'synth plan' with a valid catalogue")


@dataclass(frozen=True, kw_only=True)
class SkinParams(Params):
    CLASS: ClassVar[str] = "skin"
    melanin: float = DEFAULT_MELANIN  # set by the plan from the identity's ITA target (synth.plan.skin)
    haemoglobin: float = DEFAULT_HAEMOGLOBIN
    ita_deg: float | None = None
    roughness: float = 0.45
    oiliness: float = 0.0
    pore_scale: float = 1.0
    pore_strength: float = 0.15
    freckles: float = 0.0
    age_spots: float = 0.0
    wrinkle_depth: float = DEFAULT_WRINKLE_DEPTH
    subsurface_radius_scale: float = 1.0
    redness: float = 0.3
    detail_variant: int = 0
    noise_seed: float | None = None  # None: 7.31 * detail_variant

    def __post_init__(self):
        if self.noise_seed is None:
            object.__setattr__(self, "noise_seed", 7.31 * float(self.detail_variant))


@dataclass(frozen=True, kw_only=True)
class IrisParams(Params):
    CLASS: ClassVar[str] = "iris"
    melanin: float = 0.5
    stroma_scatter: float | None = None  # None: 0.75 below melanin 0.3, else 0.6
    pupil_dilation: float = 0.45
    fibre_contrast: float = 0.35
    limbal_ring: float = 0.5
    #: None where not planned: the palette then has no central zone (0.0) while the shader's
    #: collarette band keeps its weight of 0.25 (:attr:`collarette`); two readings of one
    #: missing value, kept apart so that renders stay the same bytes
    central_heterochromia: float | None = None

    def __post_init__(self):
        if self.stroma_scatter is None:
            object.__setattr__(self, "stroma_scatter", 0.75 if float(self.melanin) < 0.3 else 0.6)

    @property
    def heterochromia(self) -> float:
        """The palette's central heterochromia (0 where none is planned)."""
        return 0.0 if self.central_heterochromia is None else float(self.central_heterochromia)

    @property
    def collarette(self) -> float:
        """The shader's collarette-band heterochromia (0.25 where none is planned)."""
        return 0.25 if self.central_heterochromia is None else float(self.central_heterochromia)


_CURLY_HAIR = ("short_curly", "long_curly", "afro")
_HAIR_LENGTH_M = {"buzz_cut": 0.006, "short_straight": 0.05, "short_curly": 0.04, "medium_wavy": 0.15, "bob": 0.16,
                  "long_straight": 0.35, "long_layered": 0.35, "long_curly": 0.3, "braids": 0.3, "locs": 0.25}


@dataclass(frozen=True, kw_only=True)
class HairParams(Params):
    CLASS: ClassVar[str] = "hair"
    colour: str | None = None  # None: the rig's default colour
    density: float = 1.0
    hairline_recession: float = 0.0
    parting: str = "none"
    fringe: bool = False
    curl: float = 0.0
    curl_radius_m: float = 0.008
    length_m: float = 0.1
    top_length_m: float = 0.08
    side_length_m: float = 0.006
    swept: str = "back"
    volume_radius_m: float = 0.07
    bun_height: str = "mid"
    bun_radius_m: float = 0.04
    loose_strands: float = 0.0
    tie_height: str = "mid"
    tail_length_m: float = 0.25
    braid_count: int = 8
    loc_count: int = 40
    layer_ratio: float = 0.6

    @classmethod
    def asset_defaults(cls, asset_id: str) -> dict[str, Value]:
        out: dict[str, Value] = {"length_m": _HAIR_LENGTH_M.get(asset_id, 0.1)}
        if asset_id in ("bob", "long_straight", "long_layered", "medium_wavy"):
            out["parting"] = "centre"
        if asset_id == "short_back_and_sides":
            out.update(top_length_m=0.05, side_length_m=0.008, parting="left")
        if asset_id in _CURLY_HAIR:
            out["curl"] = 0.9
        if asset_id == "short_curly":
            out["curl_radius_m"] = 0.005
        return out


@dataclass(frozen=True, kw_only=True)
class EyebrowParams(Params):
    CLASS: ClassVar[str] = "eyebrows"
    colour: str | None = None
    thickness: float = 0.9
    density: float = 1.0
    arch: float = 0.3
    unruliness: float = 0.15
    monobrow: bool = False

    @classmethod
    def asset_defaults(cls, asset_id: str) -> dict[str, Value]:
        out: dict[str, Value] = {}
        for name, table in (("thickness", {"thin_arched": 0.45, "bushy": 1.5, "sparse": 0.6}),
                            ("density", {"sparse": 0.35, "bushy": 1.2}), ("arch", {"thin_arched": 0.7,
                                                                                   "straight": 0.05})):
            if asset_id in table:
                out[name] = table[asset_id]
        return out


@dataclass(frozen=True, kw_only=True)
class EyelashParams(Params):
    CLASS: ClassVar[str] = "eyelashes"
    length_scale: float = 1.0
    curl: float = 0.4
    density: float = 1.0
    clumping: float = 0.0

    @classmethod
    def asset_defaults(cls, asset_id: str) -> dict[str, Value]:
        return {"length_scale": 1.3, "curl": 0.7, "density": 1.15, "clumping": 0.4} if asset_id == "mascara" else {}


_BEARD_LENGTH_M = {"stubble": 0.0015, "chin_strap": 0.008, "mutton_chops": 0.012, "full_long": 0.08, "goatee": 0.02,
                   "moustache": 0.015}


@dataclass(frozen=True, kw_only=True)
class BeardParams(Params):
    CLASS: ClassVar[str] = "beard"
    colour: str | None = None  # None: the hair's colour, else the rig's default
    length_m: float = 0.012
    density: float = 1.0
    reach: float = DEFAULT_REACH
    moustache: bool = True
    style: str = "chevron"
    width_m: float = 0.012
    curl: float = 0.0

    @classmethod
    def asset_defaults(cls, asset_id: str) -> dict[str, Value]:
        return {"length_m": _BEARD_LENGTH_M.get(asset_id, 0.012)}


@dataclass(frozen=True, kw_only=True)
class MakeupParams(Params):
    """``None``: drawn by the rig (its generator, ``ctx.rng("makeup")``)."""

    CLASS: ClassVar[str] = "makeup"
    lip_colour: str | None = None
    colour: str | None = None
    eyeshadow_colour: str | None = None
    gloss: float | None = None
    shimmer: float | None = None
    extent: float | None = None
    thickness: float | None = None
    wing: bool | None = None
    coverage: float | None = None
    opacity: float | None = None
    intensity: float | None = None
    blush: float | None = None
    eyeliner: bool = True

    @classmethod
    def asset_defaults(cls, asset_id: str) -> dict[str, Value]:
        return {"gloss": 0.4} if asset_id == "full_look" else {}

    @property
    def shadow_colour(self) -> str | None:
        """The eyeshadow colour: ``colour`` where planned, else ``eyeshadow_colour``."""
        return self.colour if self.planned("colour") else self.eyeshadow_colour


_GARMENT_FABRIC = {"tshirt_crew": "cotton_jersey", "tshirt_vneck": "cotton_jersey", "sweater": "wool_knit",
                   "turtleneck": "wool_knit", "hoodie": "cotton_fleece", "shirt_collar": "cotton_poplin",
                   "jacket_blazer": "wool_suiting", "coat": "wool_felt", "uniform": "scrub",
                   "tank_top": "cotton_jersey", "scarf_over_sweater": "wool_knit"}


@dataclass(frozen=True, kw_only=True)
class GarmentParams(Params):
    CLASS: ClassVar[str] = "garment"
    colour_hsv: str | tuple[float, ...] = "grey"
    fabric: str = "cotton_jersey"
    style: str = ""
    knit_scale_m: float = 0.005
    neckline_depth_m: float | None = None  # None: the neckline's own (:meth:`neckline_depth`)
    collar_height_m: float = 0.06
    lapel_width_m: float = 0.07
    hood_up: bool = False
    drawstrings: bool = False
    scarf_thickness_m: float = 0.02
    wrap: str = "loop"
    tie: bool = False
    top_button_open: bool | None = None  # None: open on a polo (``style``), else closed
    undershirt: str = "shirt"
    collar_up: bool = False
    strap_width_m: float = 0.03

    def __post_init__(self):
        if self.top_button_open is None:
            object.__setattr__(self, "top_button_open", self.style == "polo")

    @classmethod
    def asset_defaults(cls, asset_id: str) -> dict[str, Value]:
        out: dict[str, Value] = {"fabric": _GARMENT_FABRIC.get(asset_id, "cotton_jersey")}
        if asset_id == "coat":
            out["lapel_width_m"] = 0.08
        return out

    def neckline_depth(self, vneck: bool) -> float:
        """The planned neckline depth, else 7 cm for a v-neck and 1 cm for a round neckline."""
        if self.neckline_depth_m is not None:
            return float(self.neckline_depth_m)
        return 0.07 if vneck else 0.01


@dataclass(frozen=True, kw_only=True)
class GlassesParams(Params):
    """``None``: drawn by the rig (:func:`synth.assets.fit.glasses.spec.frame_spec`)."""

    CLASS: ClassVar[str] = "glasses"
    lens_width_m: float | None = None
    lens_height_m: float | None = None
    lens_diameter_m: float | None = None
    frame_colour: str | None = None
    frame_material: str | None = None
    rim_thickness_m: float | None = None
    double_bridge: bool = True
    wing_lift: float = 0.5
    temple_colour: str | None = None  # None: the frame's colour
    lens_coating: str | None = None
    lens_reflectance: float | None = None
    lens_tint: float = 0.0


@dataclass(frozen=True, kw_only=True)
class HeadwearParams(Params):
    CLASS: ClassVar[str] = "headwear"
    colour_hsv: str | tuple[float, ...] = "black"
    fold_height_m: float = 0.03
    knit_scale_m: float = 0.005
    pompom: bool = False
    brim_yaw_deg: float = 0.0
    brim_curve: float = 0.5


#: class name -> its parameter record
PARAMS: dict[str, type[Params]] = {p.CLASS: p for p in (
    SkinParams, IrisParams, HairParams, EyebrowParams, EyelashParams, BeardParams, MakeupParams, GarmentParams,
    GlassesParams, HeadwearParams)}


# --------------------------------------------------------------------------- assets


@dataclass(frozen=True)
class Pack:
    """The catalogue's record of an external asset (synth.assets.packs.pack_record)."""

    cls: str
    file: str
    asset_root: str
    object: str
    sha256: str
    anchor: str
    reference_width_m: float

    @classmethod
    def from_json(cls, d: Any, where: str) -> Pack:
        readers = {f.name: of_type(str) for f in dataclasses.fields(cls)}
        readers["reference_width_m"] = of_type((int, float))
        return record_from_json(cls, d, where, readers, {"cls": "class"})

    def to_json(self) -> dict[str, Any]:
        return record_to_json(self, {"cls": "class"})


@dataclass(frozen=True)
class AssetPick:
    """One class's pick: the asset, its generator, its parameters (typed per class) and, for
    an external pack, the pack record."""

    cls: str
    id: str
    generator: str
    params: Params
    pack: Pack | None = None

    @classmethod
    def from_json(cls, cls_name: str, d: Any, where: str) -> AssetPick:
        d = as_object(d, where)
        if cls_name not in PARAMS:
            raise spec_error(f"unknown asset class '{cls_name}'", where)
        extra = set(d) - {"id", "generator", "params", "pack"}
        if extra:
            raise spec_error(f"unexpected key(s) {sorted(extra)}", where)
        aid = required(d, "id", str, where)
        params = PARAMS[cls_name].from_json(aid, required(d, "params", dict, where), where)
        pack = Pack.from_json(d["pack"], f"{where}/pack") if "pack" in d else None
        return cls(cls_name, aid, required(d, "generator", str, where), params, pack)

    @classmethod
    def of(cls, cls_name: str, asset_id: str, params: Params | Mapping | None = None,
           generator: str | None = None) -> AssetPick:
        """A pick made by hand (tests, benchmarks): the class's first procedural generator
        unless one is given."""
        gen = generator or f"procedural:{CLASSES[cls_name].generators[0]}"
        return cls(cls_name, asset_id, gen, PARAMS[cls_name].of(asset_id, params))

    @classmethod
    def coerce(cls, cls_name: str, entry: AssetPick | Mapping) -> AssetPick:
        """``entry`` as a pick: a record as it is, a plan-style object (``id``, ``params``,
        optionally ``generator`` and ``pack``) checked into one."""
        if isinstance(entry, AssetPick):
            return entry
        where = f"{cls_name} asset {entry.get('id')!r}"
        if "generator" in entry:
            return cls.from_json(cls_name, entry, where)
        return cls.of(cls_name, str(required(entry, "id", str, where)), entry.get("params"))

    @property
    def external(self) -> bool:
        """An asset of an external pack (a .blend), built by blender_scripts/assets/external.py."""
        return self.generator.endswith(".blend") or self.generator.startswith("blend:")

    def to_json(self) -> dict[str, Any]:
        out = {"id": self.id, "generator": self.generator, "params": self.params.to_json()}
        if self.pack is not None:
            out["pack"] = self.pack.to_json()
        return out


def assets_from_json(d: Any, where: str) -> dict[str, AssetPick | None]:
    """An identity's ``assets`` object: class -> pick or None, every class of the registry."""
    d = as_object(d, where)
    missing = [c for c in NAMES if c not in d]
    if missing:
        raise spec_error(f"assets lack the class(es) {missing}", where)
    return {c: None if e is None else AssetPick.from_json(c, e, f"{where}/{c}") for c, e in d.items()}
