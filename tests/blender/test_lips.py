"""The lips in the pixels: a 64 px frontal close-up of the mouth (4 spp) of light skin shows the
lips redder in hue than the skin around them, and they are not without the lips' own colour
(``synth.appearance.lips``, the ``vermilion`` attribute and ``blender_scripts.materials.skin_material``)."""

from __future__ import annotations

import numpy as np
import pytest

from synth.plan.records import RenderSettings

bpy = pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

W = H = 64


def _hue(rgb) -> float:
    from synth.appearance.skin import cielab

    lab = cielab(np.asarray(rgb, np.float64))
    return float(np.degrees(np.arctan2(lab[2], lab[1])))


def test_lips_are_redder_than_the_skin_around_them(tmp_path):
    from scipy.spatial import cKDTree

    from blender_scripts import camera, passes, scene
    from blender_scripts import materials as bmat
    from synth.appearance.lips import lip_albedo, vermilion_attribute
    from synth.appearance.skin import melanin_for_ita, skin_albedo
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
    from synth.dataset.segmentation import CLASSES
    from synth.geometry import vertex_normals
    from tests.support import asset_scene

    ctx, hm = asset_scene.head_context("neutral")
    hb = 0.015
    mel = float(melanin_for_ita(np.array([45.0]), np.array([hb]))[0])  # light skin
    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu", max_bounces=4), W, H)
    scene.uniform_environment(1.0)
    d, V = ctx.data, ctx.vertices
    lm = ctx.landmarks["ibug68"]
    mouth = 0.5 * (lm[48] + lm[54])
    cam = camera.make_camera()
    K = intrinsics(W, H, 20.0, (0.0, 0.0))
    c2w = orbit_camera_to_world(0.0, 0.0, 0.25, mouth)
    w2c = invert_rigid(c2w)
    camera.set_camera(cam, K, w2c, W, H, 0.05, 10.0)
    # vertices facing the camera: the lips' inside (attribute 1) and the skin 4-10 mm beyond them
    a = vermilion_attribute(len(V), d.regions, d.triangles)
    n = vertex_normals(V, d.triangles)
    eye = c2w[:3, 3]
    facing = np.einsum("ij,ij->i", n, eye - V) / np.linalg.norm(eye - V, axis=1) > 0.5
    lips = np.nonzero((a == 1.0) & facing)[0]
    dist = cKDTree(V[a > 0]).query(V)[0]
    near = np.nonzero((a == 0) & facing & (dist > 0.004) & (dist < 0.010))[0]
    slot = next(s for s in ctx.head.material_slots if s.material.name.startswith("skin"))

    def pixels(idx, r):
        uv = np.floor(project(K, w2c, V[idx])[0]).astype(int)
        ok = (uv >= 0).all(1) & (uv < W).all(1)
        uv = uv[ok]
        keep = r["segmentation"][uv[:, 1], uv[:, 0]] == CLASSES["skin"]
        return r["rgba"][uv[keep, 1], uv[keep, 0], :3].astype(np.float64)

    out = {}
    for name, lip in (("with", lip_albedo(mel, hb)), ("without", None)):
        slot.material = bmat.skin_material(skin_albedo(mel, hb), None, None, lip)
        r = passes.render_view(tmp_path, 1)
        pl, ps = pixels(lips, r), pixels(near, r)
        assert len(pl) >= 15 and len(ps) >= 15, (len(pl), len(ps))
        out[name] = (_hue(np.median(pl, 0)), _hue(np.median(ps, 0)))
        print(f"\n{name} the lips' colour: hue of the lips {out[name][0]:.1f}, of the skin around {out[name][1]:.1f} deg")
    # the albedos differ by 25 degrees of hue (measured: 28); without the layer only shading
    # differs (measured: 4)
    assert out["with"][0] < out["with"][1] - 15.0, out
    assert out["without"][0] > out["without"][1] - 8.0, out
