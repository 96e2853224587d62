"""The Blender side of the strand rigs (hair, beard, eyebrows, eyelashes): Curves objects.

The strands themselves are numpy (:mod:`synth.assets.fit.strands`, the groom modules
``synth.assets.fit.hair`` ... and :mod:`synth.assets.fit.groom`); a rig module calls
``StrandRig.build(ctx, groom(ctx, entry))``. This module makes the Principled Hair material,
the Curves object (with the ``synth_root_tri`` / ``synth_root_bary`` curve attributes of the
attachment; its ``surface`` is set to the head with ``surface_uv_coordinate`` filled, for
sculpting tools) and the styling stack, and writes new positions on ``update``.

Styling in Geometry Nodes: a modifier stack built from Blender's bundled procedural-hair node
groups (``Frizz Hair Curves``, ``Clump Hair Curves``, ``Set Hair Curve Profile``), appended
from ``procedural_hair_node_assets.blend``; they leave the root points where they are.
"""

from __future__ import annotations

import os

import bpy
import numpy as np

from blender_scripts.assets import Rig
from synth.appearance import pigment as pig
from synth.assets.classes import CLASSES
from synth.assets.fit.groom import Attachment, Groom, Styling, attach
from synth.assets.fit.strands import Surface


def _hair_assets_path() -> str:
    base = bpy.utils.system_resource("DATAFILES")
    p = os.path.join(base, "assets", "geometry_nodes", "procedural_hair_node_assets.blend")
    if not os.path.exists(p):
        raise FileNotFoundError(f"Blender's procedural hair node assets not found at {p}")
    return p


def hair_node_group(name: str):
    """A node group from Blender's bundled procedural-hair assets (appended once per scene)."""
    ng = bpy.data.node_groups.get(name)
    if ng is not None and ng.library is None:
        return ng
    with bpy.data.libraries.load(_hair_assets_path(), link=False) as (src, dst):
        if name not in src.node_groups:
            raise KeyError(f"node group {name!r} not in the bundled hair assets")
        dst.node_groups = [name]
    return dst.node_groups[0]


def _set_inputs(mod, ng, values: dict) -> None:
    ids = {it.name: it.identifier for it in ng.interface.items_tree
           if it.item_type == "SOCKET" and it.in_out == "INPUT"}
    for k, v in values.items():
        mod[ids[k]] = v


def add_node_modifier(ob, group_name: str, values: dict):
    ng = hair_node_group(group_name)
    mod = ob.modifiers.new(group_name, "NODES")
    mod.node_group = ng
    _set_inputs(mod, ng, values)
    return mod


