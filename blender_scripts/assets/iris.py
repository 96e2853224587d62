"""Iris rig: a procedural iris behind a refracting cornea, and the sclera, on the eye material
(no new objects).

Polar eye coordinates per vertex (``rho``: 0 at the pupil centre, 1 at the limbus; ``phi``
around the eye's axis; :func:`synth.assets.fit.eyes.eye_coordinates`) are written to the
head mesh (point attribute ``iris_coord``). Being attached to vertices, the coordinates
follow the eyeball when the eye joints rotate (gaze), for both eyes.

**Cornea.** The mesh's iris region is the corneal dome (about 1.3 mm proud of the sclera). The
iris is not painted on it: the shader refracts the view ray at the dome (IOR ``CORNEA_IOR``,
the cornea's and aqueous humour's) and looks the iris up where the refracted ray meets the iris
plane (the limbus plane, about 2.4 mm behind the apex), so the iris has depth and shifts
against the limbus with the view as a real one does. The eye frame this needs (centre, optical
axis, iris-plane axes, limbus radius: :func:`synth.assets.fit.eyes.eye_frames`) is written as
point attributes from the current vertices, at build and after every expression (gaze) change.
The wet look is the material's clear coat (``blender_scripts.materials``: a smooth dielectric
layer over the whole eye, IOR 1.376): it mirrors what surrounds the eye.

The shader (``synth.appearance.iris`` palette from melanin + stroma scattering): radial fibres (noise
stretched along rho), crypts (Voronoi), a collarette / central-heterochromia inner zone,
the limbal ring and the pupil (radius from ``pupil_dilation``), mixed over the sclera. The
sclera is not flat white: a faint yellow low-frequency tint and a vessel network (Voronoi
edges, distorted) that grows toward the periphery (rho > ``SCLERA_VESSELS_FROM``).

**Caruncle.** At each eye's medial canthus the pink caruncle (a mucosa dotted with glands) and,
lateral to it, the fainter plica semilunaris cover the eyeball (:func:`caruncle_layer`). Without
them the white sclera ran into the inner corner, a doll's eye. Their centre is the canthus on the
current mesh, projected onto the eyeball (``eye_canthus``: :func:`synth.assets.fit.eyes.medial_canthi`), so they stay with
the lids while the eyeball turns under them.
"""

from __future__ import annotations

from blender_scripts import materials as bmat
from blender_scripts.assets import Rig
from synth.appearance.iris import iris_palette, pupil_ratio
from synth.assets.fit.eyes import FRAME_ATTRIBUTES, eye_coordinates, eye_frames, medial_canthi
from synth.assets.params import AssetPick
from synth.dataset.segmentation import CLASSES

#: refractive index of the cornea / aqueous humour (Gullstrand: 1.376 / 1.336)
CORNEA_IOR = 1.376
#: rho (limbus = 1) from which scleral vessels appear, and where they are densest
SCLERA_VESSELS_FROM, SCLERA_VESSELS_FULL = 1.3, 3.0
#: the caruncle and plica semilunaris at the medial canthus (straight-line distance from the
#: canthus, metres): the caruncle's colour up to CARUNCLE_CORE_M, fading out by CARUNCLE_EDGE_M;
#: the plica's fainter pink fading out by PLICA_EDGE_M. The caruncle is a mound a few millimetres
#: across in the tear lake at the rounded medial canthus, the plica a vertical fold lateral to it.
CARUNCLE_CORE_M, CARUNCLE_EDGE_M, PLICA_EDGE_M = 0.0025, 0.004, 0.0055
#: linear albedos: the caruncle (a pink-red mucosa, darker between its glands) and the plica
CARUNCLE_RGB, CARUNCLE_DARK_RGB, PLICA_RGB = (0.46, 0.16, 0.14), (0.30, 0.08, 0.07), (0.66, 0.40, 0.36)


class IrisRig(Rig):
    """Keeps the eye-frame attributes on the current (gaze-rotated) eyes."""

    def update(self, ctx) -> None:
        _write_frames(ctx)


def _write_frames(ctx) -> None:
    for name, v in eye_frames(ctx.data, ctx.vertices).items():
        bmat.write_point_vector(ctx.head.data, name, v)
    bmat.write_point_vector(ctx.head.data, "eye_canthus", medial_canthi(ctx.data, ctx.vertices))


def _map_range(nt, value, lo: float, hi: float, smooth: bool = False):
    """Map Range node: ``value`` from [lo, hi] to [0, 1] (clamped; smoothstep if ``smooth``)."""
    r = nt.nodes.new("ShaderNodeMapRange")
    if smooth:
        r.interpolation_type = "SMOOTHSTEP"
    r.inputs["From Min"].default_value = lo
    r.inputs["From Max"].default_value = hi
    nt.links.new(value, r.inputs["Value"])
    return r.outputs["Result"]


