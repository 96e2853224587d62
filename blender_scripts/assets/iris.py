"""Iris rig: a procedural iris on the eye material (no new objects).

Per-vertex eye coordinates are written to the head mesh (point attribute ``iris_coord``):
for each eyeball, with its centre fitted to the rest-pose sclera and its forward axis from
the centre to the iris centroid (the eye joint's rest orientation), ``(rho cos phi, rho sin
phi, rho)`` where ``rho`` is the angle from the forward axis divided by the limbus angle
(0 at the pupil centre, 1 at the limbus) and ``phi`` the angle around the axis (mirrored on
the left eye so nasal/temporal match). Being attached to vertices, the coordinates follow
the eyeball when the eye joints rotate (gaze), for both eyes.

The shader (``synth.appearance.iris`` palette from melanin + stroma scattering): radial fibres (noise
stretched along rho), crypts (Voronoi), a collarette / central-heterochromia inner zone,
the limbal ring and the pupil (radius from ``pupil_dilation``), mixed over the sclera.
"""

from __future__ import annotations

import numpy as np

from blender_scripts import materials as bmat
from blender_scripts.assets import Rig
from synth.appearance.iris import iris_palette, pupil_ratio
from synth.dataset.segmentation import CLASSES


def _sphere_centre(P):
    A = np.c_[2 * P, np.ones(len(P))]
    b = (P ** 2).sum(1)
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    return x[:3]


def eye_coordinates(data, rest: np.ndarray) -> tuple[np.ndarray, dict]:
    V = np.asarray(rest, np.float64)
    out = np.full((len(V), 3), 9.0)
    info = {}
    for side, s in (("l", 1.0), ("r", -1.0)):
        eye = data.regions.get(f"eye_{side}")
        sclera = data.regions.get(f"sclera_{side}", eye)
        iris = data.regions.get(f"iris_{side}")
        if eye is None or sclera is None:
            continue
        eye = np.asarray(eye, np.int64)
        c = _sphere_centre(V[np.asarray(sclera, np.int64)])
        if iris is not None:
            f = V[np.asarray(iris, np.int64)].mean(0) - c
        else:
            f = np.array([0.0, -1.0, 0.0])
        f /= np.linalg.norm(f)
        u = np.cross(f, [0.0, 0.0, 1.0])
        u /= np.linalg.norm(u)
        w = np.cross(u, f)
        q = V[eye] - c
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        theta = np.arccos(np.clip(q @ f, -1, 1))
        if iris is not None:
            qi = V[np.asarray(iris, np.int64)] - c
            qi /= np.linalg.norm(qi, axis=1, keepdims=True)
            lim = float(np.arccos(np.clip(qi @ f, -1, 1)).max())
        else:
            lim = 0.5
        rho = theta / lim
        phi = np.arctan2(q @ w, s * (q @ u))
        out[eye] = np.c_[rho * np.cos(phi), rho * np.sin(phi), rho]
        info[side] = {"centre": c.round(6).tolist(), "forward": f.round(5).tolist(), "limbus_rad": round(lim, 5)}
    return out, info


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
