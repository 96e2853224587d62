"""Procedural upper-body garments (``procedural:garment_shell``), fitted non-rigidly to the bust.

Pure numpy; the Blender rig (``blender_scripts/assets/garment.py``) only makes the mesh
object and the cloth materials. Every garment is one mesh built from the body itself, so it
fits any identity (tested at +-3 SD):

1. **Shell**: the skin triangles of the ``neck`` and ``shoulders`` regions (with the default
   model's bust: the torso to the waist and the upper arms) are clipped exactly at a neckline
   field ``z_nl(theta) - z`` (``meshops.clip_by_field``; theta is the angle around the neck base
   ring, ``body.NeckFrame``), at the hem and at the garment's sleeves (:data:`SLEEVES`,
   :mod:`synth.assets.fit.arms`), subdivided once (8-10 mm edges; but within 3 cm of the hem),
   and offset along the interpolated body normals by the fabric thickness plus folds and drape
   (:class:`synth.assets.fit.folds.Folds`: the cloth hanging from the chest, vertical folds under
   it, compression folds at the waist and above the elbows, tension folds from the armpits; their
   height and wavelength per kind of garment, :data:`synth.assets.fit.folds.DRAPES`). The
   neckline per garment: crew, V (depth from ``neckline_depth_m``), turtleneck collar
   (``collar_height_m``, capped 1.2 cm under the jaw line), deep V with raised lapels
   (``lapel_width_m``) for jackets and coats, scoop + straps (``strap_width_m``) for tank tops.
2. **Add-ons** (:mod:`synth.assets.fit.garment_parts`, :mod:`synth.assets.fit.collars`): ribbed
   rims as tubes along the neckline loop, shirt collars (a band standing round the neck and a leaf
   folded over it, resting 1.2 mm over the band and the shirt's shell), a turtleneck's roll (its
   top folded down over the collar, ribbed and creased), hoods (up: a smoothed offset of the head behind the face
   opening; down: a flattened tube on the upper back), drawstrings, ties, scarves (loop /
   drape / knot, ``scarf_thickness_m``) as swept tubes.
3. **Fit** (:func:`synth.assets.fit.body.fit_shell`): the torso shell is clipped where it runs
   deep inside another body part (:mod:`synth.assets.fit.trim`); every other vertex closer than ``CLEARANCE`` to the skin (or
   inside it) is moved to the closest skin point + ``CLEARANCE`` along the normal.
4. **Update** (:meth:`synth.assets.fit.body.FittedShell.follow`): every vertex is bound to its
   closest neck/shoulder (or, for hoods, head) triangle in a local frame; the binding is
   re-applied to the new head vertices and the push-out runs again (about 0.1 s), so the
   garment follows expressions and a jaw opening never pushes the chin through the collar.

Materials (:class:`~synth.assets.fit.body.Cloth`, built by the rig): per ``fabric``
(:data:`FABRICS`), colour from ``colour_hsv`` (a name in :data:`COLOURS` or an ``[h, s, v]``
triple; ``striped_blue``, ``check`` and ``tartan`` are patterns, :func:`colour_rgb`).
"""

from __future__ import annotations

import colorsys
from typing import Mapping

import numpy as np

from synth.assets.fit.attach import push_out
from synth.assets.fit.body import Body, Cloth, Parts, Shell
from synth.assets.fit.collars import rolled_collar, shirt_collar
from synth.assets.fit.folds import DRAPES, Folds, kind_of
from synth.assets.fit.garment_parts import (crew_neckline, front_weight, hanging_strip, hood_up, neck_tube,
                                            necktie, torso_shell, vee_neckline)
from synth.assets.fit.meshops import icosphere, smooth_max, smooth_min
from synth.assets.params import AssetPick
from synth.model.meshutil import smoothstep

#: minimum distance (m) kept between every garment vertex and the skin
CLEARANCE = 0.0015
#: width (m) of the tank top's band along the hem (over the arm stumps of a model without the bust;
#: with it, the waist's band under the arm holes)
TANK_BAND = 0.035
#: rounding (m) of the corner where a turtleneck's collar top meets the cap under the jaw
COLLAR_ROUND = 0.045
#: rounding (m of the fields) of the corners of a tank top's openings
TANK_ROUND = 0.035

