"""The bust's cut is never visible: rendered from below, beside and behind (64 px, 4 spp), no
skin-class pixel shows a surface point near the bust's open boundary, for identities at +-3 SD
and garments of every construction (crew torso shell, tank top straps, jacket over a shirt).
The hem's geometry is tested without Blender in tests/assets/test_hem.py."""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.params import AssetPick
from synth.plan.records import RenderSettings

bpy = pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

W = H = 64
#: skin closer than this (m) to the bust's open boundary counts as the cut showing
NEAR_CUT = 0.015
VIEWS = ((0.0, -45.0), (90.0, -30.0), (180.0, -40.0), (-60.0, 0.0))
#: segmentation id given to bare forearms in this test only (no class uses it)
ARMS_HERE = 200


def _skin_points(r, K, w2c):
    from synth.conventions import invert_rigid
    from synth.dataset.segmentation import CLASSES

    v, u = np.nonzero(r["segmentation"] == CLASSES["skin"])
    z = r["depth"][v, u].astype(np.float64)
    rays = np.linalg.inv(K) @ np.stack([u + 0.5, v + 0.5, np.ones_like(u, float)])
    Xc = (rays * z).T
    c2w = invert_rigid(w2c)
    return Xc @ c2w[:3, :3].T + c2w[:3, 3]


@pytest.mark.parametrize("case,garment", [("neutral", "tshirt_crew"), ("id+3_jaw", "tank_top"),
                                          ("id-3_brows", "jacket_blazer")])
def test_no_skin_at_the_bust_cut(tmp_path, case, garment):
    from tests.support import asset_scene
    from blender_scripts import camera, passes, scene
    from blender_scripts.assets import garment as grig
    from synth.assets.fit.hem import _segment_distance, cut_loop
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world

    ctx, _ = asset_scene.head_context(case)
    rig = grig.build(ctx, AssetPick.of("garment", garment, {"colour_hsv": "navy"}))
    assert rig.record()["hidden_bust_polygons"] > 0
    if rig.record().get("torso_forearms_skin"):  # bare forearms hang beside the waist's cut: their
        mats = rig.objects[1].data.materials  # skin is not the bust's, so it gets a class of its own here
        mats[1] = mats[1].copy()
        mats[1].pass_index = ARMS_HERE
    from scipy.spatial import cKDTree

    V = ctx.vertices
    loop = cut_loop(ctx.data.triangles, V)
    arm = np.zeros(len(V), bool)
    for r in ("arm_l", "arm_r"):
        arm[np.asarray(ctx.data.regions.get(r, []), np.int64)] = True
    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu", max_bounces=4), W, H)
    scene.uniform_environment(1.0)
    cam = camera.make_camera()
    target = V[loop].mean(0) + np.array([0.0, 0.0, 0.05])
    K = intrinsics(W, H, 40.0, (0.0, 0.0))
    seen_cloth = seen_arms = 0
    for az, el in VIEWS:
        w2c = invert_rigid(orbit_camera_to_world(az, el, 0.8, target))
        camera.set_camera(cam, K, w2c, W, H, 0.05, 10.0)
        r = passes.render_view(tmp_path, 1)
        P = _skin_points(r, K, w2c)
        if len(P) and len(arm):  # the bust's bare arms hang beside the waist's cut (an elbow 6 mm from
            P = P[~arm[cKDTree(V).query(P)[1]]]  # it at +3 SD): their skin is not the cut
        d = _segment_distance(P, V[loop], V[np.roll(loop, -1)]) if len(P) else np.zeros(0)
        assert (d < NEAR_CUT).sum() == 0, f"{case} {garment} az {az} el {el}: {(d < NEAR_CUT).sum()} skin pixels at the cut"
        seen_cloth += int((r["segmentation"] == 9).sum())
        seen_arms += int((r["segmentation"] == ARMS_HERE).sum())
    assert seen_cloth > 200  # the views do look at the garment
    assert (seen_arms > 20) == bool(rig.record().get("torso_forearms_skin"))  # and at the bare forearms


#: (azimuth, elevation) of default-range views (camera.elevation_deg [-45, 70]) that showed the
#: bust's lower end inside the frame before the torso under the garment (docs/realism.md)
FRAMED_VIEWS = ((0.0, -40.0), (35.0, 0.0), (180.0, 10.0), (-120.0, 40.0), (60.0, 68.0))


@pytest.mark.parametrize("case,garment", [("neutral", "tshirt_crew"), ("id-3_brows", "hoodie"),
                                          ("id+3_jaw", "jacket_blazer")])
def test_body_leaves_the_frame_at_the_bottom(tmp_path, case, garment):
    """Framed as the default cameras frame a head (85 mm lens, the head's sphere filling 0.95 of
    the half field of view, aimed at the head's centre), the body reaches the bottom border in
    every view: the garment continues below the bust (synth.assets.fit.torso) in its cloth
    (segmentation class clothing), and a camera inside that body (far below) sees out of it."""
    from tests.support import asset_scene
    from blender_scripts import camera, passes, scene
    from blender_scripts.assets import garment as grig
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world
    from synth.dataset.segmentation import CLASSES

    ctx, _ = asset_scene.head_context(case)
    rig = grig.build(ctx, AssetPick.of("garment", garment, {"colour_hsv": "navy", "drawstrings": True}))
    assert len(rig.objects) == 2 and rig.record()["torso_vertices"] > 0
    head = ctx.vertices[ctx.vertices[:, 2] > ctx.landmarks["ibug68"][8, 2] - 0.02]
    lo, hi = head.min(0), head.max(0)
    target, radius = 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo)) + 0.03
    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu", max_bounces=4), W, H)
    scene.uniform_environment(1.0)
    cam = camera.make_camera()
    half = np.arctan(18.0 / 85.0)
    dist = radius / np.sin(0.95 * half)
    K = intrinsics(W, H, float(np.degrees(2 * half)), (0.0, 0.0))
    for az, el in FRAMED_VIEWS:
        w2c = invert_rigid(orbit_camera_to_world(az, el, dist, target))
        camera.set_camera(cam, K, w2c, W, H, 0.05, 10.0)
        seg = passes.render_view(tmp_path, 1)["segmentation"]
        bottom = seg[-1]
        assert (bottom == CLASSES["clothing"]).any(), f"{case} {garment} az {az} el {el}: {np.unique(bottom)}"
    # from straight below, inside the body (1 m under the head's centre): its walls are
    # see-through from inside, so the camera sees the bust's underside and the background
    # beside it, not the inside of the torso's wall all round
    w2c = invert_rigid(orbit_camera_to_world(0.0, -89.0, 1.0, target))
    Vt = rig.torso[0]
    assert Vt[:, 2].min() < invert_rigid(w2c)[2, 3] < Vt[:, 2].max()  # the camera is inside the torso
    camera.set_camera(cam, K, w2c, W, H, 0.05, 10.0)
    seg = passes.render_view(tmp_path, 1)["segmentation"]
    assert (seg == CLASSES["clothing"]).mean() > 0.2 and (seg == CLASSES["background"]).mean() > 0.05, np.unique(seg)
