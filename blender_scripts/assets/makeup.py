"""Makeup rig: shader layers over the skin material (no new objects).

Masks are computed per vertex with numpy from the head regions and ibug68 landmarks
(:func:`synth.assets.fit.masks.makeup_masks`) and written to the head mesh as two point
colour attributes (``makeup_mask``: lips, eyeshadow, eyeliner, blush; ``makeup_mask2``:
foundation, eyeliner wing envelope; the wing's line is drawn per shading point from two vector
attributes ``makeup_wing_r`` / ``makeup_wing_l``), read back in the skin material by Attribute nodes and mixed over the skin's base colour / roughness / coat.
Looks: ``light_foundation``, ``lipstick`` (with gloss), ``eyeliner`` (optional wing),
``eyeshadow`` (with shimmer), ``blush``, ``full_look`` (lips + shadow + liner + blush).
"""

from __future__ import annotations

import numpy as np

from blender_scripts import materials as bmat
from blender_scripts.assets import Rig
from synth.assets.fit.masks import WING_EDGE_M, WING_TIP_M, makeup_masks, wing_coordinates, wing_width
from synth.assets.params import AssetPick, planned_or
from synth.dataset.segmentation import CLASSES

LIP_COLOURS = {"red": (0.42, 0.02, 0.03), "nude": (0.42, 0.2, 0.15), "pink": (0.6, 0.16, 0.25),
               "berry": (0.2, 0.015, 0.06), "coral": (0.7, 0.18, 0.1), "brown": (0.18, 0.06, 0.035)}
SHADOW_COLOURS = {"brown": (0.12, 0.06, 0.03), "gold": (0.5, 0.33, 0.1), "grey": (0.12, 0.12, 0.13),
                  "plum": (0.17, 0.05, 0.12), "blue": (0.06, 0.12, 0.32), "green": (0.07, 0.2, 0.08)}
LINER = (0.01, 0.008, 0.008)
BLUSH = (0.62, 0.18, 0.2)


def _choose(v, table, rng):
    if v in table:
        return v
    keys = sorted(table)
    return keys[int(rng.integers(len(keys)))]


def _wing_line(ctx, mat, envelope, liner: float):
    """The eyeliner wings drawn per shading point (synth.assets.fit.masks.wing_line, the same
    formula) from the affine wing coordinates written per vertex, inside their per-vertex
    envelope: a line 1-2 mm wide is far thinner than the head's triangles there."""
    m = bmat.math_node
    L = float(np.linalg.norm(WING_TIP_M))
    hw0 = wing_width(liner)
    lines = []
    for name, uv in zip(("makeup_wing_r", "makeup_wing_l"), wing_coordinates(ctx.vertices, ctx.landmarks["ibug68"])):
        bmat.write_point_vector(ctx.head.data, name, uv)
        sep = mat.node_tree.nodes.new("ShaderNodeSeparateXYZ")
        mat.node_tree.links.new(bmat.attribute(mat, name).outputs["Vector"], sep.inputs[0])
        u, v = sep.outputs["X"], sep.outputs["Y"]
        along = m(mat, "MULTIPLY", m(mat, "MAXIMUM", m(mat, "MAXIMUM", m(mat, "MULTIPLY", u, -1.0),
                                                      m(mat, "SUBTRACT", u, 1.0)), 0.0), L)
        d = m(mat, "SQRT", m(mat, "ADD", m(mat, "MULTIPLY", along, along), m(mat, "MULTIPLY", v, v)))
        hw = m(mat, "MULTIPLY", m(mat, "SUBTRACT", 1.0, m(mat, "MULTIPLY", m(mat, "MINIMUM", m(mat, "MAXIMUM", u, 0.0),
                                                                               1.0), 0.75)), hw0)
        lines.append(m(mat, "DIVIDE", m(mat, "SUBTRACT", m(mat, "ADD", hw, WING_EDGE_M), d), WING_EDGE_M, clamp=True))
    return m(mat, "MULTIPLY", m(mat, "MAXIMUM", lines[0], lines[1]), envelope)


