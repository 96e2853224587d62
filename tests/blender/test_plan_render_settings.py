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
    changed["ci"].update(samples=99, denoise=True, adaptive_sampling=True, adaptive_threshold=0.05)
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
    # a plan made now takes the changed preset
    run_plan(load_config(None, ['render.preset="ci"']), 1, tmp_path / "plan2", seed=3)
    assert load_plan(tmp_path / "plan2").render_settings()["samples"] == 99
