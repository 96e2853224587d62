"""Eyebrows: the strands are groomed in numpy (:mod:`synth.assets.fit.eyebrows`); this rig makes
them a Blender Curves object (:class:`blender_scripts.assets.strands.StrandRig`) and paints the
band under them on the skin material (:func:`synth.assets.fit.eyebrows.band`): the brow's optical
density that the render's strands do not carry, drawn per shading point (:func:`band_nodes`) from
the per-vertex brow coordinates in the head mesh's ``brow_band`` attribute."""

from __future__ import annotations

from blender_scripts import materials as bmat
from blender_scripts.assets.strands import StrandRig
from synth.assets.fit import eyebrows as fe
from synth.assets.params import AssetPick
from synth.dataset.segmentation import CLASSES


def _smoothstep(mat, x, e0: float, e1: float):
    """Nodes of :func:`synth.model.meshutil.smoothstep`: 3t^2 - 2t^3, t = (x - e0) / (e1 - e0) clamped."""
    m = bmat.math_node
    t = m(mat, "MULTIPLY_ADD", x, 1.0 / (e1 - e0), clamp=True)
    t.node.inputs[2].default_value = -e0 / (e1 - e0)
    return m(mat, "MULTIPLY", m(mat, "MULTIPLY", t, t), m(mat, "SUBTRACT", 3.0, m(mat, "MULTIPLY", t, 2.0)))


def band_nodes(mat, depth: float, mono_share: float, seed: int = 0):
    """The band's coverage per shading point: :func:`synth.assets.fit.eyebrows.band_coverage` of
    the interpolated ``brow_band`` coordinates, as nodes (socket), its shape times a mean-one
    texture (:data:`synth.assets.fit.eyebrows.TEXTURE`; the Noise's W from ``seed``)."""
    m = bmat.math_node
    sep = mat.node_tree.nodes.new("ShaderNodeSeparateXYZ")
    mat.node_tree.links.new(bmat.attribute(mat, "brow_band").outputs["Vector"], sep.inputs[0])
    s, w, g = sep.outputs["X"], sep.outputs["Y"], sep.outputs["Z"]
    across = m(mat, "MULTIPLY", _smoothstep(mat, w, -fe.BAND_LOW[1], -fe.BAND_LOW[0]),
               _smoothstep(mat, w, fe.BAND_UP[1], fe.BAND_UP[0]))
    head = m(mat, "SUBTRACT", s, m(mat, "MULTIPLY", m(mat, "MULTIPLY", w, w), fe.BAND_ROUND))
    ends = m(mat, "MULTIPLY", _smoothstep(mat, head, -fe.BAND_END, fe.BAND_HEAD),
             _smoothstep(mat, s, 1.0 + fe.BAND_END, 1.0))
    tail = m(mat, "SUBTRACT", 1.0, m(mat, "MULTIPLY", m(mat, "MINIMUM", m(mat, "MAXIMUM", s, 0.0), 1.0), fe.BAND_TAIL))
    shape = m(mat, "MULTIPLY", m(mat, "MULTIPLY", across, ends), tail)
    nt = mat.node_tree
    uv = nt.nodes.new("ShaderNodeCombineXYZ")
    nt.links.new(m(mat, "MULTIPLY", s, fe.TEXTURE_SCALE[0]), uv.inputs["X"])
    nt.links.new(m(mat, "MULTIPLY", w, fe.TEXTURE_SCALE[1]), uv.inputs["Y"])
    noise = nt.nodes.new("ShaderNodeTexNoise")
    noise.noise_dimensions = "4D"
    noise.inputs["Scale"].default_value = 1.0
    noise.inputs["Detail"].default_value = 2.0
    noise.inputs["W"].default_value = float(seed % 1000)
    nt.links.new(uv.outputs[0], noise.inputs["Vector"])
    tex = m(mat, "MULTIPLY_ADD", noise.outputs["Fac"], 2.0 * fe.TEXTURE)
    tex.node.inputs[2].default_value = 1.0 - fe.TEXTURE
    shape = m(mat, "MULTIPLY", shape, tex)
    if mono_share > 0.0:
        glabella = _smoothstep(mat, g, fe.BAND_EDGE, fe.BAND_FULL)
        shape = m(mat, "MAXIMUM", shape, m(mat, "MULTIPLY", glabella, mono_share))
    return m(mat, "SUBTRACT", 1.0, m(mat, "EXPONENT", m(mat, "MULTIPLY", shape, -float(depth))))


def build(ctx, entry: AssetPick) -> StrandRig:
    g = fe.groom(ctx, entry)
    rig = StrandRig.build(ctx, g)
    b = fe.band(ctx, entry, g)
    mat = ctx.materials.get(CLASSES["skin"]) if ctx.materials else None
    if ctx.head is not None and mat is not None and b.depth > 0.0:
        bmat.write_point_vector(ctx.head.data, "brow_band", b.coords)
        bmat.layer_over(mat, "Base Color", b.colour, band_nodes(mat, b.depth, b.mono_share, g.styling.seed))
    rig.info["band"] = dict(b.record, drawn=bool(ctx.head is not None and mat is not None and b.depth > 0.0))
    return rig
