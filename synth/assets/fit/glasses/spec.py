"""Glasses styles, frame colours and the frame description (:class:`FrameSpec`).

:func:`frame_spec` completes the plan's parameters of one glasses asset with rig-drawn ones
(bridge width, missing sizes, tilt, wrap, colour, lens coating) from the rig's generator; the
draws are always made, in a fixed order, so they stay aligned whatever the plan gives.
"""

from __future__ import annotations

import dataclasses
from typing import Mapping

import numpy as np

from synth.assets.params import GlassesParams, planned_or

STYLES = ("rectangular", "round", "oval", "aviator", "cat_eye", "browline", "rimless", "half_rim")

COLOURS = {  # linear sRGB base colours
    "black": (0.012, 0.012, 0.013), "tortoise": (0.16, 0.06, 0.018), "brown": (0.09, 0.04, 0.018),
    "clear": (0.8, 0.8, 0.8), "silver": (0.85, 0.86, 0.87), "gold": (0.9, 0.62, 0.25),
    "navy": (0.01, 0.02, 0.08), "red": (0.45, 0.02, 0.02), "white": (0.8, 0.8, 0.78),
    "titanium": (0.55, 0.53, 0.5),
}
METALLIC_COLOURS = {"silver", "gold", "titanium"}

LENS_IOR = 1.5  #: CR-39 / crown glass
#: Reflectance of one lens surface at normal incidence: uncoated (Fresnel of LENS_IOR, 4 %) and the
#: range drawn for anti-reflective coatings (multilayer stacks leave roughly 0.3-1.2 % per surface)
UNCOATED_REFLECTANCE = ((LENS_IOR - 1.0) / (LENS_IOR + 1.0)) ** 2
AR_REFLECTANCE = (0.003, 0.012)
AR_SHARE = 0.75  #: share of lenses drawn with an anti-reflective coating (a choice, not a census)
COATINGS = ("anti_reflective", "none")
MAX_LENS_REFLECTANCE = 0.25  #: per surface; larger values (and negative ones) are refused


def reflectance_ok(r0) -> bool:
    """Whether ``r0`` is a lens reflectance the rig accepts: a number in [0, MAX_LENS_REFLECTANCE)."""
    return isinstance(r0, (int, float)) and not isinstance(r0, bool) and 0.0 <= r0 < MAX_LENS_REFLECTANCE


def reflectance_ior(r0: float) -> float:
    """The index whose Fresnel reflectance at normal incidence (from air) is ``r0``."""
    s = float(np.sqrt(np.clip(r0, 0.0, 0.99)))
    return (1.0 + s) / (1.0 - s)


#: manifest parameters whose values the rig reads from fixed sets
_CATEGORICAL = {"frame_colour": tuple(COLOURS), "temple_colour": tuple(COLOURS), "lens_coating": COATINGS}


def manifest_defects(asset: dict) -> list[tuple[str, str, str]]:
    """(what, parameter name or '', fix) for each value of a procedural glasses asset of the
    manifest that :func:`frame_spec` would refuse or silently replace: an unknown style (the
    asset id), colour or coating, a lens reflectance outside [0, MAX_LENS_REFLECTANCE). Checked
    when the catalogue loads (``synth plan``, ``synth assets validate``), not first at render time."""
    out: list[tuple[str, str, str]] = []
    if asset.get("id") not in STYLES:
        out.append((f"unknown glasses style '{asset.get('id')}' (the asset id names the style)", "",
                    f"use one of: {', '.join(STYLES)}"))
    for name, spec in (asset.get("parameters") or {}).items():
        if not isinstance(spec, dict):
            continue
        values = [spec["value"]] if "value" in spec else list(spec.get("choices", spec.get("range", [])))
        if name in _CATEGORICAL:
            bad = [v for v in values if v not in _CATEGORICAL[name]]
            if bad:
                out.append((f"unknown {name} {', '.join(repr(v) for v in bad)}", name,
                            f"use one of: {', '.join(_CATEGORICAL[name])}"))
        elif name == "lens_reflectance":
            if not all(reflectance_ok(v) for v in values):
                out.append((f"lens_reflectance outside [0, {MAX_LENS_REFLECTANCE:g})", name,
                            "give the reflectance of one lens surface as a fraction (0.04 = uncoated glass)"))
    return out