def _vmath(nt, op, a, b=None, scale=None):
    n = nt.nodes.new("ShaderNodeVectorMath")
    n.operation = op
    for i, v in enumerate((a, b)):
        if v is not None:
            nt.links.new(v, n.inputs[i])
    if scale is not None:
        if hasattr(scale, "node"):
            nt.links.new(scale, n.inputs["Scale"])
        else:
            n.inputs["Scale"].default_value = float(scale)
    return n.outputs["Value" if op in ("DOT_PRODUCT", "LENGTH", "DISTANCE") else "Vector"]


def refracted_coordinates(mat, surface):
    """Iris coordinates (same layout as ``iris_coord``) where the view ray, refracted by the
    cornea, meets the iris plane; the surface's own coordinates outside the cornea (rho > 1)."""
    nt = mat.node_tree
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    a = {k: bmat.attribute(mat, k).outputs["Vector"] for k in FRAME_ATTRIBUTES}
    plane = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(a["eye_plane"], plane.inputs[0])
    r_lim, h = plane.outputs["X"], plane.outputs["Y"]
    view_in = _vmath(nt, "SCALE", geo.outputs["Incoming"], scale=-1.0)
    T = _vmath(nt, "REFRACT", view_in, geo.outputs["Normal"], scale=1.0 / CORNEA_IOR)
    p0 = _vmath(nt, "ADD", a["eye_centre"], _vmath(nt, "SCALE", a["eye_fwd"], scale=h))
    num = _vmath(nt, "DOT_PRODUCT", _vmath(nt, "SUBTRACT", p0, geo.outputs["Position"]), a["eye_fwd"])
    t = bmat.math_node(mat, "DIVIDE", num, _vmath(nt, "DOT_PRODUCT", T, a["eye_fwd"]))
    Q = _vmath(nt, "ADD", geo.outputs["Position"], _vmath(nt, "SCALE", T, scale=t))
    d = _vmath(nt, "SUBTRACT", Q, a["eye_centre"])
    x = bmat.math_node(mat, "DIVIDE", _vmath(nt, "DOT_PRODUCT", d, a["eye_u"]), r_lim)
    y = bmat.math_node(mat, "DIVIDE", _vmath(nt, "DOT_PRODUCT", d, a["eye_w"]), r_lim)
    xy = nt.nodes.new("ShaderNodeCombineXYZ")
    nt.links.new(x, xy.inputs["X"])
    nt.links.new(y, xy.inputs["Y"])
    ref = nt.nodes.new("ShaderNodeCombineXYZ")
    nt.links.new(x, ref.inputs["X"])
    nt.links.new(y, ref.inputs["Y"])
    nt.links.new(_vmath(nt, "LENGTH", xy.outputs[0]), ref.inputs["Z"])
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(surface, sep.inputs[0])
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "VECTOR"
    nt.links.new(_map_range(nt, sep.outputs["Z"], 0.97, 1.03, smooth=True), mix.inputs["Factor"])
    nt.links.new(ref.outputs[0], mix.inputs[4])
    nt.links.new(surface, mix.inputs[5])
    return mix.outputs[1]


def sclera_layer(mat, surface, seed: float) -> None:
    """Sclera colour variation over the material's base colour (see the module docstring)."""
    nt = mat.node_tree
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(surface, sep.inputs[0])
    rho = sep.outputs["Z"]
    tint = nt.nodes.new("ShaderNodeTexNoise")
    tint.noise_dimensions = "4D"
    tint.inputs["W"].default_value = seed
    tint.inputs["Scale"].default_value = 1.5
    nt.links.new(surface, tint.inputs["Vector"])
    bmat.layer_over(mat, "Base Color", (0.86, 0.78, 0.62), bmat.math_node(mat, "MULTIPLY", tint.outputs["Fac"], 0.45))
    warp = nt.nodes.new("ShaderNodeTexNoise")
    warp.inputs["Scale"].default_value = 2.0
    warp.inputs["Detail"].default_value = 3.0
    nt.links.new(surface, warp.inputs["Vector"])
    wvec = _vmath(nt, "ADD", surface, _vmath(nt, "SCALE", warp.outputs["Color"], scale=0.6))
    vor = nt.nodes.new("ShaderNodeTexVoronoi")
    vor.feature = "DISTANCE_TO_EDGE"
    vor.voronoi_dimensions = "4D"
    vor.inputs["W"].default_value = seed + 1.0
    vor.inputs["Scale"].default_value = 2.5
    nt.links.new(wvec, vor.inputs["Vector"])
    vessel = _map_range(nt, vor.outputs["Distance"], 0.035, 0.0)
    zone = _map_range(nt, rho, SCLERA_VESSELS_FROM, SCLERA_VESSELS_FULL, smooth=True)
    fac = bmat.math_node(mat, "MULTIPLY", vessel, bmat.math_node(mat, "MULTIPLY", zone, 0.55))
    bmat.layer_over(mat, "Base Color", (0.62, 0.16, 0.13), fac)
    bmat.layer_over(mat, "Base Color", (0.78, 0.52, 0.48), bmat.math_node(mat, "MULTIPLY", zone, 0.25))


