"""Skin detail rig: procedural layers on the skin material from skin.toml parameters.

Layers (all masked per vertex by the ``skin_mask`` point colour attribute: R cheeks+nose,
G T-zone, B wrinkle zones, A beard area):

* freckles (small Voronoi spots on cheeks and nose, density/strength ~ ``freckles``),
* age spots / moles (sparse larger Voronoi spots on the face, ``age_spots``),
  both, and the stubble shadow's noise, built only as far as the identity's finest view resolves
  them (:func:`synth.appearance.skin_optics.spot_weight`): below the pixel a layer is its mean,
  a flat tint over its mask (there the pattern is only sampling noise),
* redness (cheeks and nose, from ``haemoglobin``),
* mottling: millimetre-scale fBm unevenness of the albedo over the whole skin (mean 1; browner and
  redder where darker), faded below the pixel (``synth.appearance.skin_optics.MOTTLE_*``),
* oiliness -> lower roughness and a stronger sharp specular lobe (coat) in the T-zone,
* wrinkles (forehead bands, crow's feet, nasolabial folds) as a bump, ``wrinkle_depth``, faded
  by the resolution rule of :mod:`synth.appearance.skin_optics` (``ctx.pixel_m``),
* ``detail_variant`` seeds the noise (pores and fine lines at ``pore_scale`` are the base
  material's: ``blender_scripts.materials.skin_material``),
* the tear meniscus: coat and low roughness on the lower lids' margin (``tear_line`` attribute,
  :func:`synth.assets.fit.eyes.lid_margin`),
* stubble shadow over the beard area (feathered at its edge) when the identity has no beard
  (drawn with probability 0.5 and a light strength) or has the ``stubble`` beard, as dark as
  the beard's (else the scalp hair's) colour is (:func:`synth.appearance.pigment.shaft_darkness`),
* scalp shadow where scalp hair grows (``scalp_mask`` attribute,
  :func:`synth.assets.fit.masks.scalp_hair_area`), as dark as the hair's colour is,
* under-eye darkening (periorbital, deepest at the tear trough) and redness of the ears, over the
  ``skin_tint`` attribute (:func:`synth.assets.fit.masks.skin_tint_mask`), the first drawn per
  identity (:data:`UNDER_EYE`), the second from ``haemoglobin`` as the cheeks',
* vellus hair as a sheen (the Principled BSDF's sheen layer: a soft bright rim at grazing angles),
  its weight drawn per identity (:data:`VELLUS_SHEEN`).

The base albedo (melanin/haemoglobin) is set by the worker through ``head_materials``.
"""

from __future__ import annotations

import numpy as np

from blender_scripts import materials as bmat
from blender_scripts.assets import Rig
from synth.appearance import skin_optics as so
from synth.appearance.skin_optics import WRINKLES, detail_weight, sharp_lobe
from synth.appearance.pigment import pigment, shaft_darkness
from synth.assets.fit.eyes import lid_margin
from synth.assets.fit.groom import colour_of, head_frame
from synth.assets.fit.masks import scalp_hair_area, skin_detail_mask, skin_tint_mask
from synth.assets.params import AssetPick, BeardParams
from synth.dataset.segmentation import CLASSES


#: stubble shadow of the ``stubble`` beard for black hair (at 0.55, with the strands on top,
#: light skin reads as a dirty brown patch); identities without a beard draw 0.1-0.3 with
#: probability 0.5; both scaled by the hair's :func:`shaft_darkness`
STUBBLE_SHADOW = 0.3


#: scalp shadow under scalp hair for black hair (scaled by the hair's :func:`shaft_darkness`), and
#: the colour it multiplies the skin by at full strength (the stubble shadow's)
SCALP_SHADOW = 1.0
SCALP_SHADOW_COLOUR = (0.35, 0.33, 0.34)


#: under-eye darkening: the strength (layer factor at the area's centre) is drawn uniformly in this
#: range per identity; the colour it multiplies the skin by at strength 1 (a violet-brown shadow:
#: about -12 L* on mid skin at 1, so -0.5 to -5 over the range)
UNDER_EYE = (0.05, 0.45)
UNDER_EYE_COLOUR = (0.72, 0.64, 0.70)
#: the ears' redness relative to the cheeks' (thin, well-perfused skin)
EAR_REDNESS = 0.8
#: vellus hair: the sheen layer's weight, drawn uniformly in this range per identity, its
#: roughness and tint (the fine hairs scatter a pale, nearly white rim)
VELLUS_SHEEN = (0.04, 0.2)
VELLUS_ROUGHNESS = 0.35
VELLUS_TINT = (0.95, 0.93, 0.9)