#: colour names -> sRGB HSV (h, s, v in [0, 1])
COLOURS = {
    "white": (0.0, 0.0, 0.92), "black": (0.0, 0.0, 0.06), "grey": (0.0, 0.0, 0.45), "charcoal": (0.6, 0.05, 0.22),
    "navy": (0.62, 0.7, 0.28), "red": (0.99, 0.8, 0.7), "green": (0.36, 0.6, 0.45), "blue": (0.6, 0.7, 0.7),
    "yellow": (0.14, 0.8, 0.9), "brown": (0.07, 0.65, 0.35), "pink": (0.95, 0.35, 0.95), "cream": (0.12, 0.15, 0.92),
    "burgundy": (0.97, 0.75, 0.38), "camel": (0.09, 0.5, 0.72), "light_blue": (0.58, 0.3, 0.92),
    "striped_blue": (0.6, 0.6, 0.75), "check": (0.0, 0.7, 0.6), "beige": (0.1, 0.25, 0.82), "olive": (0.2, 0.6, 0.4),
    "teal": (0.5, 0.7, 0.5), "tartan": (0.0, 0.75, 0.55), "mustard": (0.13, 0.8, 0.8), "khaki": (0.12, 0.35, 0.7),
}

#: fabric -> (thickness m, roughness, sheen weight, surface kind)
FABRICS = {
    "cotton_jersey": (0.0025, 0.85, 0.3, "jersey"), "wool_knit": (0.005, 0.95, 0.6, "knit"),
    "cotton_knit": (0.004, 0.9, 0.4, "knit"), "cotton_fleece": (0.006, 0.95, 0.7, "fleece"),
    "cotton_poplin": (0.002, 0.6, 0.15, "woven"), "oxford": (0.0025, 0.7, 0.2, "twill"),
    "linen": (0.0025, 0.8, 0.2, "woven"), "wool_suiting": (0.004, 0.7, 0.3, "twill"),
    "tweed": (0.005, 0.95, 0.4, "tweed"), "cotton_twill": (0.0035, 0.8, 0.2, "twill"),
    "wool_felt": (0.006, 0.9, 0.5, "felt"), "gabardine": (0.004, 0.6, 0.2, "twill"),
    "leather": (0.003, 0.35, 0.0, "leather"), "denim": (0.004, 0.85, 0.1, "twill"),
    "pique": (0.003, 0.85, 0.25, "knit"), "scrub": (0.0025, 0.75, 0.15, "woven"),
}

def colour_rgb(value) -> tuple[float, float, float]:
    """Linear RGB from a colour name or an (h, s, v) triple (sRGB-encoded HSV)."""
    if isinstance(value, str):
        hsv = COLOURS.get(value, COLOURS["grey"])
    else:
        hsv = tuple(float(x) for x in value)[:3]
    r, g, b = colorsys.hsv_to_rgb(*hsv)

    def lin(c):
        return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4

    return (lin(r), lin(g), lin(b))


#: sleeves over the bust's upper arms (synth.assets.fit.arms.sleeve_field) per garment id, or
#: ``id:style`` for a uniform; every other garment has long ones (to the elbows and on, down the
#: forearms), and so has a jacket's or coat's undershirt (under the jacket's: no arm holes to keep
#: smooth where nothing shows them)
SLEEVES = {"tshirt_crew": "short", "tshirt_vneck": "short", "tank_top": "none", "uniform:scrubs": "short",
           "uniform:polo": "short"}


def sleeves_of(aid: str, style: str | None = None) -> str:
    """The sleeves ('long', 'short', 'none') of garment ``aid`` (a uniform's ``style``)."""
    return SLEEVES.get(f"{aid}:{style}", SLEEVES.get(aid, "long"))


