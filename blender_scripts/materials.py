"""Materials for the head: physically based skin with subsurface scattering, eyes, teeth, mouth.

Every material's ``pass_index`` is its segmentation class ID (rendered through the
material-index pass), so labels come straight from the renderer.
"""

from __future__ import annotations

import bpy

from synth.appearance.teeth import TOOTH_ALBEDO
from synth.assets.params import SkinParams
from synth.dataset.segmentation import CLASSES


def _principled(name: str, cls: str):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.pass_index = CLASSES[cls]
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    return mat, bsdf


def _noise(nodes, links, coord, scale: float, w: float, detail: float = 1.0):
    n = nodes.new("ShaderNodeTexNoise")
    n.noise_dimensions = "4D"
    n.inputs["W"].default_value = w
    n.inputs["Scale"].default_value = scale
    n.inputs["Detail"].default_value = detail
    links.new(coord.outputs["Object"], n.inputs["Vector"])
    return n


def _ridge(nodes, links, fac):
    """|fac - 0.5|: 0 along the lines where a noise crosses its middle."""
    sub = nodes.new("ShaderNodeMath")
    sub.operation = "SUBTRACT"
    sub.inputs[1].default_value = 0.5
    links.new(fac, sub.inputs[0])
    ab = nodes.new("ShaderNodeMath")
    ab.operation = "ABSOLUTE"
    links.new(sub.outputs[0], ab.inputs[0])
    return ab.outputs[0]


