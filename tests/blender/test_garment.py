"""Garment and headwear rigs in Blender: the mesh object is the numpy shell (after build and
after an expression change), materials carry the segmentation id, and a render shows them.
The geometry itself is tested without Blender in tests/test_assets_fit_shells.py."""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.params import AssetPick
from synth.plan.records import RenderSettings

bpy = pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]


def test_rig_mesh_is_the_fitted_shell():
    from tests.support import asset_scene
    from blender_scripts.assets import garment, headwear
    from synth.assets.fit.arms import FOREARM_INSET, HAIR_CLEARANCE
    from synth.assets.fit.body import Body, fit_shell
    from synth.assets.fit import torso
    from synth.assets.fit.garment import CLEARANCE, garment_shell

    ctx, hm = asset_scene.head_context("id-3_brows", resolution=256, identity_index=2, run_seed=5)
    entry = {"id": "hoodie", "params": {"hood_up": True}}
    rig = garment.build(ctx, AssetPick.coerce("garment", entry))
    body = Body.of(ctx)
    want = fit_shell(body, garment_shell(body, entry, ctx.rng("garment")), CLEARANCE)
    got, faces = asset_scene.evaluated_mesh(rig.objects[0])
    assert np.array_equal(got, want.P.astype(np.float32).astype(np.float64)) and np.array_equal(faces, want.F)
    # the body below the bust and the forearms (synth.assets.fit.torso, .arms): a second object, in
    # the garment's cloth (long sleeves: the forearms' wall at the sleeve's reach, less the inset)
    reach = want.info["cloth_reach_m"]
    Vt, Ft = torso.garment_torso(want, (body.V, body.F, body.regions), reach - FOREARM_INSET)
    got_t, faces_t = asset_scene.evaluated_mesh(rig.objects[1])
    assert np.array_equal(got_t, Vt.astype(np.float32).astype(np.float64)) and np.array_equal(faces_t, Ft)
    assert rig.objects[1].data.materials[0].pass_index == rig.objects[0].data.materials[0].pass_index
    assert len(rig.objects[1].data.materials) == 1
    rec = rig.record()
    assert rec.pop("hidden_bust_polygons") > 0  # the bust under the hem (synth.assets.fit.hem)
    assert rec.pop("torso_vertices") == len(Vt)
    assert rec.pop("torso_forearms") is True
    assert rec.pop("hair_arm_clearance_m") == pytest.approx(reach + HAIR_CLEARANCE)
    assert rig.arm_keep_out is not None and rig.arm_keep_out.clearance == pytest.approx(reach + HAIR_CLEARANCE)
    assert rec == want.info and rec["vertices"] == len(got) and rec["sleeves"] == "long"
    asset_scene.set_case(ctx, hm, "id-3_jaw")
    rig.update(ctx)
    moved = want.follow(ctx.vertices, ctx.data.triangles)
    assert np.array_equal(asset_scene.evaluated_mesh(rig.objects[0])[0], moved.astype(np.float32).astype(np.float64))
    band = torso.hem_band(want)
    moved_t = torso.follow(Vt, want.P[band], moved[band])
    assert np.allclose(asset_scene.evaluated_mesh(rig.objects[1])[0], moved_t, atol=1e-6)
    h = headwear.build(ctx, AssetPick.coerce("headwear", {"id": "baseball_cap", "params": {"brim_yaw_deg": 90.0}}))
    assert h.cls == "headwear" and len(h.objects) == 1 and h.record()["faces"] > 100


def test_render_shows_clothing_and_headwear(tmp_path):
    from tests.support import asset_scene
    from blender_scripts import camera, passes, scene
    from blender_scripts.assets import garment, headwear
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world
    from synth.dataset.segmentation import CLASSES

    ctx, _ = asset_scene.head_context("neutral")
    g = garment.build(ctx, AssetPick.coerce("garment", {"id": "sweater", "params": {"colour_hsv": "navy"}}))
    h = headwear.build(ctx, AssetPick.coerce("headwear", {"id": "beanie", "params": {"colour_hsv": "red"}}))
    assert all(m.pass_index == CLASSES["clothing"] for m in g.objects[0].data.materials)
    assert all(m.pass_index == CLASSES["headwear"] for m in h.objects[0].data.materials)
    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu"), 48, 64)
    scene.uniform_environment(1.0)
    cam = camera.make_camera()
    lm = ctx.landmarks["ibug68"]
    target = 0.5 * (lm[39] + lm[42]) - np.array([0.0, 0.0, 0.06])
    w2c = invert_rigid(orbit_camera_to_world(20.0, 5.0, 0.9, target))
    camera.set_camera(cam, intrinsics(48, 64, 30.0, (0.0, 0.0)), w2c, 48, 64, 0.05, 10.0)
    r = passes.render_view(tmp_path, 3)
    seg = r["segmentation"]
    assert (seg == CLASSES["clothing"]).sum() > 20
    assert (seg == CLASSES["headwear"]).sum() > 20
    assert (seg == CLASSES["skin"]).sum() > 20
    assert np.isfinite(r["rgba"]).all()


