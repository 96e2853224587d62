"""Procedural upper-body garments (``procedural:garment_shell``): the Blender side.

The geometry (necklines, collars, hoods, scarves, the fit to the bust and the binding that
follows expressions) is numpy in :mod:`synth.assets.fit.garment` and
:mod:`synth.assets.fit.body` (the body below it and the forearms: :mod:`synth.assets.fit.torso`,
:mod:`synth.assets.fit.arms`); this module turns a fitted shell into one mesh object
(segmentation class ``clothing``, pass index 9) with Principled cloth materials per
``fabric`` (roughness, sheen, knit stitches at ``knit_scale_m``, twill, fleece fuzz, leather
grain) and procedural wrinkle bump. The headwear rig uses the same helpers.
"""

from __future__ import annotations

import numpy as np

from blender_scripts.assets import HeadContext, Rig
from synth.assets.classes import CLASSES
from synth.assets.fit.body import Body, Cloth, FittedShell, fit_shell
from synth.assets.fit.garment import CLEARANCE, FABRICS, colour_rgb, garment_shell
from synth.assets.fit.hem import hidden_polygons
from synth.assets.fit import torso as torso_fit
from synth.assets.params import AssetPick
from synth.dataset.segmentation import CLASSES as SEGMENTATION


def cloth_material(cls: str, cloth: Cloth):
    """Principled cloth for asset class ``cls``: colour (or pattern), roughness and sheen per
    fabric, a procedural stitch / weave bump and low-frequency wrinkle bump (object space, so
    it follows the mesh)."""
    import bpy

    name, colour, fabric, knit_scale, seed = cloth.name, cloth.colour, cloth.fabric, cloth.knit_scale, cloth.seed
    thick, rough, sheen, kind = FABRICS.get(fabric, FABRICS["cotton_jersey"])
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.pass_index = CLASSES[cls].segmentation_id
    nt = mat.node_tree
    nodes, links = nt.nodes, nt.links
    bsdf = nodes["Principled BSDF"]
    coord = nodes.new("ShaderNodeTexCoord")
    rgb = colour_rgb(colour)
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    if isinstance(colour, str) and colour in ("striped_blue", "check", "tartan"):
        if colour == "striped_blue":
            tex = nodes.new("ShaderNodeTexWave")
            tex.wave_type = "BANDS"
            tex.bands_direction = "X"
            tex.inputs["Scale"].default_value = 60.0
            step = nodes.new("ShaderNodeMath")
            step.operation = "GREATER_THAN"
            step.inputs[1].default_value = 0.7
            links.new(tex.outputs["Fac"], step.inputs[0])
            fac = step.outputs["Value"]
            c2 = (0.85, 0.85, 0.85)
        else:
            tex = nodes.new("ShaderNodeTexChecker")
            tex.inputs["Scale"].default_value = 40.0 if colour == "check" else 25.0
            fac = tex.outputs["Fac"]
            c2 = (0.8, 0.8, 0.78) if colour == "check" else (0.02, 0.08, 0.03)
        links.new(coord.outputs["Object"], tex.inputs["Vector"])
        mix = nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        mix.inputs["A"].default_value = (*rgb, 1.0)
        mix.inputs["B"].default_value = (*c2, 1.0)
        links.new(fac, mix.inputs["Factor"])
        links.new(mix.outputs["Result"], bsdf.inputs["Base Color"])
    bsdf.inputs["Roughness"].default_value = rough
    bsdf.inputs["Sheen Weight"].default_value = sheen
    bsdf.inputs["Sheen Roughness"].default_value = 0.5
    # wrinkles: stretched low-frequency noise
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (1.0, 1.0, 0.35)
    links.new(coord.outputs["Object"], mapping.inputs["Vector"])
    wr = nodes.new("ShaderNodeTexNoise")
    wr.noise_dimensions = "4D"
    wr.inputs["W"].default_value = float(seed)
    wr.inputs["Scale"].default_value = 18.0
    wr.inputs["Detail"].default_value = 2.0
    links.new(mapping.outputs["Vector"], wr.inputs["Vector"])
    bump1 = nodes.new("ShaderNodeBump")
    bump1.inputs["Strength"].default_value = 0.35
    bump1.inputs["Distance"].default_value = 0.002
    links.new(wr.outputs["Fac"], bump1.inputs["Height"])
    # fine structure per fabric
    scale = 1.0 / max(float(knit_scale), 1e-3)
    if kind == "knit":
        fine = nodes.new("ShaderNodeTexWave")
        fine.wave_type = "BANDS"
        fine.bands_direction = "X"
        fine.inputs["Scale"].default_value = scale * 0.5
        fine.inputs["Distortion"].default_value = 2.0
        strength, dist = 0.6, 0.001
    elif kind in ("twill", "tweed"):
        fine = nodes.new("ShaderNodeTexWave")
        fine.wave_type = "BANDS"
        fine.bands_direction = "DIAGONAL"
        fine.inputs["Scale"].default_value = 250.0
        strength, dist = 0.25 if kind == "twill" else 0.5, 0.0003
    else:
        fine = nodes.new("ShaderNodeTexNoise")
        fine.inputs["Scale"].default_value = {"fleece": 400.0, "felt": 600.0, "leather": 300.0}.get(kind, 800.0)
        strength, dist = {"fleece": 0.3, "felt": 0.2, "leather": 0.15}.get(kind, 0.1), 0.0003
    links.new(coord.outputs["Object"], fine.inputs["Vector"])
    bump2 = nodes.new("ShaderNodeBump")
    bump2.inputs["Strength"].default_value = strength
    bump2.inputs["Distance"].default_value = dist
    links.new(fine.outputs["Fac"], bump2.inputs["Height"])
    links.new(bump1.outputs["Normal"], bump2.inputs["Normal"])
    links.new(bump2.outputs["Normal"], bsdf.inputs["Normal"])
    mat["fabric"] = fabric
    return mat