def garment_shell(body: Body, entry: AssetPick | Mapping, rng: np.random.Generator) -> Shell:
    """The garment of a plan pick on ``body`` (``rng``: the rig's generator, ctx.rng("garment"))."""
    entry = AssetPick.coerce("garment", entry)
    aid, p = entry.id, entry.params
    fr = body.frame
    fabric, style = str(p.fabric), str(p.style)
    if aid == "uniform":
        fabric = {"scrubs": "scrub", "work_shirt": "cotton_twill", "polo": "pique"}.get(style, "scrub")
    colour = p.colour_hsv
    knit = float(p.knit_scale_m)
    thick = FABRICS.get(fabric, FABRICS["cotton_jersey"])[0]
    seed = float(rng.uniform(0, 100))
    cloths = [Cloth(f"garment_{aid}", colour, fabric, knit, seed)]
    parts = Parts()
    info = {"id": aid, "fabric": fabric, "colour": colour if isinstance(colour, str) else list(colour)}

    sleeves = sleeves_of(aid, style if aid == "uniform" else None)
    reach = []  # the outer cloth's largest offset from the skin (base + wrinkles): hair keeps off it

    drape = DRAPES[kind_of(aid, style if aid == "uniform" else None)]
    info["drape"] = {"amp_m": drape.amp, "wavelength_m": drape.wavelength, "bridge_m": drape.bridge}

    def wr(base, extra=None):  # the outer cloth's offset: thickness + folds (synth.assets.fit.folds)
        folds = Folds(body, rng, base, drape, extra)
        reach.append(folds.reach(elbow=sleeves == "long"))
        return folds

    if aid in ("tshirt_crew", "sweater", "hoodie", "scarf_over_sweater") or (aid == "uniform" and style not in (
            "scrubs", "work_shirt", "polo")):
        depth = p.neckline_depth(vneck=False)
        base = thick + 0.0015
        rim = 0.0035 if aid != "tshirt_crew" else 0.002
        torso_shell(body, parts, crew_neckline(body, 0.008, depth), wr(base), rim=rim, rim_flatten=0.8,
                    sleeves=sleeves)
        if aid == "hoodie":
            if bool(p.hood_up):
                hood_up(body, parts, 0, base)
            else:
                neck_tube(body, parts, 0, lambda t: fr.z_ring(t) + 0.02, 0.012 + base, 0.022,
                           angles=(np.pi - 2.0, np.pi + 2.0), taper=True)
            if bool(p.drawstrings):
                for sx in (-1, 1):
                    start = body.neck_loop(crew_neckline(body, 0.008, depth), 48, angle0=np.pi)
                    k = int(np.argmin(np.abs(fr.theta(start) - sx * 0.35)))
                    hanging_strip(body, parts, 0, start[k], 0.11, 0.0025, 0.0025, base + 0.002, n=8)
        if aid == "scarf_over_sweater":
            st = float(p.scarf_thickness_m)
            wrap = str(p.wrap)
            cloths.append(Cloth("garment_scarf", colour, "wool_knit", 0.006, seed + 1))

            def zc(t):
                return np.minimum(fr.z_ring(t) + 0.035, fr.z_cap(t) - 0.03)
            if wrap in ("loop", "knot"):
                neck_tube(body, parts, 1, zc, st / 2 + base, 0.03)
            else:
                neck_tube(body, parts, 1, zc, st / 2 + base, 0.03, angles=(np.pi - 2.2, np.pi + 2.2))
            loop = body.neck_loop(zc, 48, angle0=np.pi)
            if wrap == "knot":
                Vs, Fs = icosphere(2)
                k0 = loop[0]
                ctr = k0 + fr.outward(k0[None])[0] * (st + 0.02) + np.array([0, 0, -0.035])
                parts.add(push_out(ctr + Vs * np.array([0.035, 0.025, 0.03]), body.query, base + 0.004), Fs, 1)
                hanging_strip(body, parts, 1, ctr + np.array([0.01, 0, -0.02]), 0.14, 0.035, st / 2, base + 0.004)
            elif wrap == "drape":
                for sx in (-1, 1):
                    k = int(np.argmin(np.abs(fr.theta(loop) - sx * 2.2 / 1.0 * 0.5)))
                    hanging_strip(body, parts, 1, loop[k] + np.array([0, -0.01, -0.02]), 0.17, 0.03, st / 2, base + 0.004)
            else:
                hanging_strip(body, parts, 1, loop[0] + np.array([0.015, -0.01, -0.03]), 0.12, 0.03, st / 2, base + 0.004)
        info["neckline_depth_m"] = depth
    elif aid in ("tshirt_vneck",) or (aid == "uniform" and style == "scrubs"):
        depth = p.neckline_depth(vneck=True)
        base = thick + 0.0015
        torso_shell(body, parts, vee_neckline(body, 0.008, depth, 0.75), wr(base), rim=0.002, rim_flatten=0.8,
                    sleeves=sleeves)
        info["neckline_depth_m"] = depth
    elif aid == "turtleneck":
        h = float(p.collar_height_m)
        base = thick + 0.0015
        def collar(P, N):  # the collar stands a little off the neck
            return 0.003 * smoothstep(P[:, 2] - (fr.z_ring(fr.theta(P)) + 0.005), 0.0, 0.02)
        def z(t):  # the collar's top: h above the neck base, under the jaw, the corner between rounded
            top = fr.z_ring(t) + h
            return smooth_min(top, np.minimum(fr.z_cap(t), top + 1.0), COLLAR_ROUND)
        torso_shell(body, parts, z, wr(base, collar), rim=0.006, rim_flatten=0.9, sleeves=sleeves)
        # the top folded down over the collar's outside
        rolled_collar(body, parts, 0, z, base + 0.003, thick, min(0.45 * h, 0.03), rng, ribbed=fabric == "wool_knit")
        info["collar_height_m"] = h
    elif aid in ("shirt_collar",) or (aid == "uniform" and style in ("work_shirt", "polo")):
        tie = bool(p.tie) and aid == "shirt_collar"
        open_top = bool(p.top_button_open) and not tie
        base = thick + 0.001
        depth = 0.045 if open_top else 0.0
        P, F, _ = torso_shell(body, parts, vee_neckline(body, 0.006, depth, 0.35), wr(base), rim=0.0,
                              sleeves=sleeves)
        shirt_collar(body, parts, 0, base, open_top, (P, F), leaf=0.035 if style == "polo" else 0.045)
        if tie:
            cloths.append(Cloth("garment_tie", (rng.uniform(), 0.7, 0.5), "linen", 0.005, seed + 2))
            necktie(body, parts, 1, base + 0.004)
        info.update(tie=tie, top_button_open=open_top)
    elif aid in ("jacket_blazer", "coat"):
        under = str(p.undershirt) if aid == "jacket_blazer" else "shirt"
        if under != "none":
            ufab = "cotton_poplin" if under == "shirt" else "cotton_jersey"
            cloths.append(Cloth("garment_under", "white" if under == "shirt" else "grey", ufab, 0.005, seed + 3))
            ub = FABRICS[ufab][0] + 0.001
            if under == "shirt":
                P, F, _ = torso_shell(body, parts, vee_neckline(body, 0.006, 0.0, 0.35),
                                      Folds(body, rng, ub, DRAPES["under"]), slot=1)
                shirt_collar(body, parts, 1, ub, False, (P, F), band_h=0.028, leaf=0.035)
            else:
                torso_shell(body, parts, crew_neckline(body, 0.006, 0.01), Folds(body, rng, ub, DRAPES["under"]),
                            slot=1, rim=0.002)
        coat = aid == "coat"
        base = (0.014 if coat else 0.009) + thick
        lw = float(p.lapel_width_m)
        depth, half = (0.10, 0.9) if coat else (0.14, 0.85)
        zfn = vee_neckline(body, 0.02, depth, half)
        # lapels: a raised band (+5 mm) along the V edge on the front
        def lapels(P, N):
            th = fr.theta(P)
            r = fr.rxy(P)
            zr = fr.z_ring(th) + 0.02 + 0.008 * (1 - np.cos(th))
            frac = np.clip((zr - P[:, 2]) / depth, 0.0, 1.0)
            edge = half * (1.0 - frac)  # theta of the V edge at this height
            s = (np.abs(th) - edge) * r
            band = smoothstep(s, -0.002, 0.004) * (1.0 - smoothstep(s, lw - 0.008, lw))
            band = band * (np.cos(th) > 0.2) * (frac < 0.999)
            return 0.005 * band
        torso_shell(body, parts, zfn, wr(base, lapels), rim=0.003, rim_flatten=0.7, sleeves=sleeves)
        if coat and bool(p.collar_up):
            neck_tube(body, parts, 0, lambda t: np.minimum(fr.z_ring(t) + 0.04, fr.z_cap(t) - 0.02), base, 0.03,
                       angles=(0.6, 2 * np.pi - 0.6))
        else:
            neck_tube(body, parts, 0, lambda t: fr.z_ring(t) + 0.03, base * 0.6, 0.015,
                       angles=(np.pi - 1.9, np.pi + 1.9))
        info.update(undershirt=under, lapel_width_m=lw, collar_up=bool(p.collar_up))
    elif aid == "tank_top":
        w = float(p.strap_width_m)
        base = thick + 0.0015
        xs = 0.5 * fr.radius + 0.045

        def extra(fnl):
            V = body.V
            th = fr.theta(V)
            zr = fr.z_ring(th)
            torso = smooth_min(zr - 0.05 - 0.04 * front_weight(th) - V[:, 2], 0.13 - np.abs(V[:, 0]), TANK_ROUND)
            strap = smooth_min(w / 2 - np.abs(np.abs(V[:, 0]) - xs), zr + 0.01 - V[:, 2], 0.5 * w)
            band = TANK_BAND - body.hem  # a band along the hem (the cut's arm stumps without the bust)
            # the openings' corners (strap on torso, torso on band) rounded: arm holes, not notches
            return smooth_max(smooth_max(torso, strap, TANK_ROUND), band, TANK_ROUND)
        torso_shell(body, parts, lambda t: fr.z_ring(t), wr(base), extra_field=extra, rim=0.0, sleeves=sleeves)
        info["strap_width_m"] = w
    else:
        raise ValueError(f"unknown garment id '{aid}'")

    info["sleeves"] = sleeves
    if body.arms is not None and sleeves == "short":
        from synth.assets.fit.arms import SHORT_SLEEVE_T, sleeve_end

        info["sleeve_end_t"] = round(sleeve_end(body.arms, SHORT_SLEEVE_T), 4)
    info["cloth_reach_m"] = round(float(reach[0]), 6)  # the outer shell's (its first Folds)
    anchors = np.union1d(body.torso_tris, body.head_tris) if aid == "hoodie" else body.torso_tris
    return Shell("garment", f"garment_{aid}", parts, anchors, cloths, info)