def test_dressed_hair_keeps_off_the_sleeves():
    """Hair is groomed before the garment, clear of the skin; once the garment exists (``dress``) its
    strands keep the sleeves' reach off the upper arms (synth.assets.fit.arms.ArmKeepOut), also
    after an expression change. Long straight hair on this head lies on a sweater's sleeves
    otherwise (the groom keeps it off the skin, not off the cloth; a T-shirt's short sleeve does
    not reach it: the groom lays strands over the body, strands.settle)."""
    from tests.support import asset_scene
    from blender_scripts.assets import dress, update
    from synth.assets.fit.arms import HAIR_MAX_DEPTH

    ctx, hm = asset_scene.head_context("neutral", resolution=96)
    rigs = dress(ctx, {"hair": {"id": "long_straight", "generator": "procedural:hair_strands", "params": {}},
                       "garment": {"id": "sweater", "generator": "procedural:garment_shell", "params": {}}})
    keep = rigs["garment"].arm_keep_out
    hair = rigs["hair"]

    def short(pts):
        d, on_arm = keep.distance(pts)
        return (d < keep.clearance - 1e-6) & (d > -HAIR_MAX_DEPTH) & on_arm

    def curve_points():
        cv = hair.ob.data
        out = np.empty(len(cv.points) * 3, np.float32)
        cv.position_data.foreach_get("vector", out)
        return out.reshape(-1, 3).astype(np.float64)

    groomed = hair.attachment.positions(ctx)  # where the groom alone puts them
    n = hair.record()["points_out_of_arms"]
    before = int(short(groomed[:, 1:].reshape(-1, 3)).sum())
    assert before > 0 and n >= before
    # the Curves object's points (float32) keep off the arms: the rig's own positions, but where the
    # crease between arm and torso leaves no room for the clearance (with the sweater on this head:
    # 2 of 479 points stay 1.4-2.4 mm inside the sleeves' 14.75 mm reach)
    kept, _ = keep.push(groomed)
    left = int(short(kept[:, 1:].reshape(-1, 3)).sum())
    assert left <= 0.1 * before
    pts = curve_points().reshape(groomed.shape)
    assert short(pts[:, 1:].reshape(-1, 3)).sum() <= max(left, 0.01 * before)
    asset_scene.set_case(ctx, hm, "id+3_jaw")
    update(rigs, ctx)
    now = curve_points().reshape(groomed.shape)
    np.testing.assert_allclose(now, keep.push(hair.attachment.positions(ctx))[0], atol=1e-6)
    # without a garment there is nothing to keep off
    ctx2, _ = asset_scene.head_context("neutral", resolution=96)
    alone = dress(ctx2, {"hair": {"id": "long_straight", "generator": "procedural:hair_strands", "params": {}}})
    assert "points_out_of_arms" not in alone["hair"].record()


@pytest.mark.parametrize("garment_id,sleeve,forearm", [("tank_top", "skin", "skin"), ("tshirt_crew", "skin", "skin"),
                                                       ("sweater", "clothing", "clothing")])
def test_arms_under_each_kind_of_sleeve(tmp_path, garment_id, sleeve, forearm):
    """The bust's upper arm below a short sleeve, or under none, is the head's skin, under a long one
    the garment's cloth; the forearms are the head's skin (the torso object's second material slot)
    under short sleeves and none, the cloth under long ones. Checked on the mesh and in the pixels,
    seen from the front: the front of each upper arm at 70 % of the way down to the elbow, and each
    forearm 10 cm under the elbow."""
    from tests.support import asset_scene
    from blender_scripts import camera, passes, scene
    from blender_scripts.assets import garment
    from synth.assets.fit.arms import FOREARM_BEND_DEG
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
    from synth.dataset.segmentation import CLASSES

    ctx, _ = asset_scene.head_context("neutral")
    g = garment.build(ctx, AssetPick.coerce("garment", {"id": garment_id, "params": {"colour_hsv": "navy"}}))
    torso_ob = g.objects[1]
    mats = list(torso_ob.data.materials)
    slots = np.zeros(len(torso_ob.data.polygons), np.int64)
    torso_ob.data.polygons.foreach_get("material_index", slots)
    assert mats[0].pass_index == CLASSES["clothing"]
    if forearm == "skin":
        assert g.record()["torso_forearms_skin"] is True
        assert len(mats) == 2 and mats[1] is ctx.materials[CLASSES["skin"]]
        assert 0 < (slots == 1).sum() < len(slots)  # the forearms' faces, not the prism's
    else:
        assert "torso_forearms_skin" not in g.record() and len(mats) == 1 and not slots.any()
    from synth.assets.fit.body import Body

    fr = Body.of(ctx).arms
    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu"), 96, 96)
    scene.uniform_environment(1.0)
    cam = camera.make_camera()
    target = 0.5 * (fr.elbow["L"] + fr.elbow["R"])
    K = intrinsics(96, 96, 40.0, (0.0, 0.0))
    w2c = invert_rigid(orbit_camera_to_world(0.0, 0.0, 1.6, target))
    camera.set_camera(cam, K, w2c, 96, 96, 0.05, 10.0)
    seg = passes.render_view(tmp_path, 3)["segmentation"]
    b = np.radians(FOREARM_BEND_DEG)
    for s, sign in (("L", 1.0), ("R", -1.0)):
        on = (fr.side == sign) & (np.abs(fr.t - 0.7) < 0.05)
        front = ctx.vertices[on][np.argmin(ctx.vertices[on, 1])]  # the arm's front
        fore = fr.elbow[s] + 0.1 * np.array([0.0, -np.sin(b), -np.cos(b)])  # on the forearm's axis
        uv, _ = project(K, w2c, np.array([front, fore]))
        for (u, v), want in zip(uv, (sleeve, forearm)):
            assert seg[int(v), int(u)] == CLASSES[want], (garment_id, s, want, seg[int(v), int(u)])