def build(ctx, entry: AssetPick) -> Rig:
    look = entry.id
    p = entry.params
    rng = ctx.rng("makeup")
    draws = {"gloss": float(rng.uniform(0, 0.8)), "opacity": float(rng.uniform(0.5, 1.0)),
             "extent": float(rng.uniform(0.3, 1.0)), "thick": float(rng.uniform(0.3, 1.0)),
             "shimmer": float(rng.uniform(0, 0.6)), "blush": float(rng.uniform(0.2, 0.6)),
             "coverage": float(rng.uniform(0.2, 0.6)), "wing": bool(rng.random() < 0.4)}
    layers = {"foundation": 0.0, "lips": 0.0, "shadow": 0.0, "liner": 0.0, "blush": 0.0}
    rec: dict = {"id": look}
    lip_col = _choose(p.lip_colour, LIP_COLOURS, rng)
    sh_col = _choose(p.shadow_colour, SHADOW_COLOURS, rng)
    gloss = float(planned_or(p.gloss, draws["gloss"]))
    shimmer = float(planned_or(p.shimmer, draws["shimmer"]))
    extent = float(planned_or(p.extent, draws["extent"]))
    thick = float(planned_or(p.thickness, draws["thick"]))
    wing = bool(planned_or(p.wing, draws["wing"]))
    if look == "light_foundation":
        layers["foundation"] = float(planned_or(p.coverage, draws["coverage"]))
    elif look == "lipstick":
        layers["lips"] = float(planned_or(p.opacity, draws["opacity"]))
    elif look == "eyeliner":
        layers["liner"] = 1.0
    elif look == "eyeshadow":
        layers["shadow"] = 0.85
    elif look == "blush":
        layers["blush"] = float(planned_or(p.intensity, draws["blush"]))
    elif look == "full_look":  # its gloss: the planned one, else 0.4 (MakeupParams), never drawn
        layers.update(foundation=0.3, lips=0.9, shadow=0.75, blush=float(planned_or(p.blush, draws["blush"])),
                      liner=1.0 if bool(p.eyeliner) else 0.0)
    else:
        raise ValueError(f"unknown makeup look {look!r}")
    m1, m2 = makeup_masks(ctx.data, np.asarray(ctx.vertices), np.asarray(ctx.landmarks["ibug68"]),
                           extent=extent, liner=thick, wing=wing)
    me = ctx.head.data
    bmat.write_point_colour(me, "makeup_mask", m1)
    bmat.write_point_colour(me, "makeup_mask2", m2)
    mat = ctx.materials[CLASSES["skin"]]
    a1 = bmat.attribute(mat, "makeup_mask")
    a2 = bmat.attribute(mat, "makeup_mask2")
    nt = mat.node_tree
    sep1 = nt.nodes.new("ShaderNodeSeparateColor")
    nt.links.new(a1.outputs["Color"], sep1.inputs["Color"])
    sep2 = nt.nodes.new("ShaderNodeSeparateColor")
    nt.links.new(a2.outputs["Color"], sep2.inputs["Color"])
    lips_m, shadow_m, liner_m = sep1.outputs[0], sep1.outputs[1], sep1.outputs[2]
    blush_alpha = a1.outputs["Alpha"]
    found_m = sep2.outputs[0]
    if layers["foundation"] > 0:  # evens tone (less saturated, a touch lighter) and mattifies
        hsv = nt.nodes.new("ShaderNodeHueSaturation")
        hsv.inputs["Saturation"].default_value = 0.8
        hsv.inputs["Value"].default_value = 1.06
        nt.links.new(bmat.input_source(mat, "Base Color"), hsv.inputs["Color"])
        f = bmat.math_node(mat, "MULTIPLY", found_m, layers["foundation"])
        bmat.layer_over(mat, "Base Color", hsv.outputs["Color"], f)
        bmat.layer_over(mat, "Roughness", 0.6, bmat.math_node(mat, "MULTIPLY", f, 0.7))
    if layers["blush"] > 0:
        bmat.layer_over(mat, "Base Color", BLUSH, bmat.math_node(mat, "MULTIPLY", blush_alpha, 0.45 * layers["blush"]),
                        blend="MULTIPLY")
    if layers["shadow"] > 0:
        f = bmat.math_node(mat, "MULTIPLY", shadow_m, layers["shadow"])
        bmat.layer_over(mat, "Base Color", SHADOW_COLOURS[sh_col], f)
        bmat.layer_over(mat, "Roughness", max(0.15, 0.5 - 0.5 * shimmer), f)
        bmat.layer_over(mat, "Metallic", 0.35 * shimmer, f)
        rec.update(eyeshadow_colour=sh_col, extent=round(extent, 4), shimmer=round(shimmer, 4))
    if layers["liner"] > 0:
        if wing:
            liner_m = bmat.math_node(mat, "MAXIMUM", liner_m, _wing_line(ctx, mat, sep2.outputs[1], thick))
        bmat.layer_over(mat, "Base Color", LINER, bmat.math_node(mat, "MULTIPLY", liner_m, 0.95))
        rec.update(eyeliner_thickness=round(thick, 4), wing=wing)
    if layers["lips"] > 0:
        f = bmat.math_node(mat, "MULTIPLY", lips_m, layers["lips"])
        bmat.layer_over(mat, "Base Color", LIP_COLOURS[lip_col], f)
        bmat.layer_over(mat, "Roughness", max(0.08, 0.5 - 0.5 * gloss), f)
        bmat.layer_over(mat, "Coat Weight", gloss, f)
        rec.update(lip_colour=lip_col, gloss=round(gloss, 4), opacity=round(layers["lips"], 4))
    rec["layers"] = {k: round(v, 4) for k, v in layers.items()}
    rec["mask_vertices"] = {k: int((m1[:, i] > 0.5).sum()) for i, k in enumerate(("lips", "eyeshadow", "eyeliner",
                                                                                  "blush"))}
    return Rig("makeup", [], rec)
