"""A plan renders with the settings it recorded: a preset changed after the plan was made (issue
41 replaces `production` by a cheaper one) does not change how that plan's frames are rendered."""

from __future__ import annotations

import copy

import pytest

pytest.importorskip("bpy")


def test_a_plan_keeps_its_presets_settings_after_the_preset_changes(tmp_path, monkeypatch):
    from blender_scripts import scene as bscene
    from blender_scripts.worker import IdentityScene, software_versions
    from synth import config
    from synth.config import load_config
    from synth.model.head import HeadModel
    from synth.plan.io import load_plan
    from synth.plan.planner import run_plan
    from synth.plan.records import RenderSettings

    cfg = load_config(None, ['render.preset="ci"', "dataset.expressions_per_identity=1",
                             "dataset.views_per_expression=1"])
    run_plan(cfg, 1, tmp_path / "plan", seed=3)
    before = load_plan(tmp_path / "plan").render_settings()
    changed = copy.deepcopy(config.RENDER_PRESETS)
    changed["ci"].update(samples=99, denoise=True, adaptive_sampling=True, adaptive_threshold=0.05,
                         diffuse_bounces=1, transparent_bounces=2, hair_shape="thick", light_tree=False,
                         path_guiding=True)
    monkeypatch.setattr(config, "RENDER_PRESETS", changed)  # the preset as a later release defines it
    plan = load_plan(tmp_path / "plan")
    assert plan.render_settings() == before and before["samples"] == 4 and before["denoise"] is False
    spec = plan.shard_spec(plan.shard_ids()[0])
    hm = HeadModel(plan.model_data())
    sc = IdentityScene(spec.identities[0], hm, RenderSettings.from_json(plan.render_settings()), spec.run_seed,
                       {"name": hm.data.name, "sha256": plan.model_sha256()}, software_versions(), plan.shard_ids()[0])
    try:
        e = spec.identities[0].expressions[0]
        sc.set_expression(e)
        _, fj = sc.render(e.frames[0], tmp_path)
    finally:
        sc.close()
        bscene.reset()
    r = fj["render"]  # what the frame JSON says rendered it: the plan's settings
    assert r["preset"] == "ci" and r["samples"] == 4 and r["denoise"] is False and r["adaptive"] is False
    # ... and Cycles' own light paths, as before the preset could set them
    assert (r["diffuse_bounces"], r["transparent_bounces"], r["hair_shape"], r["light_tree"]) == (4, 8, "ribbons", True)
    assert r["path_guiding"] is False
    # a plan made now takes the changed preset
    run_plan(load_config(None, ['render.preset="ci"']), 1, tmp_path / "plan2", seed=3)
    new = load_plan(tmp_path / "plan2").render_settings()
    assert new["samples"] == 99 and new["diffuse_bounces"] == 1 and new["hair_shape"] == "thick"
    s = RenderSettings.from_json(new)
    assert (s.diffuse_bounces, s.transparent_bounces, s.hair_shape, s.light_tree) == (1, 2, "thick", False)


def test_unset_light_paths_are_cycles_own_and_set_ones_reach_the_engine():
    """RenderSettings' defaults are what a fresh Cycles scene has (a plan without them renders as
    plans did before they were settings); set ones are applied and recorded."""
    import bpy

    from blender_scripts import scene as bscene
    from synth.plan.records import RenderSettings

    bscene.reset()
    c, scene = bpy.context.scene.cycles, bpy.context.scene
    factory = (c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces, c.transparent_max_bounces,
               c.use_light_tree, c.caustics_reflective, c.caustics_refractive, scene.cycles_curves.shape,
               c.denoising_prefilter, c.denoising_quality)
    eff = bscene.configure_render(RenderSettings(samples=4, denoise=True, device="cpu"), 16, 16)
    assert (c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces, c.transparent_max_bounces,
            c.use_light_tree, c.caustics_reflective, c.caustics_refractive, scene.cycles_curves.shape,
            c.denoising_prefilter, c.denoising_quality) == factory
    assert eff["denoise_prefilter"] == "accurate" and eff["hair_shape"] == "ribbons"
    eff = bscene.configure_render(RenderSettings(samples=4, denoise=True, device="cpu", diffuse_bounces=2,
                                                 glossy_bounces=1, transmission_bounces=6, transparent_bounces=3,
                                                 hair_shape="thick", light_tree=False, caustics=False,
                                                 denoise_prefilter="fast", denoise_quality="balanced"), 16, 16)
    assert (c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces, c.transparent_max_bounces) == (2, 1, 6, 3)
    assert not c.use_light_tree and not c.caustics_reflective and not c.caustics_refractive
    assert scene.cycles_curves.shape == "THICK" and (c.denoising_prefilter, c.denoising_quality) == ("FAST", "BALANCED")
    assert (eff["diffuse_bounces"], eff["transparent_bounces"], eff["hair_shape"], eff["caustics"],
            eff["denoise_quality"]) == (2, 3, "thick", False, "balanced")
    bscene.reset()


def _scene(plan, render_overrides: dict | None = None):
    from blender_scripts.worker import IdentityScene, software_versions
    from synth.model.head import HeadModel
    from synth.plan.records import RenderSettings

    spec = plan.shard_spec(plan.shard_ids()[0])
    hm = HeadModel(plan.model_data())
    rs = RenderSettings.from_json({**plan.render_settings(), **(render_overrides or {})})
    sc = IdentityScene(spec.identities[0], hm, rs, spec.run_seed, {"name": hm.data.name, "sha256": plan.model_sha256()},
                       software_versions(), plan.shard_ids()[0])
    return sc, spec.identities[0].expressions[0]


def test_path_guided_frames_do_not_depend_on_threads_or_on_the_view_before(tmp_path):
    """Path guiding learns from the samples of the frame being rendered; with its deterministic
    training a frame is the same pixels whatever the thread count and whatever the persistent scene
    rendered before it (the project's rule for every frame)."""
    import bpy
    import numpy as np

    from blender_scripts import scene as bscene
    from synth.config import load_config
    from synth.plan.io import load_plan
    from synth.plan.planner import run_plan

    run_plan(load_config(None, ['render.preset="ci"', "render.samples=16", "render.path_guiding=true",
                                "dataset.expressions_per_identity=1", "dataset.views_per_expression=2"]),
             1, tmp_path / "plan", seed=5)
    plan = load_plan(tmp_path / "plan")
    assert plan.render_settings()["path_guiding"] is True

    def frames(threads: int, views: list[int], overrides=None):
        sc, e = _scene(plan, overrides)
        try:
            sc.set_expression(e)
            bpy.context.scene.render.threads_mode, bpy.context.scene.render.threads = "FIXED", threads
            outs = [sc.render(e.frames[v], tmp_path) for v in views]
        finally:
            sc.close()
            bscene.reset()
        return [o[0]["rgba"] for o in outs], outs[-1][1]

    (_, after_v0), fj = frames(2, [0, 1])
    assert fj["render"]["path_guiding"] is True
    (alone,), _ = frames(1, [1])
    assert np.array_equal(after_v0, alone)
    (plain,), fj = frames(1, [1], {"path_guiding": False})  # guiding does change the pixels it is said to change
    assert fj["render"]["path_guiding"] is False and not np.array_equal(plain, alone)
    assert np.array_equal(plain[..., 3] > 0.5, alone[..., 3] > 0.5) or np.mean(plain[..., 3] != alone[..., 3]) < 0.02
