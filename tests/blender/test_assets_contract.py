"""The contract every registered asset class keeps (one parametrized test over the registry):

Each class is checked on three models: the embedded default, the ICT-FaceKit sample
(imported from ``shared/ict-facekit``; skipped when absent) and the default remeshed (1-to-4
subdivided and shuffled: :func:`tests.support.models.remeshed`), so that no rig leans on one
model's vertex order, density or topology.

1. **builds** on the head from a plan entry the planner would write (the first identity
   of a fixed run seed whose sampled assets include the class);
2. **records**: ``rig.record()`` is strict JSON (no NaN), before and after an update, and the
   worker's frame record ``{**entry, "build": record}`` serialises;
3. **updates** after an expression change (same identity, jaw open: what the worker does
   between expressions) with finite geometry; an update on the unchanged head moves nothing, and
   after the change the rig is on the changed head (:func:`_assert_follows`: strand roots on
   their attachment points, and no rig taken off the head);
4. **shows in a tiny render** (64 x 64, 4 samples):
   * geometry classes: every material carries the class's segmentation id, and that id is in
     the segmentation of a view framing the rig's objects or of a close-up of one of their
     points (thin strands), after the build and again after the update;
   * shader-layer classes (skin, iris, makeup) add no object: they edit the head's materials,
     so their pixels carry the host's id (skin 1, eyes 2). Their check: the record is not
     empty, and with the same camera and seed, at least 5 pixels of the host id change by more
     than 0.01 (linear RGB) between the bare head and the dressed one.
"""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest

from synth.assets.classes import CLASSES, NAMES
from synth.plan.records import RenderSettings

bpy = pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

SIZE, SAMPLES, FOV = 64, 4, 30.0
CHANGED_PIXELS, CHANGE = 5, 0.01
ATTACHED_M, FOLLOW_M, STILL_M, ROOT_M = 0.01, 0.002, 1e-5, 1e-6


MODELS = ("default", "ict-facekit", "remeshed")


def _model(name: str):
    """The HeadModelData of a MODELS name (None: the embedded default)."""
    from tests.support import models

    if name == "ict-facekit":
        return models.ict_model()
    if name == "remeshed":
        return _remeshed_default()
    return None


@functools.lru_cache(maxsize=1)
def _remeshed_default():
    from synth.model.default import load_default_model
    from tests.support.models import remeshed

    return remeshed(load_default_model(), seed=3)


@pytest.fixture(scope="module")
def entries():
    from synth.assets.catalogue import load_catalogue
    from synth.plan.assets import sample_assets_batch

    picks = sample_assets_batch(11, range(400), load_catalogue())
    return {c: next(p[c] for p in picks if p[c] is not None) for c in NAMES}


def _render(ctx, tmp, target, radius, near=0.01):
    from blender_scripts import camera, passes, scene
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world

    scene.configure_render(RenderSettings(samples=SAMPLES, denoise=False, device="cpu"), SIZE, SIZE)
    scene.uniform_environment(1.0)
    cam = bpy.data.objects.get("contract_cam") or camera.make_camera("contract_cam")
    w2c = invert_rigid(orbit_camera_to_world(0.0, 10.0, radius, np.asarray(target, np.float64)))
    camera.set_camera(cam, intrinsics(SIZE, SIZE, FOV, (0.0, 0.0)), w2c, SIZE, SIZE, near, 10.0)
    r = passes.render_view(tmp, 3)
    assert np.isfinite(r["rgba"]).all()
    return r


def _face_view(ctx):
    lm = ctx.landmarks["ibug68"]
    return 0.5 * (lm[39] + lm[42]) + np.array([0.0, 0.0, -0.025]), 0.3


def _points(rig):
    from tests.support import asset_scene

    pts = np.concatenate([asset_scene.evaluated_mesh(ob)[0] for ob in rig.objects])
    assert len(pts) and np.isfinite(pts).all()
    return pts


def _ids_seen(ctx, rig, tmp) -> set[int]:
    """Segmentation ids of a view framing the rig's objects and of a close-up of one point."""
    pts = _points(rig)
    lo, hi = pts.min(0), pts.max(0)
    extent = max(hi[0] - lo[0], hi[2] - lo[2], 0.02)
    radius = 0.65 * extent / np.tan(np.radians(FOV / 2)) + 0.5 * (hi[1] - lo[1])
    seen = set(np.unique(_render(ctx, tmp, 0.5 * (lo + hi), radius)["segmentation"]).tolist())
    near = pts[np.argmin(np.linalg.norm(pts - pts.mean(0), axis=1))]
    seen |= set(np.unique(_render(ctx, tmp, near, 0.015 / np.tan(np.radians(FOV / 2)))["segmentation"]).tolist())
    return seen


