"""Glasses: the contact solver (pure numpy, ``synth.assets.fit.glasses``) on the hard cases, and
the Blender rig (its meshes are the solver's parts).

Contact is measured independently of the solver's own bookkeeping: distances with
``trimesh.triangles.closest_point`` on candidate head triangles, the inside/outside side by
ray parity (robust where the +-3 SD heads fold over themselves), on every vertex of the
built geometry.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from synth.assets.classes import CLASSES
from synth.assets.fit.glasses.front import build_front
from synth.assets.fit.glasses.solve import FRAME_PARTS, fit_glasses
from synth.assets.fit.glasses.spec import STYLES, frame_spec
from synth.assets.fit.glasses.surface import Surface
from synth.model.default import load_default_model
from synth.model.head import HeadModel
from tests import asset_scene

PEN_MAX = 0.0005  # m
NOSE_MAX = 0.002
EAR_MAX = 0.004


def _head(case):
    hm = HeadModel(load_default_model())
    beta, psi, rot = asset_scene._codes(hm, case)
    rest, verts, joints, lms = asset_scene._ctx_arrays(hm, beta, psi, rot)
    return hm.data, verts, lms


def contact_report(verts, triangles, regions, lms, frame_v, lateral):
    """(max penetration, nose gap, ear gaps) of world vertices against the head."""
    import trimesh
    from scipy.spatial import cKDTree

    from synth.assets.fit.glasses.contact import HeadQuery, ear_rests, head_basis, nose_faces

    T = np.asarray(triangles, np.int64)
    tris = verts[T]
    tree = cKDTree(tris.mean(1))
    _, cand = tree.query(frame_v, k=24)
    best = np.full(len(frame_v), np.inf)
    for j in range(cand.shape[1]):
        q = trimesh.triangles.closest_point(tris[cand[:, j]], frame_v)
        best = np.minimum(best, np.linalg.norm(q - frame_v, axis=1))
    ears = ear_rests(verts, T, regions)
    B = head_basis(ears, lms["ibug68"])
    hq = HeadQuery(verts, T, B, float(lms["ibug68"][27:31].mean(0) @ B[:, 0]))
    inside = hq.inside(frame_v, lateral)
    pen = float(np.max(np.where(inside, best, 0.0)))
    # nose bridge: head faces near ibug 27-29
    nose_f = nose_faces(verts, T, regions, lms["ibug68"])
    ntree = cKDTree(verts[T[nose_f]].mean(1))
    _, nc = ntree.query(frame_v, k=8)
    nb = np.full(len(frame_v), np.inf)
    for j in range(nc.shape[1]):
        q = trimesh.triangles.closest_point(verts[T[nose_f[nc[:, j]]]], frame_v)
        nb = np.minimum(nb, np.linalg.norm(q - frame_v, axis=1))
    ear_gap = []
    for name, side in (("ear_l", 1), ("ear_r", -1)):
        ev = verts[np.asarray(regions[name])]
        d = cKDTree(ev).query(frame_v[lateral])[0]
        ear_gap.append(float(d.min()))
    return pen, float(nb.min()), ear_gap


def _lateral(frame_v, lens_v):
    """Temple vertices (well behind the lenses) look sideways for the inside test."""
    return frame_v[:, 1] > lens_v[:, 1].max() + 0.012


# ----------------------------------------------------------------------------- pure numpy


def test_closest_point_matches_trimesh():
    import trimesh

    from synth.assets.fit.closest import closest_on_triangles

    rng = np.random.default_rng(0)
    tri = rng.normal(size=(200, 3, 3))
    p = rng.normal(size=(200, 3)) * 2
    q, bary = closest_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])
    ref = trimesh.triangles.closest_point(tri, p)
    np.testing.assert_allclose(q, ref, atol=1e-9)
    np.testing.assert_allclose(bary.sum(1), 1.0, atol=1e-9)


def test_ray_parity_on_a_sphere_with_a_fold():
    import trimesh

    from synth.assets.fit.glasses.surface import RayGrid

    s = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    g = RayGrid(s.vertices, s.faces, [0, 1, 0], cell=0.004)
    rng = np.random.default_rng(1)
    p = rng.uniform(-0.07, 0.07, (500, 3))
    inside = np.linalg.norm(p, axis=1) < 0.05
    sure = np.abs(np.linalg.norm(p, axis=1) - 0.05) > 1e-3
    assert np.all(g.inside(p[sure], -1.0) == inside[sure])
    assert np.all(g.inside(p[sure], 1.0) == inside[sure])


@pytest.mark.parametrize("case", ["id+3_brows"])
def test_fit_all_styles_pure(case):
    data, verts, lms = _head(case)
    surf = Surface(verts, data.triangles)
    for style in STYLES:
        spec = frame_spec(style, {}, np.random.default_rng(3))
        fit = fit_glasses(verts, data.triangles, data.regions, lms, spec, surface=surf)
        allv = np.concatenate([v for v, _ in fit.parts.values()])
        assert np.isfinite(allv).all()
        assert fit.info["nose_gap_m"] < NOSE_MAX, (style, fit.info)
        assert fit.info["min_clearance_m"] > -PEN_MAX, (style, fit.info)
        assert fit.info["ear_rest_offset_m"] < EAR_MAX, (style, fit.info)
        assert 0.09 < min(fit.info["temple_length_m"]) and max(fit.info["temple_length_m"]) < 0.2


def test_fit_deterministic_and_spec_from_params():
    data, verts, lms = _head("neutral")
    spec = frame_spec("aviator", {"lens_width_m": 0.056, "lens_tint": 0.4, "frame_colour": "gold"},
                         np.random.default_rng(5))
    assert spec.double_bridge and spec.material == "metal" and spec.lens_w == 0.056 and spec.tint == 0.4
    a = fit_glasses(verts, data.triangles, data.regions, lms, spec)
    b = fit_glasses(verts, data.triangles, data.regions, lms, spec)
    for k in a.parts:
        np.testing.assert_array_equal(a.parts[k][0], b.parts[k][0])
    with pytest.raises(ValueError):
        frame_spec("monocle", {}, np.random.default_rng(0))


@pytest.mark.slow
def test_fit_contact_on_hard_cases():
    """Every style built at one hard case (the rig's own parameters and generator) and re-fitted
    at another, measured independently of the solver (``contact_report``)."""
    hm = HeadModel(load_default_model())
    hard = asset_scene.CASES[1:]
    results = {}
    for i, style in enumerate(STYLES):
        case, then = hard[i % len(hard)], hard[(i + 1) % len(hard)]
        ctx = asset_scene.head_arrays(hm, case)
        spec = frame_spec(style, {}, ctx.rng("glasses"))
        front = build_front(spec)
        for stage in (case, then):
            if stage != case:
                asset_scene.set_case_arrays(ctx, hm, stage)
            fit = fit_glasses(ctx.vertices, ctx.data.triangles, ctx.data.regions, ctx.landmarks, spec, front=front)
            fv = np.concatenate([fit.parts[k][0] for k in FRAME_PARTS if k in fit.parts])
            lv = fit.parts["lens"][0]
            assert np.isfinite(fv).all() and np.isfinite(lv).all()
            allv = np.concatenate([fv, lv])
            lat = np.concatenate([_lateral(fv, lv), np.zeros(len(lv), bool)])
            pen, nose, ears = contact_report(ctx.vertices, ctx.data.triangles, ctx.data.regions, ctx.landmarks,
                                             allv, lat)
            results[(style, stage)] = (pen, nose, ears)
            assert pen < PEN_MAX, (style, stage, pen)
            assert nose < NOSE_MAX, (style, stage, nose)
            assert max(ears) < EAR_MAX, (style, stage, ears)
    print({k: tuple(np.round(np.r_[v[0], v[1], v[2]] * 1e3, 3)) for k, v in results.items()})


# ----------------------------------------------------------------------------- Blender rig


@pytest.mark.blender
@pytest.mark.slow
def test_glasses_rig_meshes_are_the_fit():
    """The rig's two objects hold the solver's parts (after build and after an update), every
    material carries the glasses segmentation id, and the record is the fit's."""
    pytest.importorskip("bpy")
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


@pytest.mark.blender
@pytest.mark.slow
def test_glasses_rig_deterministic():
    pytest.importorskip("bpy")
    mod = importlib.import_module("blender_scripts.assets.glasses")
    out = []
    for _ in range(2):
        ctx, _ = asset_scene.head_context("neutral", identity_index=3, run_seed=11)
        rig = mod.build(ctx, {"id": "cat_eye", "params": {"wing_lift": 0.6}})
        out.append((asset_scene.evaluated_mesh(rig.objects[0])[0], rig.record()))
    np.testing.assert_array_equal(out[0][0], out[1][0])
    assert out[0][1] == out[1][1]