def skin_material(albedo, params: SkinParams | None = None, pixel_m: float | None = None, lip_albedo=None):
    """Principled skin (``synth.appearance.skin_optics`` for the physics and the rules):
    random-walk subsurface with per-channel radii (red furthest), the broad specular lobe with
    the sampled roughness (varied with a low-frequency noise) and a sharp coat lobe, albedo
    modulated by low-frequency redness, and two fine bump layers, pores and the micro-relief's
    fine lines, each built only as far as the finest view of the identity resolves it
    (``pixel_m``: metres per pixel on the face; None = every layer at full strength); what is not
    resolved widens the broad lobe instead. All variation is procedural (noise seeded by the
    plan's ``noise_seed``), so it follows any identity and expression. ``lip_albedo`` (linear
    sRGB, :func:`synth.appearance.lips.lip_albedo`): the lips' own colour and a smoother surface
    over the ``vermilion`` point attribute (``blender_scripts.head``); None: none."""
    from synth.appearance import lips as lp
    from synth.appearance import skin_optics as so

    p = params if params is not None else SkinParams()
    roughness = float(p.roughness)
    seed = float(p.noise_seed)
    mat, bsdf = _principled("skin", "skin")
    nt = mat.node_tree
    nodes, links = nt.nodes, nt.links
    coord = nodes.new("ShaderNodeTexCoord")
    # low-frequency blotchiness / redness
    blotch = _noise(nodes, links, coord, 12.0, seed, 3.0)
    base = nodes.new("ShaderNodeRGB")
    base.outputs[0].default_value = (*albedo, 1.0)
    red = nodes.new("ShaderNodeRGB")
    red.outputs[0].default_value = (min(1.0, albedo[0] * 1.1), albedo[1] * 0.7, albedo[2] * 0.75, 1.0)
    mix = nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    ramp = nodes.new("ShaderNodeMath")
    ramp.operation = "MULTIPLY"
    ramp.inputs[1].default_value = float(p.redness)
    links.new(blotch.outputs["Fac"], ramp.inputs[0])
    links.new(ramp.outputs[0], mix.inputs["Factor"])
    links.new(base.outputs[0], mix.inputs["A"])
    links.new(red.outputs[0], mix.inputs["B"])
    links.new(mix.outputs["Result"], bsdf.inputs["Base Color"])
    # fine bump layers, as far as the resolution shows them
    layers = {"pores": (so.PORES, float(p.pore_scale), float(p.pore_strength), 0.0003),
              "fine_lines": (so.FINE_LINES, 1.0, 0.1 + 0.25 * float(p.wrinkle_depth), 0.0002)}
    unresolved, normal = [], None
    for name, ((period, var), scale, strength, dist) in layers.items():
        w = 1.0 if pixel_m is None else so.detail_weight(pixel_m, period * scale)
        unresolved.append((w, var))
        mat[f"detail_{name}"] = w
        if w <= 0.0:
            continue
        if name == "pores":
            tex = _noise(nodes, links, coord, 1.0 / (period * scale), seed + 17.0)
            height = tex.outputs["Fac"]
        else:  # grooves: where a smooth noise crosses its middle (|noise - 0.5|: a furrow network);
            # 3D noise offset by the seed costs about as much as the 4D pore noise, a Voronoi
            # edge network (the look-alike) 3 times more
            shift = nodes.new("ShaderNodeMapping")
            shift.inputs["Location"].default_value = (0.37 * seed, 0.11 * seed, 0.23 * seed)
            links.new(coord.outputs["Object"], shift.inputs["Vector"])
            tex = nodes.new("ShaderNodeTexNoise")
            tex.inputs["Scale"].default_value = 1.0 / period
            tex.inputs["Detail"].default_value = 0.0
            links.new(shift.outputs["Vector"], tex.inputs["Vector"])
            height = _ridge(nodes, links, tex.outputs["Fac"])
        bump = nodes.new("ShaderNodeBump")
        bump.inputs["Strength"].default_value = strength * w
        bump.inputs["Distance"].default_value = dist
        links.new(height, bump.inputs["Height"])
        if normal is not None:
            links.new(normal, bump.inputs["Normal"])
        normal = bump.outputs["Normal"]
    if normal is not None:
        links.new(normal, bsdf.inputs["Normal"])
    # broad lobe: roughness varies slightly with the blotch noise (oilier T-zone look), widened by
    # the unresolved detail; sharp lobe: the coat
    broad = so.subpixel_roughness(roughness, unresolved)
    rough = nodes.new("ShaderNodeMapRange")
    rough.inputs["To Min"].default_value = max(0.05, broad - 0.1)
    rough.inputs["To Max"].default_value = min(1.0, broad + 0.1)
    links.new(blotch.outputs["Fac"], rough.inputs["Value"])
    links.new(rough.outputs["Result"], bsdf.inputs["Roughness"])
    for k, v in so.sharp_lobe(roughness, float(p.oiliness)).items():
        bsdf.inputs[k].default_value = v
    radius, scale = so.subsurface(float(p.subsurface_radius_scale))
    bsdf.subsurface_method = "RANDOM_WALK"
    bsdf.inputs["Subsurface Weight"].default_value = 1.0
    bsdf.inputs["Subsurface Radius"].default_value = radius
    bsdf.inputs["Subsurface Scale"].default_value = scale
    bsdf.inputs["IOR"].default_value = 1.4
    if lip_albedo is not None:  # the vermilion: its edge sharpened about the border loop's value
        edge = nodes.new("ShaderNodeMapRange")
        edge.interpolation_type = "SMOOTHSTEP"
        edge.clamp = True
        edge.inputs["From Min"].default_value = lp.BORDER_VALUE - 0.5 * lp.EDGE_WIDTH
        edge.inputs["From Max"].default_value = lp.BORDER_VALUE + 0.5 * lp.EDGE_WIDTH
        links.new(attribute(mat, "vermilion").outputs["Fac"], edge.inputs["Value"])
        layer_over(mat, "Base Color", tuple(float(c) for c in lip_albedo), edge.outputs["Result"])
        layer_over(mat, "Roughness", max(0.05, broad - lp.LIP_ROUGHNESS_DROP), edge.outputs["Result"])
    return mat


