"""The caruncle in the pixels: a 64 px close-up of the left eye (4 spp, the skin visible) shows
pink at the medial canthus and white sclera away from it, and the pink stays at the canthus
when the eye turns (the caruncle belongs to the lids, not the eyeball;
``blender_scripts/assets/iris.py``, ``caruncle_layer``)."""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.params import AssetPick
from synth.plan.records import RenderSettings

bpy = pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

W = H = 64
#: red over green of linear RGB: the caruncle's albedo gives 2.9, the sclera's about 1.0
PINK, WHITE = 1.6, 1.25


def test_caruncle_is_pink_at_the_medial_canthus_and_stays_when_the_eye_turns(tmp_path):
    from blender_scripts import camera, passes, scene
    from blender_scripts import head as bhead
    from blender_scripts.assets import iris
    from synth.conventions import gaze_axis_angle, intrinsics, invert_rigid, orbit_camera_to_world, project
    from synth.dataset.segmentation import CLASSES
    from synth.model.meshutil import barycentric_points
    from tests.support import asset_scene

    ctx, hm = asset_scene.head_context("neutral")
    rig = iris.build(ctx, AssetPick.of("iris", "blue", {"melanin": 0.05, "stroma_scatter": 0.9,
                                                  "pupil_dilation": 0.5}))
    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu", max_bounces=4), W, H)
    scene.uniform_environment(1.0)
    eye = np.asarray(ctx.data.regions["eye_l"])
    c = ctx.rest_vertices[eye].mean(0)
    cam = camera.make_camera()
    K = intrinsics(W, H, 8.0, (0.0, 0.0))
    w2c = invert_rigid(orbit_camera_to_world(0.0, 0.0, 0.25, c))
    camera.set_camera(cam, K, w2c, W, H, 0.05, 10.0)
    tri, bary = ctx.data.landmarks["ibug68"]
    v, u = np.mgrid[0:H, 0:W] + 0.5
    pupils = []
    for yaw in (0.0, 20.0, -20.0):
        rot = np.zeros((hm.J, 3))
        rot[hm.joint_index["eye_l"]] = rot[hm.joint_index["eye_r"]] = gaze_axis_angle(yaw, 0.0)
        ctx.vertices = hm.evaluate(np.zeros(hm.data.identity_dims), np.zeros(hm.data.expression_dims),
                                   rot).vertices[0].astype(np.float64)
        bhead.set_vertices(ctx.head, ctx.vertices)
        rig.update(ctx)
        r = passes.render_view(tmp_path, 1)
        on_eye = r["segmentation"] == CLASSES["eyes"]
        rgb = r["rgba"][..., :3].astype(np.float64)
        redness = rgb[..., 0] / np.maximum(rgb[..., 1], 1e-6)
        p = barycentric_points(ctx.vertices, ctx.data.triangles, tri[[42]], bary[[42]])[0]
        q = project(K, w2c, p[None])[0][0]
        d = np.hypot(u - q[0], v - q[1])
        near, far = on_eye & (d < 4.0), on_eye & (d > 14.0)
        L = rgb @ np.array([0.2126, 0.7152, 0.0722])
        sclera = far & (L > np.percentile(L[on_eye], 60))  # the bright part: not the iris
        assert near.sum() >= 4 and sclera.sum() >= 20, (yaw, near.sum(), sclera.sum())
        pink_near = np.median(redness[near])
        white_far = np.median(redness[sclera])
        print(f"\nyaw {yaw:+.0f}: red/green at the canthus {pink_near:.2f}, on the sclera {white_far:.2f}")
        assert pink_near > PINK and white_far < WHITE, (yaw, pink_near, white_far)
        dark = on_eye & (L < np.percentile(L[on_eye], 10))
        pupils.append(np.array([(u * dark).sum(), (v * dark).sum()]) / dark.sum())
    # the eye did turn (by about 9 px each way), under a caruncle that stayed at the canthus: one
    # painted on the eyeball would have turned with it, away from the canthus at +20 degrees
    # (leaving white sclera there) and under the lid at -20 degrees
    moved_pupil = min(np.linalg.norm(x - pupils[0]) for x in pupils[1:])
    print(f"the pupil moved {moved_pupil:.2f} px")
    assert moved_pupil > 5.0, moved_pupil