def _tex_node(mat, kind, scale, seed, vec=None):
    nt = mat.node_tree
    t = nt.nodes.new(kind)
    if hasattr(t, "voronoi_dimensions"):
        t.voronoi_dimensions = "4D"
    if hasattr(t, "noise_dimensions"):
        t.noise_dimensions = "4D"
    t.inputs["Scale"].default_value = scale
    if "W" in t.inputs:
        t.inputs["W"].default_value = seed
    coord = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(vec if vec is not None else coord.outputs["Object"], t.inputs["Vector"])
    return t


def _blend_mean(mat, tex, w: float, mean: float, mask):
    """``mask * (w * tex + (1 - w) * mean)``: a detail layer faded to its mean below the pixel
    (``tex`` is not used, and need not exist, at w = 0)."""
    if w <= 0.0:
        return bmat.math_node(mat, "MULTIPLY", mask, mean)
    if w < 1.0:
        tex = bmat.math_node(mat, "ADD", bmat.math_node(mat, "MULTIPLY", tex, w), (1.0 - w) * mean)
    return bmat.math_node(mat, "MULTIPLY", tex, mask)


def spot_factor(mat, layer: tuple[float, float], seed: float, threshold: float, mask, w: float):
    """Factor of a Voronoi spot layer (``layer`` = (cell_m, radius) of skin_optics): 1 in the
    cells whose random colour is below ``threshold``, within ``radius`` cells of their feature
    point; faded to its mean coverage by ``w``; times ``mask``."""
    cell, radius = layer
    tex = None
    if w > 0.0:
        v = _tex_node(mat, "ShaderNodeTexVoronoi", 1.0 / cell, seed)
        sepc = mat.node_tree.nodes.new("ShaderNodeSeparateColor")
        mat.node_tree.links.new(v.outputs["Color"], sepc.inputs["Color"])
        spot = bmat.math_node(mat, "LESS_THAN", sepc.outputs[0], threshold)
        small = bmat.math_node(mat, "LESS_THAN", v.outputs["Distance"], radius)
        tex = bmat.math_node(mat, "MULTIPLY", spot, small)
    return _blend_mean(mat, tex, w, so.spot_coverage(threshold, radius), mask)


def stubble_factor(mat, seed: float, strength: float, mask, w: float):
    """Factor of the stubble shadow: ``strength`` x a fine noise over ``mask``, faded to the
    noise's mean by ``w`` (its period is far below the pixel in every preset)."""
    tex = None
    if w > 0.0:
        tex = _tex_node(mat, "ShaderNodeTexNoise", 1.0 / so.STUBBLE_PERIOD_M, seed).outputs["Fac"]
    return _blend_mean(mat, tex, w, so.NOISE_FAC_MEAN, bmat.math_node(mat, "MULTIPLY", mask, strength))


def mottle_factor(mat, seed: float, amplitude: float):
    """Colour socket of the mottling: ``1 - amplitude * (fac - 0.5) * MOTTLE_TINT`` per channel over
    an fBm noise ``fac`` (mean 1, so the skin's calibrated colour stays on average)."""
    nt = mat.node_tree
    n = _tex_node(mat, "ShaderNodeTexNoise", 1.0 / so.MOTTLE_PERIOD_M, seed)
    n.inputs["Detail"].default_value = so.MOTTLE_DETAIL
    n.inputs["Roughness"].default_value = so.MOTTLE_ROUGHNESS
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    nt.links.new(n.outputs["Fac"], mix.inputs[0])
    mix.inputs[6].default_value = (*(1.0 + 0.5 * amplitude * t for t in so.MOTTLE_TINT), 1.0)  # fac 0
    mix.inputs[7].default_value = (*(1.0 - 0.5 * amplitude * t for t in so.MOTTLE_TINT), 1.0)  # fac 1
    return mix.outputs[2]