#: the plain Principled materials of the head (name, class, inputs): a sclera-white eye under a
#: glossy cornea-like coat (the iris rig paints the iris), teeth (measured enamel colour,
#: synth.appearance.teeth) and the mouth cavity
PLAIN_MATERIALS = (
    ("eye", "eyes", {"Base Color": (0.8, 0.78, 0.75, 1.0), "Roughness": 0.25, "Coat Weight": 1.0,
                     "Coat Roughness": 0.02, "Coat IOR": 1.376}),
    ("teeth", "teeth", {"Base Color": (*TOOTH_ALBEDO, 1.0), "Roughness": 0.3, "Subsurface Weight": 0.3,
                        "Subsurface Scale": 0.002}),
    ("mouth_interior", "mouth_interior", {"Base Color": (0.35, 0.06, 0.07, 1.0), "Roughness": 0.35,
                                          "Subsurface Weight": 0.5, "Subsurface Scale": 0.003}),
)


def plain_material(name: str, cls: str, inputs: dict):
    mat, bsdf = _principled(name, cls)
    for k, v in inputs.items():
        bsdf.inputs[k].default_value = v
    if name == "teeth":
        tooth_gaps(mat)
    return mat


def tooth_gaps(mat) -> None:
    """Separate teeth on the coarse arch of each jaw: from the ``tooth_arch`` point attribute
    (:func:`synth.appearance.teeth.arch_attribute`; gaps at the integers) a dark gap between
    neighbouring teeth, each tooth's brightness varied a little, and its surface rounded off
    toward the gaps (a bump)."""
    from synth.appearance import teeth as tt

    nt = mat.node_tree

    def ramp(x, lo, hi, out_lo, out_hi):
        n = nt.nodes.new("ShaderNodeMapRange")
        n.interpolation_type = "SMOOTHSTEP"
        n.clamp = True
        nt.links.new(x, n.inputs["Value"])
        n.inputs["From Min"].default_value, n.inputs["From Max"].default_value = lo, hi
        n.inputs["To Min"].default_value, n.inputs["To Max"].default_value = out_lo, out_hi
        return n.outputs["Result"]

    u = math_node(mat, "SUBTRACT", attribute(mat, "tooth_arch").outputs["Fac"], tt.ARCH_OFFSET)
    f = math_node(mat, "ABSOLUTE", math_node(mat, "SUBTRACT", u, math_node(mat, "ROUND", u)))  # to the nearest gap
    shade = ramp(f, tt.GAP_HALF, tt.GAP_HALF + tt.GAP_SOFT, 1.0 - tt.GAP_DARK, 1.0)
    noise = nt.nodes.new("ShaderNodeTexWhiteNoise")
    noise.noise_dimensions = "1D"
    nt.links.new(math_node(mat, "FLOOR", u), noise.inputs["W"])
    vary = math_node(mat, "ADD", math_node(mat, "MULTIPLY", noise.outputs["Value"], tt.TOOTH_VARIATION),
                     1.0 - 0.5 * tt.TOOTH_VARIATION)
    grey = nt.nodes.new("ShaderNodeCombineColor")
    scale = math_node(mat, "MULTIPLY", shade, vary)
    for k in range(3):
        nt.links.new(scale, grey.inputs[k])
    layer_over(mat, "Base Color", grey.outputs[0], 1.0, blend="MULTIPLY")
    chain_bump(mat, ramp(f, 0.0, tt.ROUNDING, 0.0, 1.0), 0.5, 0.0004)


def head_materials(skin_params: SkinParams | None, albedo, pixel_m: float | None = None,
                   lip_albedo=None) -> dict[int, "bpy.types.Material"]:
    """Material per segmentation class for the head mesh (``pixel_m``, ``lip_albedo``: see
    :func:`skin_material`)."""
    return {
        CLASSES["skin"]: skin_material(albedo, skin_params, pixel_m, lip_albedo),
        **{CLASSES[cls]: plain_material(name, cls, inputs) for name, cls, inputs in PLAIN_MATERIALS},
    }


# --------------------------------------------------------------------------------------
# layering helpers for shader-layer assets (makeup, iris, skin detail): they insert nodes
# between what currently feeds a Principled input and the input itself, so layers stack in
# build order whatever was there before.


def principled(mat) -> "bpy.types.Node":
    for n in mat.node_tree.nodes:
        if n.type == "BSDF_PRINCIPLED":
            return n
    raise KeyError(f"material {mat.name!r} has no Principled BSDF")


