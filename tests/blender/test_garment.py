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
    # the body below the bust (synth.assets.fit.torso): a second object, in the garment's cloth
    Vt, Ft = torso.garment_torso(want)
    got_t, faces_t = asset_scene.evaluated_mesh(rig.objects[1])
    assert np.array_equal(got_t, Vt.astype(np.float32).astype(np.float64)) and np.array_equal(faces_t, Ft)
    assert rig.objects[1].data.materials[0].pass_index == rig.objects[0].data.materials[0].pass_index
    rec = rig.record()
    assert rec.pop("hidden_bust_polygons") > 0  # the bust under the hem (synth.assets.fit.hem)
    assert rec.pop("torso_vertices") == len(Vt)
    assert rec.pop("torso_arms") is True  # the arms follow the prism's vertices
    arms = torso.arm_params(want.P[torso.torso_shell_vertices(want)])
    assert len(rig.arms) == 2 and rig.arms == arms
    Va, Fa = torso.arms(want.P[torso.torso_shell_vertices(want)])
    np.testing.assert_array_equal(Vt[-len(Va):], Va)
    assert rec == want.info and rec["vertices"] == len(got)
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


def test_dressed_hair_keeps_out_of_the_arms():
    """Hair is groomed before the garment, on the head and bust alone; once the garment's arms exist
    (``dress``) its strands leave them (synth.assets.fit.torso.keep_strands_out), also after an
    expression change. Long straight hair on this head hangs through both shoulders otherwise."""
    from tests.support import asset_scene
    from blender_scripts.assets import dress, update
    from synth.assets.fit import torso
    from synth.geometry.raycast import ray_hit_counts

    ctx, hm = asset_scene.head_context("neutral", resolution=96)
    rigs = dress(ctx, {"hair": {"id": "long_straight", "generator": "procedural:hair_strands", "params": {}},
                       "garment": {"id": "tshirt_crew", "generator": "procedural:garment_shell", "params": {}}})
    arms = rigs["garment"].arms
    V, F = torso.arms(rigs["garment"].fitted.P[torso.torso_shell_vertices(rigs["garment"].fitted)])
    hair = rigs["hair"]
    groomed = hair.attachment.positions(ctx).reshape(-1, 3)  # where the groom alone puts them

    def inside(pts):
        return ray_hit_counts(pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1)), V, F, t_min=1e-9) % 2 == 1

    def curve_points():
        cv = hair.ob.data
        out = np.empty(len(cv.points) * 3, np.float32)
        cv.position_data.foreach_get("vector", out)
        return out.reshape(-1, 3).astype(np.float64)

    assert inside(groomed).sum() > 50 and hair.record()["points_out_of_arms"] > 50
    assert len(arms) == 2 and not inside(curve_points()).any()
    asset_scene.set_case(ctx, hm, "id+3_jaw")
    update(rigs, ctx)
    assert not inside(curve_points()).any()
    # without a garment there is nothing to keep out of
    ctx2, _ = asset_scene.head_context("neutral", resolution=96)
    alone = dress(ctx2, {"hair": {"id": "long_straight", "generator": "procedural:hair_strands", "params": {}}})
    assert "points_out_of_arms" not in alone["hair"].record()


@pytest.mark.parametrize("garment_id,bare", [("tank_top", True), ("tshirt_crew", False)])
def test_sleeveless_garments_have_bare_arms(tmp_path, garment_id, bare):
    """A tank top's upper arms are the head's skin (segmentation class skin, second slot of the
    torso object); a T-shirt's are its cloth. Checked on the mesh and in the pixels: the outer side of
    each arm, 8 cm under its cap's base, seen from the front."""
    from tests.support import asset_scene
    from blender_scripts import camera, passes, scene
    from blender_scripts.assets import garment
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
    from synth.dataset.segmentation import CLASSES

    ctx, _ = asset_scene.head_context("neutral")
    g = garment.build(ctx, AssetPick.coerce("garment", {"id": garment_id, "params": {"colour_hsv": "navy"}}))
    torso_ob = g.objects[1]
    mats = list(torso_ob.data.materials)
    slots = np.zeros(len(torso_ob.data.polygons), np.int64)
    torso_ob.data.polygons.foreach_get("material_index", slots)
    assert mats[0].pass_index == CLASSES["clothing"]
    if bare:
        assert g.record()["torso_arms_skin"] is True
        assert len(mats) == 2 and mats[1] is ctx.materials[CLASSES["skin"]]
        assert 0 < (slots == 1).sum() < len(slots)  # the arms' faces, not the prism's
    else:
        assert "torso_arms_skin" not in g.record() and len(mats) == 1 and not slots.any()
    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu"), 64, 64)
    scene.uniform_environment(1.0)
    cam = camera.make_camera()
    z = min(a.z_base for a in g.arms) - 0.08
    target = np.array([0.0, float(np.mean([a.axis[1] for a in g.arms])), z])
    K = intrinsics(64, 64, 40.0, (0.0, 0.0))
    w2c = invert_rigid(orbit_camera_to_world(0.0, 0.0, 1.0, target))
    camera.set_camera(cam, K, w2c, 64, 64, 0.05, 10.0)
    seg = passes.render_view(tmp_path, 3)["segmentation"]
    pts = np.array([[a.axis[0] + a.side * 0.8 * float(a.radius_at(z)), a.axis[1], z] for a in g.arms])
    uv, _ = project(K, w2c, pts)
    want = CLASSES["skin"] if bare else CLASSES["clothing"]
    for u, v in uv:
        assert seg[int(v), int(u)] == want, (garment_id, seg[int(v), int(u)])
