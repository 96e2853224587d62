"""Skin detail rig: procedural layers on the skin material from skin.toml parameters.

Layers (all masked per vertex by the ``skin_mask`` point colour attribute: R cheeks+nose,
G T-zone, B wrinkle zones, A beard area):

* freckles (small Voronoi spots on cheeks and nose, density/strength ~ ``freckles``),
* age spots / moles (sparse larger Voronoi spots on the face, ``age_spots``),
* redness (cheeks and nose, from ``haemoglobin``),
* oiliness -> lower roughness and a stronger sharp specular lobe (coat) in the T-zone,
* wrinkles (forehead bands, crow's feet, nasolabial folds) as a bump, ``wrinkle_depth``, faded
  by the resolution rule of :mod:`synth.appearance.skin_optics` (``ctx.pixel_m``),
* ``detail_variant`` seeds the noise (pores and fine lines at ``pore_scale`` are the base
  material's: ``blender_scripts.materials.skin_material``),
* the tear meniscus: coat and low roughness on the lower lids' margin (``tear_line`` attribute,
  :func:`synth.assets.fit.eyes.lid_margin`),
* stubble shadow over the beard area when the identity has no beard (drawn with
  probability 0.5 and a light strength) or has the ``stubble`` beard.

The base albedo (melanin/haemoglobin) is set by the worker through ``head_materials``.
"""

from __future__ import annotations

import numpy as np

from blender_scripts import materials as bmat
from blender_scripts.assets import Rig
from synth.appearance.skin_optics import WRINKLES, detail_weight, sharp_lobe
from synth.assets.fit.eyes import lid_margin
from synth.assets.fit.masks import skin_detail_mask
from synth.dataset.segmentation import CLASSES


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