def input_source(mat, input_name: str):
    """The socket feeding a Principled input; an RGB/Value node holding its default if unlinked."""
    nt = mat.node_tree
    sock = principled(mat).inputs[input_name]
    if sock.is_linked:
        return sock.links[0].from_socket
    if sock.type == "RGBA":
        n = nt.nodes.new("ShaderNodeRGB")
        n.outputs[0].default_value = tuple(sock.default_value)
    else:
        n = nt.nodes.new("ShaderNodeValue")
        n.outputs[0].default_value = float(sock.default_value)
    return n.outputs[0]


def attribute(mat, name: str):
    """Attribute node reading a mesh attribute (per-vertex masks written by the rigs)."""
    n = mat.node_tree.nodes.new("ShaderNodeAttribute")
    n.attribute_type = "GEOMETRY"
    n.attribute_name = name
    return n


def layer_over(mat, input_name: str, value, factor, blend: str = "MIX"):
    """Mix ``value`` (socket or constant) over what feeds ``input_name`` by ``factor``
    (socket or constant). Colour inputs use an RGBA mix with ``blend``; others a float mix."""
    nt = mat.node_tree
    bsdf = principled(mat)
    sock = bsdf.inputs[input_name]
    src = input_source(mat, input_name)
    mix = nt.nodes.new("ShaderNodeMix")
    rgba = sock.type == "RGBA"
    mix.data_type = "RGBA" if rgba else "FLOAT"
    if rgba:
        mix.blend_type = blend
        a, b, out = mix.inputs[6], mix.inputs[7], mix.outputs[2]
    else:
        a, b, out = mix.inputs[2], mix.inputs[3], mix.outputs[0]
    nt.links.new(src, a)
    if hasattr(value, "node"):
        nt.links.new(value, b)
    else:
        b.default_value = (*value, 1.0) if rgba and len(value) == 3 else value
    if hasattr(factor, "node"):
        nt.links.new(factor, mix.inputs[0])
    else:
        mix.inputs[0].default_value = float(factor)
    nt.links.new(out, sock)
    return mix


def chain_bump(mat, height, strength: float, distance: float):
    """Add a bump layer on top of whatever feeds the Principled normal."""
    nt = mat.node_tree
    bsdf = principled(mat)
    bump = nt.nodes.new("ShaderNodeBump")
    bump.inputs["Strength"].default_value = float(strength)
    bump.inputs["Distance"].default_value = float(distance)
    nt.links.new(height, bump.inputs["Height"])
    sock = bsdf.inputs["Normal"]
    if sock.is_linked:
        nt.links.new(sock.links[0].from_socket, bump.inputs["Normal"])
    nt.links.new(bump.outputs["Normal"], sock)
    return bump


def math_node(mat, op: str, a, b=None, clamp: bool = False):
    nt = mat.node_tree
    n = nt.nodes.new("ShaderNodeMath")
    n.operation = op
    n.use_clamp = clamp
    for i, v in enumerate((a, b)):
        if v is None:
            continue
        if hasattr(v, "node"):
            nt.links.new(v, n.inputs[i])
        else:
            n.inputs[i].default_value = float(v)
    return n.outputs[0]


def write_point_colour(mesh, name: str, rgba) -> None:
    """(V, 4) float colour attribute on the points of ``mesh`` (replaced if it exists)."""
    import numpy as np

    if name in mesh.attributes:
        mesh.attributes.remove(mesh.attributes[name])
    attr = mesh.attributes.new(name, "FLOAT_COLOR", "POINT")
    attr.data.foreach_set("color", np.ascontiguousarray(rgba, np.float32).ravel())


def write_point_vector(mesh, name: str, vec) -> None:
    import numpy as np

    if name in mesh.attributes:
        mesh.attributes.remove(mesh.attributes[name])
    attr = mesh.attributes.new(name, "FLOAT_VECTOR", "POINT")
    attr.data.foreach_set("vector", np.ascontiguousarray(vec, np.float32).ravel())
