"""Eye-glasses rig: parametric frames posed by contact on the nose bridge and the ears.

Geometry and the pose solve live in :mod:`synth.assets.fit.glasses` (plain numpy,
tested without Blender); this module builds the Blender side: one mesh object for the frame
(rims, bridge, end pieces, hinges, pad arms, temples, temple tips, nose pads; one material
slot per finish) and one for the two lenses (glass tinted by ``lens_tint``, its reflection
set by the lens coating, see :func:`_lens_material`). Every material has
``pass_index = CLASSES['glasses']`` (10), lenses included.

Meshes are built in world coordinates (object transform = identity). ``update`` re-solves
on the current expression and swaps in fresh mesh data (expressions barely move the nose
and ears, so the fit changes little).
"""

from __future__ import annotations

import bpy
import numpy as np

from blender_scripts.assets import Rig
from synth.assets.params import AssetPick
from synth.assets.classes import CLASSES
from synth.assets.fit.glasses.front import build_front
from synth.assets.fit.glasses.solve import FRAME_PARTS, GlassesFit, fit_glasses
from synth.assets.fit.glasses.spec import (COLOURS, LENS_IOR, METALLIC_COLOURS, FrameSpec, frame_spec,
                                           reflectance_ior)

PASS = CLASSES["glasses"].segmentation_id
LENS_SHARP_DEG = 45.0  #: lens edges with a steeper dihedral angle (cap to wall: ~90) are shaded sharp
TINTS = {"aviator": (0.30, 0.26, 0.16), "default": (0.35, 0.33, 0.30)}  # tint colour at full strength
LENS_ROUGHNESS = 0.02
AR_RESIDUAL_RGB = (0.85, 1.05, 0.85)  #: residual reflection of an anti-reflective coating (luminance ~1)


def _principled(name: str):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.pass_index = PASS
    return mat, mat.node_tree.nodes["Principled BSDF"]


def _finish(name: str, colour: str, kind: str, seed: float = 0.0):
    """kind: acetate | metal | tip | pad."""
    mat, b = _principled(name)
    rgb = COLOURS.get(colour, COLOURS["black"])
    b.inputs["Base Color"].default_value = (*rgb, 1.0)
    if kind == "metal" or (kind == "tip" and colour in METALLIC_COLOURS):
        if kind == "tip":  # metal temples get acetate/silicone tips
            b.inputs["Base Color"].default_value = (0.03, 0.03, 0.03, 1.0)
            b.inputs["Roughness"].default_value = 0.35
        else:
            b.inputs["Metallic"].default_value = 1.0
            b.inputs["Roughness"].default_value = 0.18
    elif kind == "pad":
        b.inputs["Base Color"].default_value = (0.9, 0.9, 0.88, 1.0)
        b.inputs["Transmission Weight"].default_value = 0.6
        b.inputs["Roughness"].default_value = 0.3
    else:  # acetate: glossy plastic under a clear coat
        b.inputs["Roughness"].default_value = 0.3
        b.inputs["Coat Weight"].default_value = 0.6
        b.inputs["Coat Roughness"].default_value = 0.05
        if colour == "clear":
            b.inputs["Transmission Weight"].default_value = 0.85
            b.inputs["Roughness"].default_value = 0.1
        if colour == "tortoise":  # mottled amber / dark brown
            nt = mat.node_tree
            tex = nt.nodes.new("ShaderNodeTexNoise")
            tex.noise_dimensions = "4D"
            tex.inputs["W"].default_value = float(seed)
            tex.inputs["Scale"].default_value = 350.0
            tex.inputs["Detail"].default_value = 4.0
            ramp = nt.nodes.new("ShaderNodeValToRGB")
            ramp.color_ramp.elements[0].position = 0.45
            ramp.color_ramp.elements[0].color = (0.035, 0.012, 0.004, 1.0)
            ramp.color_ramp.elements[1].position = 0.6
            ramp.color_ramp.elements[1].color = (0.32, 0.12, 0.025, 1.0)
            nt.links.new(tex.outputs["Fac"], ramp.inputs["Fac"])
            nt.links.new(ramp.outputs["Color"], b.inputs["Base Color"])
    return mat