def hair_material(name: str, cls: str, pg: "pig.HairPigment", roughness: float = 0.3,
                  random_color: float = 0.12, coat: float = 0.0, tip_lightening: float = 0.0,
                  redness_jitter: float = 0.0):
    """Principled Hair BSDF (Chiang model, melanin parametrisation) with the pigment; grey and
    white hair mix in unpigmented fibres per strand (Hair Info > Random < white_fraction).

    Per strand, the BSDF's Random Color varies the melanin by +-``random_color`` and Random
    Roughness the roughness by +-10 % (both from Hair Info > Random). ``redness_jitter`` adds
    +-that much to the Melanin Redness per strand (the pheomelanin share; a white noise of
    Hair Info > Random, so not tied to the melanin's draw), clamped to [0, 1]. ``tip_lightening``
    takes that fraction of the melanin concentration away along the strand, linearly from none
    at the root to all of it at the tip (Hair Info > Intercept; weathered, sun-bleached ends):
    Melanin = 1 - exp(-c (1 - tip_lightening x intercept)), c = eumelanin + pheomelanin."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.pass_index = CLASSES[cls].segmentation_id
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    info = None

    def hair_info():
        nonlocal info
        if info is None:
            info = nt.nodes.new("ShaderNodeHairInfo")
        return info

    def math(op, *inputs, clamp=False):
        node = nt.nodes.new("ShaderNodeMath")
        node.operation = op
        node.use_clamp = clamp
        for i, v in enumerate(inputs):
            if isinstance(v, (int, float)):
                node.inputs[i].default_value = float(v)
            else:
                nt.links.new(v, node.inputs[i])
        return node.outputs[0]

    def bsdf(eu, ph, varied=False):
        b = nt.nodes.new("ShaderNodeBsdfHairPrincipled")
        b.model = "CHIANG"
        b.parametrization = "MELANIN"
        m, r = pig.to_blender(eu, ph)
        b.inputs["Melanin"].default_value = float(m)
        b.inputs["Melanin Redness"].default_value = float(r)
        b.inputs["Tint"].default_value = (1.0, 1.0, 1.0, 1.0)
        b.inputs["Roughness"].default_value = float(roughness)
        b.inputs["Radial Roughness"].default_value = 0.3
        b.inputs["Coat"].default_value = float(coat)
        b.inputs["IOR"].default_value = 1.55
        b.inputs["Random Color"].default_value = float(random_color)
        b.inputs["Random Roughness"].default_value = 0.1
        if varied and tip_lightening > 0.0:
            c = float(eu + ph)
            x = math("MULTIPLY_ADD", hair_info().outputs["Intercept"], float(tip_lightening) * c, -c)
            nt.links.new(math("SUBTRACT", 1.0, math("EXPONENT", x)), b.inputs["Melanin"])
        if varied and redness_jitter > 0.0:
            noise = nt.nodes.new("ShaderNodeTexWhiteNoise")
            noise.noise_dimensions = "1D"
            nt.links.new(hair_info().outputs["Random"], noise.inputs["W"])
            j = float(redness_jitter)
            nt.links.new(math("MULTIPLY_ADD", noise.outputs["Value"], 2.0 * j, float(r) - j, clamp=True),
                         b.inputs["Melanin Redness"])
        return b

    main = bsdf(pg.eumelanin, pg.pheomelanin, varied=True)
    if pg.white_fraction > 0.0:
        white = bsdf(*pig.WHITE_FIBRE)
        lt = nt.nodes.new("ShaderNodeMath")
        lt.operation = "LESS_THAN"
        lt.inputs[1].default_value = float(pg.white_fraction)
        nt.links.new(hair_info().outputs["Random"], lt.inputs[0])
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(lt.outputs[0], mix.inputs["Fac"])
        nt.links.new(main.outputs[0], mix.inputs[1])
        nt.links.new(white.outputs[0], mix.inputs[2])
        nt.links.new(mix.outputs[0], out.inputs["Surface"])
    else:
        nt.links.new(main.outputs[0], out.inputs["Surface"])
    mat["pigment"] = {k: v for k, v in pg.as_dict().items() if k != "approx_rgb"}
    mat["shader"] = {"random_color": float(random_color), "random_roughness": 0.1,
                     "redness_jitter": float(redness_jitter), "tip_lightening": float(tip_lightening)}
    return mat


def make_curves_object(name: str, pts: np.ndarray, head_ob, material, surface: Surface, tri, bary):
    """Hair Curves object from (N, P, 3) strands, attached (metadata) to the head."""
    N, P, _ = pts.shape
    cv = bpy.data.hair_curves.new(name)
    cv.add_curves([P] * N)
    cv.position_data.foreach_set("vector", np.ascontiguousarray(pts, np.float32).ravel())
    cv.materials.append(material)
    cv.surface = head_ob
    if head_ob is not None and head_ob.data.uv_layers.get("UVMap") is not None:
        cv.surface_uv_map = "UVMap"
    a = cv.attributes.new("synth_root_tri", "INT", "CURVE")
    a.data.foreach_set("value", tri.astype(np.int32))
    a = cv.attributes.new("synth_root_bary", "FLOAT_VECTOR", "CURVE")
    a.data.foreach_set("vector", np.ascontiguousarray(bary, np.float32).ravel())
    d = surface.data
    if d.uvs is not None and d.tri_uv is not None:
        uv = np.einsum("nk,nkd->nd", bary, np.asarray(d.uvs, np.float64)[np.asarray(d.tri_uv)[tri]])
        a = cv.attributes.get("surface_uv_coordinate") or cv.attributes.new("surface_uv_coordinate", "FLOAT2",
                                                                            "CURVE")
        a.data.foreach_set("vector", np.ascontiguousarray(uv, np.float32).ravel())
    ob = bpy.data.objects.new(name, cv)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def set_curves_positions(ob, pts: np.ndarray) -> None:
    """Move the points of a Curves object (same topology) and drop its derived caches.

    ``position_data.foreach_set`` alone leaves the curves' cached derived data (evaluated
    lengths, which Geometry Nodes' Spline Parameter and so "Set Hair Curve Profile"'s radius
    use) as computed for the old positions: the evaluated copy made for a render shares those
    caches with the original. Resizing every curve to its own size marks the topology changed,
    which clears them, so the next evaluation depends on the new positions only."""
    cv = ob.data
    cv.position_data.foreach_set("vector", np.ascontiguousarray(pts, np.float32).ravel())
    offsets = np.empty(len(cv.curves) + 1, np.int32)
    cv.curve_offset_data.foreach_get("value", offsets)
    cv.resize_curves(np.diff(offsets).tolist())
    cv.update_tag()
    ob.update_tag()


def apply_styling(ob, st: Styling) -> list[str]:
    applied = []
    if st.clump > 0.0:
        add_node_modifier(ob, "Clump Hair Curves", {"Existing Guide Map": False, "Guide Distance": float(st.clump_distance),
                                                     "Factor": float(st.clump), "Shape": float(st.clump_shape),
                                                     "Seed": int(st.seed % 100000), "Preserve Length": True})
        applied.append("Clump Hair Curves")
    if st.frizz > 0.0:
        add_node_modifier(ob, "Frizz Hair Curves", {"Factor": 1.0, "Distance": float(st.frizz), "Shape": float(st.frizz_shape),
                                                     "Seed": int((st.seed // 7) % 100000), "Preserve Length": False})
        applied.append("Frizz Hair Curves")
    add_node_modifier(ob, "Set Hair Curve Profile", {"Replace Radius": True, "Radius": float(st.root_radius),
                                                      "Shape": float(st.tip_shape), "Factor Min": 0.0, "Factor Max": 1.0})
    applied.append("Set Hair Curve Profile")
    return applied


class StrandRig(Rig):
    """A Curves object whose strands follow the head through their :class:`Attachment`."""

    def __init__(self, cls, ob, attachment: Attachment, info):
        super().__init__(cls, [ob], info)
        self.ob = ob
        self.attachment = attachment
        self.keep = None  # what the strands keep off (keep_out_of): the sleeves over the upper arms

    @classmethod
    def build(cls_, ctx, g: Groom) -> "StrandRig":
        mat = hair_material(g.name, g.cls, g.pigment, roughness=g.roughness, coat=g.coat,
                            tip_lightening=g.tip_lightening, redness_jitter=g.redness_jitter)
        _, attachment = attach(g)
        # the strands where their attachment puts them on this head, as every update does: an
        # expression change moves them only as the head moves (the groomed points, taken as they
        # are, sit up to millimetres off what the attachment's push-out gives)
        pts = attachment.positions(ctx)
        ob = make_curves_object(g.name, pts, ctx.head, mat, g.surface, g.tri, g.bary)
        mods = apply_styling(ob, g.styling)
        info = dict(g.info)
        info.update({"strands": int(pts.shape[0]), "points_per_strand": int(pts.shape[1]),
                     "attachment": "root_triangle_barycentric", "geometry_nodes": mods,
                     "root_radius_m": float(g.styling.root_radius), "shader": mat["shader"].to_dict()})
        return cls_(g.cls, ob, attachment, info)

    def keep_out_of(self, keep, ctx) -> None:
        """From now on keep the strands off ``keep`` (:class:`synth.assets.fit.arms.ArmKeepOut`, the
        upper arms under the garment's sleeves, built after the hair); moves the strands now."""
        self.keep = keep
        pts, moved = self._positions(ctx)
        set_curves_positions(self.ob, pts)
        self.info["points_out_of_arms"] = moved

    def _positions(self, ctx):
        pts = self.attachment.positions(ctx)
        if self.keep is None:
            return pts, 0
        self.keep.follow(ctx.vertices)
        return self.keep.push(pts)

    def update(self, ctx) -> None:
        set_curves_positions(self.ob, self._positions(ctx)[0])
