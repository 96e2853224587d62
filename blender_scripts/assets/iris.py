"""Iris rig: a procedural iris on the eye material (no new objects).

Polar eye coordinates per vertex (``rho``: 0 at the pupil centre, 1 at the limbus; ``phi``
around the eye's axis; :func:`synth.assets.fit.eyes.eye_coordinates`) are written to the
head mesh (point attribute ``iris_coord``). Being attached to vertices, the coordinates
follow the eyeball when the eye joints rotate (gaze), for both eyes.

The shader (``synth.appearance.iris`` palette from melanin + stroma scattering): radial fibres (noise
stretched along rho), crypts (Voronoi), a collarette / central-heterochromia inner zone,
the limbal ring and the pupil (radius from ``pupil_dilation``), mixed over the sclera.
"""

from __future__ import annotations

from blender_scripts import materials as bmat
from blender_scripts.assets import Rig
from synth.appearance.iris import iris_palette, pupil_ratio
from synth.assets.fit.eyes import eye_coordinates
from synth.dataset.segmentation import CLASSES


def build(ctx, entry: dict) -> Rig:
    p = dict(entry.get("params") or {})
    rng = ctx.rng("iris")
    seed = float(rng.uniform(0, 100))
    pal = iris_palette(p)
    pupil = pupil_ratio(float(p.get("pupil_dilation", 0.45)))
    coords, info = eye_coordinates(ctx.data, ctx.rest_vertices)
    bmat.write_point_vector(ctx.head.data, "iris_coord", coords)
    mat = ctx.materials[CLASSES["eyes"]]
    nt = mat.node_tree
    attr = bmat.attribute(mat, "iris_coord")
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(attr.outputs["Vector"], sep.inputs["Vector"])
    rho = sep.outputs["Z"]
    # polar texture space: unit direction around the axis (x40) and rho (x3): radial streaks
    dirv = nt.nodes.new("ShaderNodeCombineXYZ")
    nt.links.new(sep.outputs["X"], dirv.inputs["X"])
    nt.links.new(sep.outputs["Y"], dirv.inputs["Y"])
    norm = nt.nodes.new("ShaderNodeVectorMath")
    norm.operation = "NORMALIZE"
    nt.links.new(dirv.outputs[0], norm.inputs[0])
    scale = nt.nodes.new("ShaderNodeVectorMath")
    scale.operation = "SCALE"
    scale.inputs["Scale"].default_value = 40.0
    nt.links.new(norm.outputs[0], scale.inputs[0])
    radial = nt.nodes.new("ShaderNodeCombineXYZ")
    nt.links.new(bmat.math_node(mat, "MULTIPLY", rho, 3.0), radial.inputs["Z"])
    polar = nt.nodes.new("ShaderNodeVectorMath")
    polar.operation = "ADD"
    nt.links.new(scale.outputs[0], polar.inputs[0])
    nt.links.new(radial.outputs[0], polar.inputs[1])
    fib = nt.nodes.new("ShaderNodeTexNoise")
    fib.noise_dimensions = "4D"
    fib.inputs["W"].default_value = seed
    fib.inputs["Scale"].default_value = 1.0
    fib.inputs["Detail"].default_value = 6.0
    nt.links.new(polar.outputs[0], fib.inputs["Vector"])
    contrast = float(p.get("fibre_contrast", 0.35))
    fmap = nt.nodes.new("ShaderNodeMapRange")
    fmap.inputs["From Min"].default_value = 0.35
    fmap.inputs["From Max"].default_value = 0.65
    nt.links.new(fib.outputs["Fac"], fmap.inputs["Value"])
    col = nt.nodes.new("ShaderNodeMix")
    col.data_type = "RGBA"
    col.inputs[6].default_value = (*pal["base"], 1.0)
    col.inputs[7].default_value = (*pal["light"], 1.0)
    nt.links.new(bmat.math_node(mat, "MULTIPLY", fmap.outputs["Result"], 0.4 + contrast), col.inputs[0])
    last = col.outputs[2]

    def over(colour, fac):
        nonlocal last
        m = nt.nodes.new("ShaderNodeMix")
        m.data_type = "RGBA"
        nt.links.new(last, m.inputs[6])
        if hasattr(colour, "node"):
            nt.links.new(colour, m.inputs[7])
        else:
            m.inputs[7].default_value = (*colour, 1.0)
        nt.links.new(fac, m.inputs[0])
        last = m.outputs[2]

    def band(lo, hi, rising=True):
        r = nt.nodes.new("ShaderNodeMapRange")
        r.interpolation_type = "SMOOTHSTEP"
        r.inputs["From Min"].default_value = lo
        r.inputs["From Max"].default_value = hi
        if not rising:
            r.inputs["To Min"].default_value, r.inputs["To Max"].default_value = 1.0, 0.0
        nt.links.new(rho, r.inputs["Value"])
        return r.outputs["Result"]

    # crypts: Voronoi cells in the polar space, darker where a cell centre is near
    vor = nt.nodes.new("ShaderNodeTexVoronoi")
    vor.inputs["Scale"].default_value = 0.18
    nt.links.new(polar.outputs[0], vor.inputs["Vector"])
    crypt = nt.nodes.new("ShaderNodeMapRange")
    crypt.inputs["From Min"].default_value = 0.25
    crypt.inputs["From Max"].default_value = 0.05
    nt.links.new(vor.outputs["Distance"], crypt.inputs["Value"])
    mid = bmat.math_node(mat, "MULTIPLY", band(pupil + 0.1, pupil + 0.25), band(0.7, 0.95, rising=False))
    over(pal["dark"], bmat.math_node(mat, "MULTIPLY", crypt.outputs["Result"], mid))
    # inner (collarette) zone and limbal ring
    het = float(p.get("central_heterochromia", 0.25))
    inner_edge = pupil + (1 - pupil) * 0.35
    over(pal["inner"], bmat.math_node(mat, "MULTIPLY", band(inner_edge - 0.05, inner_edge + 0.05, rising=False),
                                      0.3 + 0.7 * het))
    ring = float(p.get("limbal_ring", 0.5))
    over(pal["limbal"], bmat.math_node(mat, "MULTIPLY", band(0.82, 0.98), ring))
    over((0.004, 0.004, 0.004), band(pupil - 0.03, pupil + 0.01, rising=False))
    # over the sclera, inside the limbus
    bmat.layer_over(mat, "Base Color", last, band(1.0, 1.05, rising=False))
    rec = {"id": entry.get("id"), "palette": {k: [round(c, 5) for c in v] for k, v in pal.items()},
           "pupil_ratio": round(pupil, 4), "eyes": info}
    return Rig("iris", [], rec)