class FittedRig(Rig):
    """A mesh bound to body triangles; ``update`` re-applies the binding and pushes out."""

    def __init__(self, ob, fitted: FittedShell):
        super().__init__(fitted.cls, [ob], fitted.info)
        self.fitted = fitted
        self.torso = None  # (rest vertices, hem rim indices) of the body below the bust and the forearms
        #: the bust's upper arms, which hair keeps off (synth.assets.fit.arms.ArmKeepOut), or None
        self.arm_keep_out = None

    def update(self, ctx: HeadContext) -> None:
        from blender_scripts.mesh import set_positions

        P = self.fitted.follow(ctx.vertices, ctx.data.triangles)
        set_positions(self.objects[0], P)
        if self.torso is not None:
            Vt, band = self.torso
            set_positions(self.objects[1], torso_fit.follow(Vt, self.fitted.P[band], P[band]))


def see_through_from_inside(mat):
    """The material, transparent on back faces: a camera inside a closed mesh (the torso under
    the bust, seen from far below with ``camera.elevation_deg`` under about -75 degrees) sees out
    of it, and fully transparent hits stay out of the data passes."""
    nt = mat.node_tree
    out = nt.nodes["Material Output"]
    link = out.inputs["Surface"].links[0]
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(nt.nodes.new("ShaderNodeNewGeometry").outputs["Backfacing"], mix.inputs["Fac"])
    nt.links.new(link.from_socket, mix.inputs[1])
    nt.links.new(nt.nodes.new("ShaderNodeBsdfTransparent").outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    return mat


def shell_rig(fitted: FittedShell, torso: bool = False, skin=None, body: Body | None = None) -> FittedRig:
    """The mesh object of a fitted shell, with one cloth material per slot; ``torso``: and the
    body below the bust in the first cloth (:func:`synth.assets.fit.torso.garment_torso_parts`), a
    second object that follows the garment's hem; with ``body`` (the bust's arms: the default
    model) the forearms join it, in the sleeves' cloth under long sleeves and in ``skin`` (the
    head's skin material; segmentation class skin, the object's second material slot) under short
    ones or none, and the rig keeps hair off the upper arms (:class:`synth.assets.fit.arms.ArmKeepOut`,
    ``clearance`` the cloth's reach plus ``HAIR_CLEARANCE``)."""
    from blender_scripts.mesh import link_object, new_triangle_mesh
    from synth.assets.fit import arms as arms_fit

    materials = [cloth_material(fitted.cls, c) for c in fitted.cloths]
    ob = link_object(fitted.name, new_triangle_mesh(fitted.name, fitted.P, fitted.F, fitted.M), materials)
    rig = FittedRig(ob, fitted)
    with_arms = body is not None and body.arms is not None
    bare = fitted.info.get("sleeves", "long") != "long"
    reach = float(fitted.info.get("cloth_reach_m", 0.0))
    if torso:
        offset = 0.0 if bare else max(reach - arms_fit.FOREARM_INSET, 0.0)
        parts = torso_fit.garment_torso_parts(fitted, (body.V, body.F, body.regions) if with_arms else None, offset)
        (Vp, Fp), (Va, Fa) = parts
        Vt, Ft = np.vstack([Vp, Va]), np.vstack([Fp, np.asarray(Fa, np.int64) + len(Vp)])
        name = f"{fitted.name}_torso"
        mats = [see_through_from_inside(cloth_material(fitted.cls, fitted.cloths[0]))]
        slots = None
        skin_arms = bare and skin is not None and len(Fa) > 0
        if skin_arms:
            mats.append(skin)
            slots = np.concatenate([np.zeros(len(Fp), np.int64), np.ones(len(Fa), np.int64)])
        rig.objects.append(link_object(name, new_triangle_mesh(name, Vt, Ft, slots), mats))
        rig.torso = (Vt, torso_fit.hem_band(fitted))
        rig.info["torso_vertices"] = int(len(Vt))
        if len(Fa):
            rig.info["torso_forearms"] = True
        if skin_arms:
            rig.info["torso_forearms_skin"] = True
    if with_arms:
        clearance = arms_fit.HAIR_CLEARANCE + (0.0 if fitted.info.get("sleeves") == "none" else reach)
        rig.arm_keep_out = arms_fit.ArmKeepOut(body.V, body.F, body.regions, clearance)
        rig.info["hair_arm_clearance_m"] = round(clearance, 6)
    return rig


def hide_bust_under_hem(head, body: Body) -> int:
    """Give the head polygons under the garment's hem (:func:`synth.assets.fit.hem.hidden_polygons`)
    a transparent material outside every pass (pass index 0: background in the segmentation;
    Cycles leaves fully transparent surfaces out of the depth and normal passes), so that the
    bust's cut is never seen. Returns how many polygons were hidden."""
    import bpy
    import numpy as np

    me = head.data
    n = len(me.polygons)
    start, total = np.empty(n, np.int32), np.empty(n, np.int32)
    me.polygons.foreach_get("loop_start", start)
    me.polygons.foreach_get("loop_total", total)
    corners = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", corners)
    hidden = hidden_polygons(body.V, body.F, np.append(start, start[-1] + total[-1]), corners)
    if hidden.any():
        mat = bpy.data.materials.new("bust_under_hem")
        mat.use_nodes = True
        mat.pass_index = 0
        nt = mat.node_tree
        nt.nodes.remove(nt.nodes["Principled BSDF"])
        nt.links.new(nt.nodes.new("ShaderNodeBsdfTransparent").outputs[0], nt.nodes["Material Output"].inputs[0])
        me.materials.append(mat)
        slots = np.empty(n, np.int32)
        me.polygons.foreach_get("material_index", slots)
        slots[hidden] = len(me.materials) - 1
        me.polygons.foreach_set("material_index", slots)
        me.update()
    return int(hidden.sum())


def build(ctx: HeadContext, entry: AssetPick) -> Rig:
    body = Body.of(ctx)
    skin = (ctx.materials or {}).get(SEGMENTATION["skin"])
    rig = shell_rig(fit_shell(body, garment_shell(body, entry, ctx.rng("garment")), CLEARANCE), torso=True,
                    skin=skin, body=body)
    rig.info["hidden_bust_polygons"] = hide_bust_under_hem(ctx.head, body)
    return rig