def build(ctx, entry: AssetPick) -> Rig:
    p = entry.params
    rng = ctx.rng("skin")
    rng.integers(64)  # drawn, not used (the plan gives detail_variant): the draws after it stay aligned
    seed = float(p.detail_variant) * 7.31
    stub_draw, stub_level = float(rng.random()), float(rng.uniform(0.1, 0.3))
    under_eye, sheen = float(rng.uniform(*UNDER_EYE)), float(rng.uniform(*VELLUS_SHEEN))
    mat = ctx.materials[CLASSES["skin"]]
    nt = mat.node_tree
    V, lm = np.asarray(ctx.vertices), np.asarray(ctx.landmarks["ibug68"])
    beard_entry, hair_entry = ctx.pick("beard"), ctx.pick("hair")
    reach = (beard_entry.params if beard_entry is not None else BeardParams()).reach  # the beard's cheek line
    bmat.write_point_colour(ctx.head.data, "skin_mask", skin_detail_mask(ctx.data, V, lm, reach))
    attr = bmat.attribute(mat, "skin_mask")
    sep = nt.nodes.new("ShaderNodeSeparateColor")
    nt.links.new(attr.outputs["Color"], sep.inputs["Color"])
    cheeks, tzone, wzone, beard = sep.outputs[0], sep.outputs[1], sep.outputs[2], attr.outputs["Alpha"]
    rec = {"id": entry.id}
    pore = float(p.pore_scale)  # the base material builds the pores (materials.skin_material)
    # redness from blood volume
    red = float(np.clip(float(p.haemoglobin) / 0.07, 0, 1))
    bmat.layer_over(mat, "Base Color", (0.75, 0.3, 0.3), bmat.math_node(mat, "MULTIPLY", cheeks, 0.35 * red),
                    blend="MULTIPLY")
    # mottling: millimetre-scale unevenness of the albedo (mean 1), faded out where even its
    # coarsest octave is below the pixel
    w_mo = 1.0 if ctx.pixel_m is None else detail_weight(ctx.pixel_m, so.MOTTLE_PERIOD_M)
    mottle = so.MOTTLE_AMPLITUDE * w_mo
    if mottle > 0.0:
        bmat.layer_over(mat, "Base Color", mottle_factor(mat, seed + 11, mottle), 1.0, blend="MULTIPLY")
    # freckles: small cells, random per cell, thresholded by the amount
    fr = float(p.freckles)
    w_fr = so.spot_weight(ctx.pixel_m, so.FRECKLES)
    if fr > 0.01:
        f = spot_factor(mat, so.FRECKLES, seed, 0.6 * fr, bmat.math_node(mat, "MULTIPLY", cheeks, 0.8), w_fr)
        bmat.layer_over(mat, "Base Color", (0.55, 0.35, 0.22), f, blend="MULTIPLY")
    ag = float(p.age_spots)
    w_ag = so.spot_weight(ctx.pixel_m, so.AGE_SPOTS)
    if ag > 0.01:
        f = spot_factor(mat, so.AGE_SPOTS, seed + 3, 0.25 * ag, bmat.math_node(mat, "MAXIMUM", cheeks, wzone), w_ag)
        bmat.layer_over(mat, "Base Color", (0.45, 0.3, 0.2), f, blend="MULTIPLY")
    oil = float(p.oiliness)
    if oil > 0.0:  # an oilier T-zone: both lobes sharper, the sharp one stronger
        base_r = float(p.roughness)
        tz = bmat.math_node(mat, "MULTIPLY", tzone, 0.9)
        bmat.layer_over(mat, "Roughness", base_r * (1 - 0.6 * oil), tz)
        bmat.layer_over(mat, "Coat Weight", sharp_lobe(base_r, min(1.0, 2.0 * oil))["Coat Weight"], tz)
    # the tear meniscus: a wet, sharp reflection along the lower lids' margin
    bmat.write_point_vector(ctx.head.data, "tear_line", np.repeat(lid_margin(ctx.data, V)[:, None], 3, 1))
    tear = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(bmat.attribute(mat, "tear_line").outputs["Vector"], tear.inputs[0])
    for name, value in (("Coat Weight", 1.0), ("Coat Roughness", 0.03), ("Roughness", 0.15)):
        bmat.layer_over(mat, name, value, tear.outputs["X"])
    wd = float(p.wrinkle_depth)
    w_wr = 1.0 if ctx.pixel_m is None else detail_weight(ctx.pixel_m, WRINKLES[0])
    if wd > 0.01 and w_wr > 0.0:
        wave = _tex_node(mat, "ShaderNodeTexWave", 90.0, seed)
        wave.wave_type = "BANDS"
        wave.bands_direction = "Z"
        wave.inputs["Distortion"].default_value = 3.0
        h = bmat.math_node(mat, "MULTIPLY", wave.outputs["Fac"], wzone)
        bmat.chain_bump(mat, h, 0.35 * wd * w_wr, 0.0006)
    beard_id = beard_entry.id if beard_entry is not None else None
    # the shadow of shaved or short beard hair shows as far as the hair is darker than the skin
    dark = shaft_darkness(pigment(colour_of(beard_entry, ctx)))
    stubble = 0.0
    if beard_id == "stubble":
        stubble = STUBBLE_SHADOW * dark
    elif beard_entry is None and stub_draw < 0.5:
        stubble = stub_level * dark
    w_st = 1.0 if ctx.pixel_m is None else detail_weight(ctx.pixel_m, so.STUBBLE_PERIOD_M)
    if stubble > 0:
        f = stubble_factor(mat, seed + 5, 1.6 * stubble, beard, w_st)
        bmat.layer_over(mat, "Base Color", (0.35, 0.33, 0.34), bmat.math_node(mat, "MINIMUM", f, 1.0),
                        blend="MULTIPLY")
    # the scalp shadow: under scalp hair the skin between the strands reads as the hair's colour
    # (a render carries far fewer strands than a head has hairs, and bare pink scalp showed
    # through them from above); as dark as the hair is, where it grows (receding hairline kept)
    scalp = 0.0
    if hair_entry is not None:
        scalp = SCALP_SHADOW * shaft_darkness(pigment(colour_of(hair_entry, ctx)))
        rec_h = float(hair_entry.params.hairline_recession)
        area = scalp_hair_area(ctx.data, V, head_frame(ctx), rec_h)
        bmat.write_point_vector(ctx.head.data, "scalp_mask", np.repeat(area[:, None], 3, 1))
        sm = nt.nodes.new("ShaderNodeSeparateXYZ")
        nt.links.new(bmat.attribute(mat, "scalp_mask").outputs["Vector"], sm.inputs[0])
        bmat.layer_over(mat, "Base Color", SCALP_SHADOW_COLOUR, bmat.math_node(mat, "MULTIPLY", sm.outputs["X"], scalp),
                        blend="MULTIPLY")
    # under-eye darkening and the ears' redness over the second mask
    bmat.write_point_vector(ctx.head.data, "skin_tint", skin_tint_mask(ctx.data, V, lm))
    tint = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(bmat.attribute(mat, "skin_tint").outputs["Vector"], tint.inputs[0])
    bmat.layer_over(mat, "Base Color", UNDER_EYE_COLOUR, bmat.math_node(mat, "MULTIPLY", tint.outputs["X"], under_eye),
                    blend="MULTIPLY")
    bmat.layer_over(mat, "Base Color", (0.75, 0.3, 0.3),
                    bmat.math_node(mat, "MULTIPLY", tint.outputs["Y"], 0.35 * EAR_REDNESS * red), blend="MULTIPLY")
    # vellus hair: a sheen at grazing angles
    bsdf = bmat.principled(mat)
    bsdf.inputs["Sheen Weight"].default_value = sheen
    bsdf.inputs["Sheen Roughness"].default_value = VELLUS_ROUGHNESS
    bsdf.inputs["Sheen Tint"].default_value = (*VELLUS_TINT, 1.0)
    rec.update(freckles=fr, age_spots=ag, redness=round(red, 4), oiliness=oil, wrinkle_depth=wd,
               pore_scale=pore, stubble_shadow=round(stubble, 4), scalp_shadow=round(scalp, 4),
               under_eye=round(under_eye, 4), vellus_sheen=round(sheen, 4),
               detail={"pixel_m": None if ctx.pixel_m is None else round(ctx.pixel_m, 7),
                       "pores": round(float(mat.get("detail_pores", 1.0)), 4),
                       "fine_lines": round(float(mat.get("detail_fine_lines", 1.0)), 4), "wrinkles": round(w_wr, 4),
                       "mottle": round(w_mo, 4), "freckles": round(w_fr, 4), "age_spots": round(w_ag, 4),
                       "stubble": round(w_st, 4)})
    return Rig("skin", [], rec)
