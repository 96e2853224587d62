"""The skin-detail rig's albedo layers below the pixel (freckles, age spots, the stubble shadow):
faded to a flat tint, that tint must be the layer's true mean, measured here in Cycles on a
plane of many cells (the numbers behind it: synth.appearance.skin_optics)."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance import skin_optics as so
from synth.plan.records import RenderSettings
from tests.support import asset_scene

N = 128  # pixels across; 16 samples each: 262,144 point samples of the pattern


def _plane_mean(tmp_path, size_m: float, build_factor) -> tuple[float, float]:
    """(mean, spread) of an emission plane whose strength is the factor socket that
    ``build_factor(mat)`` returns, seen whole by an orthographic camera."""
    import bpy

    from blender_scripts import passes, scene

    scene.reset()
    scene.configure_render(RenderSettings(samples=16, denoise=False, device="cpu", max_bounces=0,
                            filter_width=0.01), N, N)
    bpy.ops.mesh.primitive_plane_add(size=size_m)  # object coordinates = metres, as on the head
    plane = bpy.context.active_object
    mat, em = asset_scene.single_shader_material("layer", "ShaderNodeEmission", {"Color": (1.0, 1.0, 1.0, 1.0)})
    fac = build_factor(mat)
    if hasattr(fac, "node"):
        mat.node_tree.links.new(fac, em.inputs["Strength"])
    else:
        em.inputs["Strength"].default_value = float(fac)
    plane.data.materials.append(mat)
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 0.98 * size_m
    cam.location = (0.0, 0.0, 1.0)
    r = passes.render_view(tmp_path, 1)
    g = r["rgba"][..., 1].astype(np.float64)
    assert r["rgba"][..., 3].min() > 0.99  # the plane fills the frame
    return float(g.mean()), float(g.std())


def _one(mat):
    return 1.0


@pytest.mark.blender
@pytest.mark.parametrize("name,layer,threshold", [("freckles", so.FRECKLES, 0.5), ("age_spots", so.AGE_SPOTS, 1.0)])
def test_spot_layer_faded_is_its_mean(tmp_path, name, layer, threshold):
    pytest.importorskip("bpy")
    from blender_scripts.assets.skin_detail import spot_factor

    size = 240 * layer[0]  # 240 x 240 cells: thousands of spots
    full, spread = _plane_mean(tmp_path, size, lambda m: spot_factor(m, layer, 3.1, threshold, 1.0, 1.0))
    flat, flat_spread = _plane_mean(tmp_path, size, lambda m: spot_factor(m, layer, 3.1, threshold, 1.0, 0.0))
    half, _ = _plane_mean(tmp_path, size, lambda m: spot_factor(m, layer, 3.1, threshold, 1.0, 0.5))
    expect = so.spot_coverage(threshold, layer[1])
    assert spread > 0.01 and flat_spread < 1e-6  # spots at full detail, a flat tint at none
    assert flat == pytest.approx(expect, rel=1e-5)
    assert full == pytest.approx(expect, rel=0.05), (name, full, expect)
    assert half == pytest.approx(0.5 * (full + flat), rel=0.05)


@pytest.mark.blender
def test_stubble_faded_is_its_mean(tmp_path):
    pytest.importorskip("bpy")
    from blender_scripts.assets.skin_detail import stubble_factor

    size = 240 * so.STUBBLE_PERIOD_M
    full, spread = _plane_mean(tmp_path, size, lambda m: stubble_factor(m, 8.0, 1.0, 1.0, 1.0))
    flat, flat_spread = _plane_mean(tmp_path, size, lambda m: stubble_factor(m, 8.0, 1.0, 1.0, 0.0))
    assert spread > 0.005 and flat_spread < 1e-6
    assert flat == pytest.approx(so.NOISE_FAC_MEAN, rel=1e-5)
    assert full == pytest.approx(flat, abs=0.02)


@pytest.mark.blender
def test_mottling_keeps_the_mean_colour_and_shows(tmp_path):
    """The mottling multiplies the albedo by a factor of mean 1 (the skin's calibrated colour stays
    on average) that varies visibly at millimetre scales."""
    pytest.importorskip("bpy")
    from blender_scripts.assets.skin_detail import mottle_factor

    size = 30 * so.MOTTLE_PERIOD_M  # 30 x 30 periods of the coarsest octave
    mean, spread = _plane_mean(tmp_path, size, lambda m: mottle_factor(m, 3.0, so.MOTTLE_AMPLITUDE))
    assert mean == pytest.approx(1.0, abs=0.02)
    assert 0.02 < spread < 0.25  # visible, not a dirty patchwork
    none, none_spread = _plane_mean(tmp_path, size, lambda m: mottle_factor(m, 3.0, 0.0))
    assert none == pytest.approx(1.0, abs=1e-5) and none_spread < 1e-6


def test_spot_weights_follow_the_pixel():
    # a freckle is 2 x 0.35 cells = 1.56 mm across: resolved at 0.5 mm pixels, a tint at 2 mm
    assert so.spot_weight(None, so.FRECKLES) == 1.0
    assert so.spot_weight(0.0005, so.FRECKLES) == 1.0
    assert so.spot_weight(0.002, so.FRECKLES) == 0.0
    assert 0.0 < so.spot_weight(0.001, so.FRECKLES) < 1.0
    # age spots (8.3 mm) stay resolved at preview's 2 mm pixels, not at ci's 8 mm
    assert so.spot_weight(0.002, so.AGE_SPOTS) == 1.0
    assert so.spot_weight(0.008, so.AGE_SPOTS) < 0.1
    assert so.spot_coverage(2.0, 0.35) == so.VORONOI_F1_BELOW[0.35]
    assert so.spot_coverage(-1.0, 0.25) == 0.0
