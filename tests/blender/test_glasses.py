"""The glasses rig in Blender: its meshes are the contact solver's parts (after build and after
an expression change), every material carries the glasses segmentation id, and it is
deterministic."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from synth.assets.classes import CLASSES
from synth.assets.fit.glasses.solve import FRAME_PARTS, fit_glasses
from synth.assets.fit.glasses.spec import frame_spec
from tests.support import asset_scene

pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]


def test_glasses_rig_meshes_are_the_fit():
    """The rig's two objects hold the solver's parts (after build and after an update), every
    material carries the glasses segmentation id, and the record is the fit's."""
    mod = importlib.import_module("blender_scripts.assets.glasses")
    ctx, hm = asset_scene.head_context("id-3_jaw", identity_index=4, run_seed=2)
    entry = {"id": "browline", "params": {"frame_colour": "tortoise"}}
    rig = mod.build(ctx, entry)
    spec = frame_spec("browline", entry["params"], ctx.rng("glasses"))
    for stage in ("build", "update"):
        if stage == "update":
            asset_scene.set_case(ctx, hm, "id-3_brows")
            rig.update(ctx)
        fit = fit_glasses(ctx.vertices, ctx.data.triangles, ctx.data.regions, ctx.landmarks, spec)
        fv = np.concatenate([fit.parts[k][0] for k in FRAME_PARTS if k in fit.parts and len(fit.parts[k][0])])
        got_f, _ = asset_scene.evaluated_mesh(rig.objects[0])
        got_l, _ = asset_scene.evaluated_mesh(rig.objects[1])
        assert np.array_equal(got_f, fv.astype(np.float32).astype(np.float64)), stage
        assert np.array_equal(got_l, fit.parts["lens"][0].astype(np.float32).astype(np.float64)), stage
        assert all(rig.record()[k] == v for k, v in fit.info.items()), stage
    for ob in rig.objects:
        assert all(m.pass_index == CLASSES["glasses"].segmentation_id == 10 for m in ob.data.materials)


def test_glasses_rig_deterministic():
    mod = importlib.import_module("blender_scripts.assets.glasses")
    out = []
    for _ in range(2):
        ctx, _ = asset_scene.head_context("neutral", identity_index=3, run_seed=11)
        rig = mod.build(ctx, {"id": "cat_eye", "params": {"wing_lift": 0.6}})
        out.append((asset_scene.evaluated_mesh(rig.objects[0])[0], rig.record()))
    np.testing.assert_array_equal(out[0][0], out[1][0])
    assert out[0][1] == out[1][1]