def build(ctx, entry: dict) -> Rig:
    p = dict(entry.get("params") or {})
    rng = ctx.rng("skin")
    seed = float(p.get("detail_variant", rng.integers(64))) * 7.31
    stub_draw, stub_level = float(rng.random()), float(rng.uniform(0.1, 0.3))
    mat = ctx.materials[CLASSES["skin"]]
    nt = mat.node_tree
    V, lm = np.asarray(ctx.vertices), np.asarray(ctx.landmarks["ibug68"])
    bmat.write_point_colour(ctx.head.data, "skin_mask", skin_detail_mask(ctx.data, V, lm))
    attr = bmat.attribute(mat, "skin_mask")
    sep = nt.nodes.new("ShaderNodeSeparateColor")
    nt.links.new(attr.outputs["Color"], sep.inputs["Color"])
    cheeks, tzone, wzone, beard = sep.outputs[0], sep.outputs[1], sep.outputs[2], attr.outputs["Alpha"]
    rec = {"id": entry.get("id")}
    pore = float(p.get("pore_scale", 1.0))  # the base material builds the pores (materials.skin_material)
    # redness from blood volume
    red = float(np.clip(float(p.get("haemoglobin", 0.02)) / 0.07, 0, 1))
    bmat.layer_over(mat, "Base Color", (0.75, 0.3, 0.3), bmat.math_node(mat, "MULTIPLY", cheeks, 0.35 * red),
                    blend="MULTIPLY")
    # freckles: small cells, random per cell, thresholded by the amount
    fr = float(p.get("freckles", 0.0))
    if fr > 0.01:
        v = _tex_node(mat, "ShaderNodeTexVoronoi", 450.0, seed)
        sepc = nt.nodes.new("ShaderNodeSeparateColor")
        nt.links.new(v.outputs["Color"], sepc.inputs["Color"])
        spot = bmat.math_node(mat, "LESS_THAN", sepc.outputs[0], 0.6 * fr)
        small = bmat.math_node(mat, "LESS_THAN", v.outputs["Distance"], 0.35)
        f = bmat.math_node(mat, "MULTIPLY", bmat.math_node(mat, "MULTIPLY", spot, small), cheeks)
        bmat.layer_over(mat, "Base Color", (0.55, 0.35, 0.22), bmat.math_node(mat, "MULTIPLY", f, 0.8),
                        blend="MULTIPLY")
    ag = float(p.get("age_spots", 0.0))
    if ag > 0.01:
        v = _tex_node(mat, "ShaderNodeTexVoronoi", 60.0, seed + 3)
        sepc = nt.nodes.new("ShaderNodeSeparateColor")
        nt.links.new(v.outputs["Color"], sepc.inputs["Color"])
        spot = bmat.math_node(mat, "LESS_THAN", sepc.outputs[0], 0.25 * ag)
        small = bmat.math_node(mat, "LESS_THAN", v.outputs["Distance"], 0.25)
        face = bmat.math_node(mat, "MAXIMUM", cheeks, wzone)
        f = bmat.math_node(mat, "MULTIPLY", bmat.math_node(mat, "MULTIPLY", spot, small), face)
        bmat.layer_over(mat, "Base Color", (0.45, 0.3, 0.2), f, blend="MULTIPLY")
    oil = float(p.get("oiliness", 0.0))
    if oil > 0.0:  # an oilier T-zone: both lobes sharper, the sharp one stronger
        base_r = float(p.get("roughness", 0.45))
        tz = bmat.math_node(mat, "MULTIPLY", tzone, 0.9)
        bmat.layer_over(mat, "Roughness", base_r * (1 - 0.6 * oil), tz)
        bmat.layer_over(mat, "Coat Weight", sharp_lobe(base_r, min(1.0, 2.0 * oil))["Coat Weight"], tz)
    # the tear meniscus: a wet, sharp reflection along the lower lids' margin
    bmat.write_point_vector(ctx.head.data, "tear_line", np.repeat(lid_margin(ctx.data, V)[:, None], 3, 1))
    tear = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(bmat.attribute(mat, "tear_line").outputs["Vector"], tear.inputs[0])
    for name, value in (("Coat Weight", 1.0), ("Coat Roughness", 0.03), ("Roughness", 0.15)):
        bmat.layer_over(mat, name, value, tear.outputs["X"])
    wd = float(p.get("wrinkle_depth", 0.0))
    w_wr = 1.0 if ctx.pixel_m is None else detail_weight(ctx.pixel_m, WRINKLES[0])
    if wd > 0.01 and w_wr > 0.0:
        wave = _tex_node(mat, "ShaderNodeTexWave", 90.0, seed)
        wave.wave_type = "BANDS"
        wave.bands_direction = "Z"
        wave.inputs["Distortion"].default_value = 3.0
        h = bmat.math_node(mat, "MULTIPLY", wave.outputs["Fac"], wzone)
        bmat.chain_bump(mat, h, 0.35 * wd * w_wr, 0.0006)
    beard_entry = (ctx.assets or {}).get("beard")
    beard_id = (beard_entry or {}).get("id")
    stubble = 0.0
    if beard_id == "stubble":
        stubble = 0.55
    elif not beard_entry and stub_draw < 0.5:
        stubble = stub_level
    if stubble > 0:
        nz = _tex_node(mat, "ShaderNodeTexNoise", 2500.0, seed + 5)
        f = bmat.math_node(mat, "MULTIPLY", bmat.math_node(mat, "MULTIPLY", beard, nz.outputs["Fac"]), 1.6 * stubble)
        bmat.layer_over(mat, "Base Color", (0.35, 0.33, 0.34), bmat.math_node(mat, "MINIMUM", f, 1.0),
                        blend="MULTIPLY")
    rec.update(freckles=fr, age_spots=ag, redness=round(red, 4), oiliness=oil, wrinkle_depth=wd,
               pore_scale=pore, stubble_shadow=round(stubble, 4),
               detail={"pixel_m": None if ctx.pixel_m is None else round(ctx.pixel_m, 7),
                       "pores": round(float(mat.get("detail_pores", 1.0)), 4),
                       "fine_lines": round(float(mat.get("detail_fine_lines", 1.0)), 4), "wrinkles": round(w_wr, 4)})
    return Rig("skin", [], rec)
