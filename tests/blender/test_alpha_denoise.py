"""With denoising on, the render's alpha is denoised too (blender_scripts/scene.py
``_alpha_denoiser``, synth.dataset.alpha): at 16 samples a sub-pixel coverage pattern's alpha
is measured against a 1,024-sample render of the same scene."""

from __future__ import annotations

import numpy as np
import pytest

from synth.plan.records import RenderSettings
from tests.support import asset_scene

N = 48


def _render(tmp_path, samples: int, denoise: bool) -> dict:
    import bpy

    from blender_scripts import passes, scene

    scene.reset()
    eff = scene.configure_render(RenderSettings(samples=samples, denoise=denoise, device="cpu", max_bounces=2), N, N)
    scene.uniform_environment(1.0)
    bpy.ops.mesh.primitive_plane_add(size=1.0)
    plane = bpy.context.active_object
    mat, bsdf = asset_scene.single_shader_material("fringe", "ShaderNodeBsdfPrincipled",
                                                   {"Base Color": (0.05, 0.03, 0.02, 1.0)})
    # strands of coverage: a fine noise thresholded into opaque and clear, its density rising
    # from left to right (a hair fringe over the background, sub-pixel)
    nt = mat.node_tree
    coord = nt.nodes.new("ShaderNodeTexCoord")
    noise = nt.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 300.0
    nt.links.new(coord.outputs["Object"], noise.inputs["Vector"])
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(coord.outputs["Object"], sep.inputs["Vector"])
    ramp = nt.nodes.new("ShaderNodeMath")
    ramp.operation = "MULTIPLY_ADD"  # threshold 0.35 .. 0.65 across the plane
    ramp.inputs[1].default_value = 0.3
    ramp.inputs[2].default_value = 0.5
    nt.links.new(sep.outputs["X"], ramp.inputs[0])
    cut = nt.nodes.new("ShaderNodeMath")
    cut.operation = "LESS_THAN"
    nt.links.new(noise.outputs["Fac"], cut.inputs[0])
    nt.links.new(ramp.outputs[0], cut.inputs[1])
    nt.links.new(cut.outputs[0], bsdf.inputs["Alpha"])
    plane.data.materials.append(mat)
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 0.8
    cam.location = (0.0, 0.0, 1.0)
    r = passes.render_view(tmp_path, 5)
    r["effective"] = eff
    return r


@pytest.mark.blender
def test_denoised_render_denoises_its_alpha(tmp_path):
    pytest.importorskip("bpy")
    ref_r = _render(tmp_path, 1024, False)
    ref = ref_r["rgba"][..., 3]
    raw = _render(tmp_path, 16, False)
    dn = _render(tmp_path, 16, True)
    assert dn["effective"]["alpha_denoised"] and not raw["effective"]["alpha_denoised"]
    a_raw, a_dn = raw["rgba"][..., 3], dn["rgba"][..., 3]
    fringe = (ref > 0.02) & (ref < 0.98)
    assert fringe.mean() > 0.5  # the pattern is a fringe almost everywhere
    err_raw = np.abs(a_raw - ref)[fringe].mean()
    err_dn = np.abs(a_dn - ref)[fringe].mean()
    assert err_dn < 0.6 * err_raw, (err_dn, err_raw)
    assert a_dn.min() >= 0.0 and a_dn.max() <= 1.0
    # the composite over grey follows the reference better too (colour denoised, alpha now as well)
    def comp(rgb, a):
        return rgb + (1.0 - a[..., None]) * 0.5

    ref_c = comp(ref_r["rgba"][..., :3], ref)
    e_dn = np.abs(comp(dn["rgba"][..., :3], a_dn) - ref_c)[fringe].mean()
    e_mixed = np.abs(comp(dn["rgba"][..., :3], a_raw) - ref_c)[fringe].mean()  # what was stored before
    assert e_dn < 0.7 * e_mixed, (e_dn, e_mixed)
