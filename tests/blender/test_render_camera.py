"""Camera truth at the renderer: a tiny Cycles render of the default head, checked against the
OpenCV camera of synth.conventions (projection of 3D landmarks vs rendered depth and alpha)."""

from __future__ import annotations

import numpy as np
import pytest

from synth.plan.records import RenderSettings

bpy = pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    from blender_scripts import camera, head, materials, passes, scene
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from synth.appearance.skin import skin_albedo

    m = load_default_model()
    hm = HeadModel(m)
    scene.reset()
    W, H = 64, 48
    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu"), W, H)
    scene.uniform_environment(1.0)
    mats = materials.head_materials(None, skin_albedo(0.05, 0.015))
    ev = hm.evaluate(np.zeros(m.identity_dims), np.zeros(m.expression_dims))
    head.build_head_object(m, ev.vertices[0], mats)
    cam = camera.make_camera()
    lm = ev.landmarks["ibug68"][0].astype(np.float64)
    eyes = 0.5 * (lm[39] + lm[42])
    # the last two views see the whole model (nothing cropped), for the principal-point check: aimed
    # at the centre of its bounding box from 2 m, the head and the bust to the waist and elbows
    # (0.61 m tall) span about 33 of the 48 rows
    whole = 0.5 * (ev.vertices[0].min(0) + ev.vertices[0].max(0)).astype(np.float64)
    out = []
    tmp = tmp_path_factory.mktemp("render")
    for az, el, rad, off, target in ((0.0, 0.0, 0.55, (0.0, 0.0), eyes), (35.0, 15.0, 0.55, (2.5, -1.5), eyes),
                                     (-80.0, -10.0, 0.55, (0.0, 0.0), eyes), (0.0, 0.0, 2.0, (0.0, 0.0), whole),
                                     (0.0, 0.0, 2.0, (4.0, -3.0), whole)):
        w2c = invert_rigid(orbit_camera_to_world(az, el, rad, target))
        K = intrinsics(W, H, 35.0, off)
        camera.set_camera(cam, K, w2c, W, H, 0.05, 10.0)
        r = passes.render_view(tmp, 7)
        uv, z = project(K, w2c, lm)
        out.append((K, w2c, uv, z, r))
    return m, out


def test_visible_landmarks_match_depth_and_alpha(rendered):
    from synth.dataset.labels import visibility

    _, views = rendered
    n_checked = 0
    for K, w2c, uv, z, r in views[:3]:
        vis = visibility(uv, z, r["depth"], r["rgba"][..., 3])
        assert vis.sum() >= 20  # most of the face is visible in each of these views
        col, row = np.floor(uv[vis]).astype(int).T
        assert np.all(r["rgba"][row, col, 3] > 0.5)
        # the pixel's own rendered depth is the landmark's camera z up to the pixel's depth span
        err = np.abs(r["depth"][row, col] - z[vis])
        assert np.median(err) < 0.01
        n_checked += int(vis.sum())
    assert n_checked > 60


def test_silhouette_centred_where_the_camera_says(rendered):
    """The rendered head moves with the principal point exactly as K says (sub-pixel)."""
    from synth.conventions import project

    m, views = rendered
    (K0, w0, *_ , r0), (K1, w1, *_ , r1) = views[0], views[1]
    a = r0["rgba"][..., 3]
    ys, xs = np.mgrid[: a.shape[0], : a.shape[1]]
    # centroid of the head's alpha vs the projection of the head's vertex centroid: the
    # frontal view is nearly symmetric left/right, so the x coordinates must agree closely
    cx = (a * (xs + 0.5)).sum() / a.sum()
    centre = m.template[m.regions["face"]].mean(0, keepdims=True)
    u, _ = project(K0, w0, centre)
    assert abs(cx - u[0, 0]) < 1.5
    # same pose with the principal point moved by (4, -3) px: the image moves by exactly that
    a0, a3 = views[3][4]["rgba"][..., 3], views[4][4]["rgba"][..., 3]
    assert a0[0].max() == 0 and a0[-1].max() == 0 and a0[:, 0].max() == 0 and a0[:, -1].max() == 0
    c0 = np.array([(a0 * xs).sum(), (a0 * ys).sum()]) / a0.sum()
    c3 = np.array([(a3 * xs).sum(), (a3 * ys).sum()]) / a3.sum()
    np.testing.assert_allclose(c3 - c0, [4.0, -3.0], atol=0.35)


def test_segmentation_and_background(rendered):
    from synth.dataset.segmentation import CLASSES

    _, views = rendered
    r = views[0][4]
    seg, alpha = r["segmentation"], r["rgba"][..., 3]
    assert set(np.unique(seg).tolist()) <= set(CLASSES.values())
    assert np.all(seg[alpha <= 0] == 0)
    assert (seg == CLASSES["skin"]).sum() > 200
    assert (seg == CLASSES["eyes"]).sum() > 0
    assert np.all(np.isinf(r["depth"][alpha <= 0]))
    assert np.all(np.isfinite(r["rgba"]))