@dataclasses.dataclass
class FrameSpec:
    style: str
    lens_w: float  # box width of one lens (m)
    lens_h: float  # box height
    rim_w: float  # rim face width (in the lens plane)
    rim_d: float  # rim depth (along the optical axis)
    bridge: float  # distance between lenses (DBL)
    rim_mode: str  # full | half | none | browline
    material: str  # acetate | metal
    colour: str
    temple_colour: str
    tint: float
    superellipse: float
    wing_lift: float = 0.0
    double_bridge: bool = False
    pantoscopic_deg: float = 8.0
    wrap_deg: float = 4.0
    lens_thickness: float = 0.002
    temple_r: tuple = (0.0012, 0.0022)  # half sizes (horizontal, vertical) of the temple section
    tip_r: float = 0.0016
    coating: str = "none"  # anti_reflective | none
    lens_reflectance: float = UNCOATED_REFLECTANCE  # per surface, at normal incidence

    def record(self) -> dict:
        d = dataclasses.asdict(self)
        return {k: (round(v, 6) if isinstance(v, float) else (list(v) if isinstance(v, tuple) else v))
                for k, v in d.items()}


def frame_spec(style: str, params: GlassesParams | Mapping | None, rng: np.random.Generator) -> FrameSpec:
    """Complete the plan's parameters with rig-drawn ones (bridge, what is not planned, ...)."""
    if style not in STYLES:
        raise ValueError(f"unknown glasses style {style!r}; expected one of {STYLES}")
    p = GlassesParams.of(style, params)
    u = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731 - always drawn, so draws stay aligned
    draws = {"w": u(0.046, 0.054), "h": u(0.03, 0.038), "rim": u(0.002, 0.005), "bridge": u(0.016, 0.021),
             "pct": u(6.0, 10.0), "wrap": u(2.0, 6.0), "mat": u(0.0, 1.0), "col": int(rng.integers(1 << 30)),
             "coat": u(0.0, 1.0), "refl": u(0.0, 1.0)}
    w = float(planned_or(p.lens_width_m, p.lens_diameter_m, draws["w"]))
    h = float(planned_or(p.lens_height_m, p.lens_diameter_m, 0.0)) or None
    colour = str(planned_or(p.frame_colour, ["black", "tortoise", "brown", "silver", "gold"][draws["col"] % 5]))
    material = str(planned_or(p.frame_material, "metal" if colour in METALLIC_COLOURS else "acetate"))
    if style in ("aviator", "rimless"):
        material = "metal"
    rim_w = float(planned_or(p.rim_thickness_m, draws["rim"]))
    n_exp, rim_mode, wing, dbl = 2.0, "full", 0.0, False
    if style == "rectangular":
        n_exp, h = 4.5, h or 0.68 * w
    elif style == "round":
        n_exp, h = 2.0, h or w
    elif style == "oval":
        n_exp, h = 2.3, h or 0.68 * w
    elif style == "aviator":
        n_exp, h, dbl = 2.4, h or 0.86 * w, bool(p.double_bridge)
        rim_w = min(rim_w, 0.0025)
    elif style == "cat_eye":
        n_exp, h, wing = 2.8, h or 0.66 * w, float(p.wing_lift)
    elif style == "browline":
        n_exp, h, rim_mode = 3.2, h or 0.7 * w, "browline"
    elif style == "rimless":
        n_exp, h, rim_mode = 3.0, h or 0.62 * w, "none"
    elif style == "half_rim":
        n_exp, h, rim_mode = 3.5, h or 0.66 * w, "half"
    metal = material == "metal"
    if metal and style != "browline":
        rim_w = float(np.clip(0.45 * rim_w, 0.0012, 0.0022))
    rim_d = rim_w if metal else float(np.clip(1.3 * rim_w, 0.003, 0.006))
    temple_colour = str(planned_or(p.temple_colour, colour))
    coating = str(planned_or(p.lens_coating, COATINGS[0] if draws["coat"] < AR_SHARE else COATINGS[1]))
    if coating not in COATINGS:
        raise ValueError(f"unknown lens_coating {coating!r}; expected one of {COATINGS}")
    lo, hi = AR_REFLECTANCE
    refl = lo * (hi / lo) ** draws["refl"] if coating == "anti_reflective" else UNCOATED_REFLECTANCE
    refl = float(planned_or(p.lens_reflectance, refl))
    if not reflectance_ok(refl):
        raise ValueError(f"lens_reflectance {refl!r} is outside [0, {MAX_LENS_REFLECTANCE:g})")
    return FrameSpec(style=style, lens_w=w, lens_h=float(h), rim_w=rim_w, rim_d=rim_d, bridge=draws["bridge"],
                     rim_mode=rim_mode, material=material, colour=colour, temple_colour=temple_colour,
                     tint=float(p.lens_tint), superellipse=n_exp, wing_lift=wing, double_bridge=dbl,
                     pantoscopic_deg=draws["pct"], wrap_deg=draws["wrap"],
                     lens_thickness=0.0022 if style == "rimless" else 0.0018,
                     temple_r=(0.0007, 0.0007) if metal else (0.0011, 0.0021),
                     tip_r=0.0014 if metal else 0.0016, coating=coating, lens_reflectance=refl)
