"""The procedural studio environment (synth.appearance.lighting): its normalisation, where its
lights are, hard parameters, and (in Blender) that a diffuse sphere under it shows the
irradiance the numpy model predicts, pixel by pixel."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance.lighting import FRONT, Studio, front_normals, irradiance, map_directions, studio_map
from synth.conventions import spherical_offset
from synth.plan.records import RenderSettings
from tests.support import asset_scene


def _argmax_direction(L: np.ndarray) -> np.ndarray:
    d, _ = map_directions(L.shape[1])
    return d.reshape(-1, 3)[np.argmax(L[..., 0])]


def test_the_face_gets_the_uniform_irradiance_on_average():
    """Surfaces facing the front half-space get on average the irradiance of the uniform
    environment of radiance 1 (pi); the front more, its key side more than its fill side, the
    back and the underside less."""
    L = studio_map(Studio())
    assert L.shape == (128, 256, 3) and L.dtype == np.float32 and (L > 0).all()
    n = front_normals()
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0) and (n[:, 1] <= 0).all() and abs(n.mean(0)[1] + 0.5) < 1e-3
    assert irradiance(L, n).mean() == pytest.approx(np.pi, rel=1e-6)
    front, right, left, back, down = irradiance(L, np.array([FRONT, [-1.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]]))
    assert front > np.pi > right > left > back and down < left  # key on the subject's right (-X), fill left
    d, w = map_directions(256)
    assert w.sum() == pytest.approx(4 * np.pi, rel=1e-4)
    assert np.allclose(np.linalg.norm(d, axis=-1), 1.0)


@pytest.mark.parametrize("key,rot", [((-35.0, 30.0), 0.0), ((0.0, 0.0), 90.0), ((120.0, -40.0), -30.0), ((10.0, 80.0), 0.0)])
def test_the_brightest_direction_is_the_key(key, rot):
    L = studio_map(Studio(key_deg=key, key_size_deg=5.0, key_share=0.9, fill_share=0.0, rotation_deg=rot))
    want = spherical_offset(key[0] + rot, key[1])
    assert np.degrees(np.arccos(np.clip(_argmax_direction(L) @ want, -1, 1))) < 1.5  # a pixel is 1.4 degrees


@pytest.mark.parametrize("kw", [dict(key_share=0.0, fill_share=0.0), dict(key_share=1.0, fill_share=0.0),
                                dict(key_share=0.5, fill_share=0.5, key_size_deg=5.0, fill_size_deg=5.0),
                                dict(key_size_deg=90.0, fill_size_deg=90.0)])
def test_hard_parameters_stay_finite_and_normalised(kw):
    L = studio_map(Studio(**kw))
    assert np.isfinite(L).all() and (L >= 0).all()
    assert irradiance(L, front_normals()).mean() == pytest.approx(np.pi, rel=1e-5)
    if kw.get("key_share") == 0.0:  # ambient only: no azimuth is preferred
        assert np.allclose(L[:, 0], L[:, 100], rtol=1e-5)


@pytest.mark.parametrize("kw,what", [(dict(key_share=0.7, fill_share=0.4), "shares"), (dict(key_size_deg=0.0), "sizes")])
def test_bad_studio_parameters_are_refused(kw, what):
    with pytest.raises(ValueError, match=what):
        Studio(**kw)


def test_config_refuses_shares_over_one(tmp_path):
    from synth.config import load_config
    from synth.errors import SynthError

    with pytest.raises(SynthError, match="studio_key_share"):
        load_config(overrides=["lighting.studio_key_share=0.9", "lighting.studio_fill_share=0.2"])


def test_planned_studio_record_and_rotation_from_the_seed():
    from synth.config import Config, load_config
    from synth.plan.assets import sample_lighting

    rec = sample_lighting(3, 5, Config().lighting)
    assert rec["environment"] == "studio" and rec["rotation_deg"] == 0.0 and rec["key_deg"] == [-35.0, 30.0]
    assert Studio.from_record(rec) == Studio()  # the config defaults are the environment's defaults
    lit = load_config(overrides=["lighting.studio_rotation_deg=[-90,90]"]).lighting
    a, b = (sample_lighting(3, i, lit)["rotation_deg"] for i in (5, 6))
    assert a == sample_lighting(3, 5, lit)["rotation_deg"] and a != b and -90 <= a <= 90


@pytest.mark.blender
@pytest.mark.slow
def test_a_diffuse_sphere_shows_the_predicted_irradiance(tmp_path):
    """A white Lambertian sphere under the studio environment in Cycles (48 px, 64 spp): each
    pixel's radiance is albedo * E(n) / pi, E from the numpy map at the pixel's rendered
    normal. Checks the map's orientation in Blender (rows, azimuth sign), its colour space and
    normalisation; a flipped or mirrored map fails by far more than the noise."""
    pytest.importorskip("bpy")
    from blender_scripts import camera, passes, scene
    from blender_scripts.mesh import link_object, new_triangle_mesh
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world
    from synth.plan.assets import sample_lighting
    from synth.plan.records import lighting_from_json
    from synth.config import load_config

    scene.reset()
    lat, lon = np.meshgrid(np.linspace(-np.pi / 2, np.pi / 2, 65)[1:-1], np.linspace(0, 2 * np.pi, 128, endpoint=False),
                           indexing="ij")
    V = 0.1 * np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], -1).reshape(-1, 3)
    V = np.vstack([V, [[0, 0, -0.1], [0, 0, 0.1]]])
    R, C = lat.shape
    idx = np.arange(R * C).reshape(R, C)
    a, b = idx[:-1], np.roll(idx, -1, 1)[:-1]
    c, d = idx[1:], np.roll(idx, -1, 1)[1:]
    F = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3),
                        np.stack([np.full(C, R * C), idx[0, (np.arange(C) + 1) % C], idx[0]], -1),
                        np.stack([np.full(C, R * C + 1), idx[-1], idx[-1, (np.arange(C) + 1) % C]], -1)])
    mat, _ = asset_scene.single_shader_material("white", "ShaderNodeBsdfDiffuse",
                                                {"Color": (0.8, 0.8, 0.8, 1.0), "Roughness": 0.0})
    me = new_triangle_mesh("sphere", V, F)
    me.shade_smooth()
    link_object("sphere", me, [mat])
    scene.configure_render(RenderSettings(samples=64, denoise=False, device="cpu", max_bounces=4), 48, 48)
    env = sample_lighting(0, 0, load_config(overrides=["lighting.studio_rotation_deg=[40,40]"]).lighting)
    scene.studio_environment(lighting_from_json(env, "test"))
    L = studio_map(Studio.from_record(env))
    cam = camera.make_camera()
    for az, el in ((0.0, 0.0), (120.0, 30.0)):
        camera.set_camera(cam, intrinsics(48, 48, 20.0), invert_rigid(orbit_camera_to_world(az, el, 0.8, np.zeros(3))),
                          48, 48, 0.01, 10.0)
        r = passes.render_view(tmp_path, 1)
        inside = r["rgba"][..., 3] > 0.999
        n = r["normals"][inside].astype(np.float64)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        want = 0.8 * irradiance(L, n) / np.pi
        got = r["rgba"][inside][:, :3].mean(1)
        ratio = np.median(got / want)
        assert inside.sum() > 600 and abs(ratio - 1.0) < 0.05, (az, el, ratio)
        assert np.corrcoef(got, want)[0, 1] > 0.97, (az, el, np.corrcoef(got, want)[0, 1])
        mirrored = 0.8 * irradiance(L, n * np.array([-1.0, 1.0, 1.0])) / np.pi  # the map read mirrored
        assert np.abs(got - want).mean() < 0.5 * np.abs(got - mirrored).mean()