def _lens_material(spec: FrameSpec):
    """Clear lens: sharp refraction at LENS_IOR mixed with a mirror reflection by the Fresnel
    factor of the index whose normal-incidence reflectance is ``spec.lens_reflectance`` (4 %
    uncoated: the lens's own index; an anti-reflective coating leaves 0.3-1.2 %, with the
    greenish residual hue of multilayer coatings). The Principled BSDF cannot lower the
    reflection of a transmissive surface without changing its refraction."""
    mat, b = _principled("glasses_lens")
    nt = mat.node_tree
    nt.nodes.remove(b)
    tc = np.asarray(TINTS.get(spec.style, TINTS["default"]))
    col = 1.0 - float(np.clip(spec.tint, 0.0, 1.0)) * (1.0 - tc)
    refr = nt.nodes.new("ShaderNodeBsdfRefraction")
    refr.distribution = "GGX"
    refr.inputs["Color"].default_value = (*col, 1.0)
    refr.inputs["Roughness"].default_value = LENS_ROUGHNESS
    refr.inputs["IOR"].default_value = LENS_IOR
    mirror = nt.nodes.new("ShaderNodeBsdfGlossy")
    mirror.distribution = "GGX"
    mirror.inputs["Roughness"].default_value = LENS_ROUGHNESS
    coated = spec.coating == "anti_reflective"
    mirror.inputs["Color"].default_value = (*(AR_RESIDUAL_RGB if coated else (1.0, 1.0, 1.0)), 1.0)
    fresnel = nt.nodes.new("ShaderNodeFresnel")
    fresnel.inputs["IOR"].default_value = reflectance_ior(spec.lens_reflectance)
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(fresnel.outputs["Fac"], mix.inputs["Fac"])
    nt.links.new(refr.outputs["BSDF"], mix.inputs[1])
    nt.links.new(mirror.outputs["BSDF"], mix.inputs[2])
    nt.links.new(mix.outputs["Shader"], nt.nodes["Material Output"].inputs["Surface"])
    return mat


def mesh_from_arrays(name: str, parts: list[tuple[np.ndarray, np.ndarray, int]]):
    """Mesh from (V, F, material slot) triples (triangles), smooth shaded."""
    Vs, Fs, Ms, off = [], [], [], 0
    for V, F, slot in parts:
        Vs.append(np.asarray(V, np.float64))
        Fs.append(np.asarray(F, np.int64) + off)
        Ms.append(np.full(len(F), slot, np.int32))
        off += len(V)
    from blender_scripts.mesh import new_triangle_mesh

    return new_triangle_mesh(name, np.concatenate(Vs), np.concatenate(Fs), np.concatenate(Ms))


def lens_mesh(V: np.ndarray, F: np.ndarray):
    """The lenses' mesh (closed solids wound outward, see ``synth.assets.fit.glasses.front``):
    smooth shaded, with the normals split where the caps meet the edge wall (~90 degrees on
    shared vertices), so the caps refract as smooth glass up to the rim (averaged normals would
    tilt the outer ring of cap triangles by up to ~45 degrees)."""
    me = mesh_from_arrays("glasses_lenses", [(V, F, 0)])
    me.set_sharp_from_angle(angle=np.radians(LENS_SHARP_DEG))
    return me


class GlassesRig(Rig):
    def __init__(self, spec: FrameSpec, frame_ob, lens_ob, materials: dict, info: dict):
        super().__init__("glasses", [frame_ob, lens_ob], info)
        self.spec = spec
        self.front = build_front(spec)
        self.materials = materials

    def _fit(self, ctx) -> GlassesFit:
        return fit_glasses(ctx.vertices, ctx.data.triangles, ctx.data.regions, ctx.landmarks, self.spec,
                              front=self.front)

    def _apply(self, fit: GlassesFit) -> None:
        frame_ob, lens_ob = self.objects
        slots = [(fit.parts[k][0], fit.parts[k][1], i) for i, k in enumerate(FRAME_PARTS)
                 if k in fit.parts and len(fit.parts[k][0])]
        for ob, me in ((frame_ob, mesh_from_arrays("glasses_frame", slots)), (lens_ob, lens_mesh(*fit.parts["lens"]))):
            old = ob.data
            for m in old.materials:
                me.materials.append(m)
            ob.data = me
            bpy.data.meshes.remove(old)
        self.info.update(fit.info)

    def update(self, ctx) -> None:
        self._apply(self._fit(ctx))


def build(ctx, entry: AssetPick) -> GlassesRig:
    style = entry.id
    rng = ctx.rng("glasses")
    spec = frame_spec(style, entry.params, rng)
    seed = float(rng.uniform(0, 100))
    metal_col = spec.temple_colour if spec.temple_colour in METALLIC_COLOURS else (
        spec.colour if spec.colour in METALLIC_COLOURS else "silver")
    frame_kind = "metal" if spec.material == "metal" else "acetate"
    mats = {
        "frame": _finish("glasses_frame", spec.colour, frame_kind, seed),
        "metal": _finish("glasses_metal", metal_col, "metal"),
        "temple": _finish("glasses_temple", spec.temple_colour,
                          "metal" if spec.material == "metal" else "acetate", seed + 1),
        "tip": _finish("glasses_tip", spec.temple_colour, "tip" if spec.material == "metal" else "acetate", seed + 2),
        "pad": _finish("glasses_pad", "clear", "pad"),
        "lens": _lens_material(spec),
    }
    frame_me = bpy.data.meshes.new("glasses_frame")
    lens_me = bpy.data.meshes.new("glasses_lenses")
    for k in FRAME_PARTS:
        frame_me.materials.append(mats[k])
    lens_me.materials.append(mats["lens"])
    frame_ob = bpy.data.objects.new("glasses_frame", frame_me)
    lens_ob = bpy.data.objects.new("glasses_lenses", lens_me)
    for ob in (frame_ob, lens_ob):
        bpy.context.scene.collection.objects.link(ob)
        ob.pass_index = PASS
    rig = GlassesRig(spec, frame_ob, lens_ob, mats, {"id": style})
    rig.update(ctx)
    return rig