def caruncle_layer(mat, seed: float) -> None:
    """The caruncle and the plica semilunaris over the sclera at each eye's medial canthus
    (``eye_canthus``, which follows the lids, not the gaze: the sclera turns under them as a
    real eye's does). It covers the cornea too where the eye turns in far enough to bring the
    limbus under it, as the real caruncle, in front of the eyeball, hides it."""
    nt = mat.node_tree
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    d = _vmath(nt, "DISTANCE", geo.outputs["Position"], bmat.attribute(mat, "eye_canthus").outputs["Vector"])
    plica = _map_range(nt, d, PLICA_EDGE_M, CARUNCLE_CORE_M, smooth=True)
    bmat.layer_over(mat, "Base Color", PLICA_RGB, bmat.math_node(mat, "MULTIPLY", plica, 0.6))
    # glands: fine cells (about 0.4 mm) darker between them
    vor = nt.nodes.new("ShaderNodeTexVoronoi")
    vor.voronoi_dimensions = "4D"
    vor.feature = "DISTANCE_TO_EDGE"
    vor.inputs["W"].default_value = seed + 2.0
    vor.inputs["Scale"].default_value = 2500.0
    nt.links.new(geo.outputs["Position"], vor.inputs["Vector"])
    col = nt.nodes.new("ShaderNodeMix")
    col.data_type = "RGBA"
    col.inputs[6].default_value = (*CARUNCLE_DARK_RGB, 1.0)
    col.inputs[7].default_value = (*CARUNCLE_RGB, 1.0)
    nt.links.new(_map_range(nt, vor.outputs["Distance"], 0.0, 0.12), col.inputs[0])
    core = _map_range(nt, d, CARUNCLE_EDGE_M, CARUNCLE_CORE_M, smooth=True)
    bmat.layer_over(mat, "Base Color", col.outputs[2], core)
    bmat.layer_over(mat, "Roughness", 0.4, core)
    # a rounded, slightly raised mound
    bmat.chain_bump(mat, core, 0.6, 0.0004)


def build(ctx, entry: AssetPick) -> Rig:
    p = entry.params
    rng = ctx.rng("iris")
    seed = float(rng.uniform(0, 100))
    pal = iris_palette(p)
    pupil = pupil_ratio(float(p.pupil_dilation))
    coords, info = eye_coordinates(ctx.data, ctx.rest_vertices)
    bmat.write_point_vector(ctx.head.data, "iris_coord", coords)
    _write_frames(ctx)
    mat = ctx.materials[CLASSES["eyes"]]
    nt = mat.node_tree
    surface = bmat.attribute(mat, "iris_coord").outputs["Vector"]
    sclera_layer(mat, surface, seed)
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(refracted_coordinates(mat, surface), sep.inputs["Vector"])
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
    contrast = float(p.fibre_contrast)
    fmap = _map_range(nt, fib.outputs["Fac"], 0.35, 0.65)
    col = nt.nodes.new("ShaderNodeMix")
    col.data_type = "RGBA"
    col.inputs[6].default_value = (*pal["base"], 1.0)
    col.inputs[7].default_value = (*pal["light"], 1.0)
    nt.links.new(bmat.math_node(mat, "MULTIPLY", fmap, 0.4 + contrast), col.inputs[0])
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
        out = _map_range(nt, rho, lo, hi, smooth=True)
        if not rising:
            out.node.inputs["To Min"].default_value, out.node.inputs["To Max"].default_value = 1.0, 0.0
        return out

    # crypts: Voronoi cells in the polar space, darker where a cell centre is near
    vor = nt.nodes.new("ShaderNodeTexVoronoi")
    vor.inputs["Scale"].default_value = 0.18
    nt.links.new(polar.outputs[0], vor.inputs["Vector"])
    crypt = _map_range(nt, vor.outputs["Distance"], 0.25, 0.05)
    mid = bmat.math_node(mat, "MULTIPLY", band(pupil + 0.1, pupil + 0.25), band(0.7, 0.95, rising=False))
    over(pal["dark"], bmat.math_node(mat, "MULTIPLY", crypt, mid))
    # inner (collarette) zone and limbal ring
    het = p.collarette
    inner_edge = pupil + (1 - pupil) * 0.35
    over(pal["inner"], bmat.math_node(mat, "MULTIPLY", band(inner_edge - 0.05, inner_edge + 0.05, rising=False),
                                      0.3 + 0.7 * het))
    ring = float(p.limbal_ring)
    over(pal["limbal"], bmat.math_node(mat, "MULTIPLY", band(0.82, 0.98), ring))
    over((0.004, 0.004, 0.004), band(pupil - 0.03, pupil + 0.01, rising=False))
    # over the sclera, inside the limbus
    bmat.layer_over(mat, "Base Color", last, band(1.0, 1.05, rising=False))
    caruncle_layer(mat, seed)
    rec = {"id": entry.id, "palette": {k: [round(c, 5) for c in v] for k, v in pal.items()},
           "pupil_ratio": round(pupil, 4), "eyes": info, "cornea_ior": CORNEA_IOR}
    return IrisRig("iris", [], rec)