def _strict_json(obj) -> str:
    return json.dumps(obj, allow_nan=False)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("cls", NAMES)
def test_asset_class_contract(cls, model, entries, tmp_path):
    from tests.support import asset_scene
    from blender_scripts.assets import dress, update

    spec = CLASSES[cls]
    entry = entries[cls]
    ctx, hm = asset_scene.head_context("neutral", resolution=SIZE, identity_index=5, run_seed=11,
                                       model=_model(model))
    before = _render(ctx, tmp_path, *_face_view(ctx)) if spec.shader_layer else None
    rigs = dress(ctx, {cls: entry})
    assert set(rigs) == {cls}
    rig = rigs[cls]
    rec = rig.record()
    assert rec and _strict_json({**entry, "build": rec})

    if spec.shader_layer:
        assert rig.objects == []
        after = _render(ctx, tmp_path, *_face_view(ctx))
        host = (before["segmentation"] == spec.segmentation_id) & (after["segmentation"] == spec.segmentation_id)
        diff = np.abs(after["rgba"][..., :3].astype(np.float64) - before["rgba"][..., :3].astype(np.float64)).max(-1)
        assert host.sum() > 0 and (diff[host] > CHANGE).sum() >= CHANGED_PIXELS, (cls, entry["id"], host.sum())
    else:
        for ob in rig.objects:
            assert all(m.pass_index == spec.segmentation_id for m in ob.data.materials if m is not None), ob.name
        assert spec.segmentation_id in _ids_seen(ctx, rig, tmp_path), (cls, entry["id"])

    pre = None if spec.shader_layer else _points(rig)
    head_pre = ctx.vertices.copy()
    if not spec.shader_layer:  # an update on the unchanged head leaves the rig where it is
        update(rigs, ctx)
        still = float(np.abs(_points(rig) - pre).max())
        assert still <= STILL_M, (cls, entry["id"], "moved on an unchanged head", still)
    asset_scene.set_case(ctx, hm, "jaw")  # identity 0 as before, jaw open
    update(rigs, ctx)
    assert _strict_json(rig.record())
    if not spec.shader_layer:
        assert spec.segmentation_id in _ids_seen(ctx, rig, tmp_path), (cls, entry["id"], "after update")
        _assert_follows(cls, entry, rig, ctx, head_pre, pre, _points(rig))


def _roots(rig) -> np.ndarray:
    """The first point of every curve of a strand rig's Curves object."""
    cv = rig.ob.data
    pos = np.empty(len(cv.points) * 3, np.float32)
    cv.position_data.foreach_get("vector", pos)
    offsets = np.empty(len(cv.curves) + 1, np.int32)
    cv.curve_offset_data.foreach_get("value", offsets)
    return pos.reshape(-1, 3)[offsets[:-1]].astype(np.float64)


def _assert_follows(cls, entry, rig, ctx, head_pre, pre, moved):
    """After the expression change the rig is on the changed head.

    * Strand rigs (attached by root triangle and barycentrics): every root is on the changed
      surface at its attachment point (within ROOT_M).
    * Every rig: for its points within ATTACHED_M of the head, the distance to the nearest head
      vertex changes (95th percentile) by at most FOLLOW_M more than it would had the rig not
      moved at all: the update never takes a rig off the head."""
    from scipy.spatial import cKDTree

    from synth.assets.fit.strands import Surface

    assert moved.shape == pre.shape, (cls, entry["id"], "the update changed the number of points")
    att = getattr(rig, "attachment", None)
    if att is not None:
        off = np.linalg.norm(_roots(rig) - Surface(ctx).points(att.tri, att.bary), axis=1).max()
        assert off <= ROOT_M, (cls, entry["id"], "roots off their attachment", off)
    d_pre = cKDTree(head_pre).query(pre)[0]
    near = d_pre <= ATTACHED_M
    assert near.any(), (cls, entry["id"], "no point of the rig is near the head")
    tree = cKDTree(ctx.vertices)
    change = float(np.percentile(np.abs(tree.query(moved[near])[0] - d_pre[near]), 95))
    left = float(np.percentile(np.abs(tree.query(pre[near])[0] - d_pre[near]), 95))
    assert change <= left + FOLLOW_M, (cls, entry["id"], change, left)
