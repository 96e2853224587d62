"""Glasses: the contact solver (pure numpy, ``synth.assets.fit.glasses``) on the hard cases
(the Blender rig: tests/blender/test_glasses.py).

Contact is measured independently of the solver's own bookkeeping: distances with
``trimesh.triangles.closest_point`` on candidate head triangles, the inside/outside side by
ray parity (robust where the +-3 SD heads fold over themselves), on every vertex of the
built geometry.
"""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.fit.glasses.contact import head_surface
from synth.assets.fit.glasses.front import build_front
from synth.assets.fit.glasses.solve import FRAME_PARTS, fit_glasses
from synth.assets.fit.glasses.spec import STYLES, frame_spec
from tests.support import asset_scene

PEN_MAX = 0.0005  # m
NOSE_MAX = 0.002
EAR_MAX = 0.004


def _head(hm, case):
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

@pytest.mark.parametrize("case", ["id+3_brows"])
def test_fit_all_styles_pure(default_head, case):
    data, verts, lms = _head(default_head, case)
    surf = head_surface(verts, data.triangles)
    for style in STYLES:
        spec = frame_spec(style, {}, np.random.default_rng(3))
        fit = fit_glasses(verts, data.triangles, data.regions, lms, spec, surface=surf)
        allv = np.concatenate([v for v, _ in fit.parts.values()])
        assert np.isfinite(allv).all()
        assert fit.info["nose_gap_m"] < NOSE_MAX, (style, fit.info)
        assert fit.info["min_clearance_m"] > -PEN_MAX, (style, fit.info)
        assert fit.info["ear_rest_offset_m"] < EAR_MAX, (style, fit.info)
        assert 0.09 < min(fit.info["temple_length_m"]) and max(fit.info["temple_length_m"]) < 0.2


def _inside_by_parity(P, tris, direction=(0.3141, 0.5926, 0.7418)):
    """Inside test by ray parity (odd number of crossings of a fixed ray; Moller-Trumbore on
    every triangle), independent of the triangles' winding."""
    d = np.asarray(direction) / np.linalg.norm(direction)
    a, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    inside = []
    for p in P:
        s = p - a
        u = np.einsum("ij,ij->i", s, h) / det
        q = np.cross(s, e1)
        v = (q @ d) / det
        t = np.einsum("ij,ij->i", e2, q) / det
        inside.append(int(((u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)).sum()) % 2 == 1)
    return np.array(inside)


def _lens_faces_outward(V, F, stride: int = 31):
    """Fraction of (every ``stride``-th) lens faces whose normal points out of the solid: a point
    just off the face along its normal is outside, just off against it inside (ray parity)."""
    import trimesh

    m = trimesh.Trimesh(V, F, process=False)
    assert m.is_watertight and m.is_winding_consistent
    tri = V[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    c = tri.mean(1)[::stride]
    eps = 2e-4  # m, well under the lens thickness (1.8-2.2 mm)
    out, inn = _inside_by_parity(c + eps * n[::stride], tri), _inside_by_parity(c - eps * n[::stride], tri)
    return float(np.mean(~out & inn))


def test_lenses_are_closed_and_wound_outward(default_head):
    """Cycles decides entering vs leaving glass by the side of the geometric normal: lenses wound
    inward refract as if leaving the glass and reflect totally beyond ~42 degrees (issue 13's
    white discs). Every face of both lenses, every style, in frame space and fitted on a head."""
    data, verts, lms = _head(default_head, "neutral")
    for style in STYLES:
        spec = frame_spec(style, {}, np.random.default_rng(7))
        front = build_front(spec)
        fit = fit_glasses(verts, data.triangles, data.regions, lms, spec, front=front)
        for where, (V, F) in (("frame space", (front.lens_V, front.lens_F)), ("fitted", fit.parts["lens"])):
            assert _lens_faces_outward(np.asarray(V, np.float64), np.asarray(F)) > 0.99, (style, where)


def test_fit_deterministic_and_spec_from_params(default_head):
    data, verts, lms = _head(default_head, "neutral")
    spec = frame_spec("aviator", {"lens_width_m": 0.056, "lens_tint": 0.4, "frame_colour": "gold"},
                         np.random.default_rng(5))
    assert spec.double_bridge and spec.material == "metal" and spec.lens_w == 0.056 and spec.tint == 0.4
    a = fit_glasses(verts, data.triangles, data.regions, lms, spec)
    b = fit_glasses(verts, data.triangles, data.regions, lms, spec)
    for k in a.parts:
        np.testing.assert_array_equal(a.parts[k][0], b.parts[k][0])
    with pytest.raises(ValueError):
        frame_spec("monocle", {}, np.random.default_rng(0))


def test_lens_coating_drawn_after_the_other_draws_and_pinnable():
    """A quarter of lenses (AR_SHARE) are uncoated, reflecting 4 % per surface (the Fresnel
    reflectance of the lens index); coated ones 0.3-1.2 %. The two draws come after all others,
    so every other field is what the same generator gave before they existed; the manifest can
    pin both, and a wrong value is refused."""
    from synth.assets.fit.glasses import spec as gs

    assert gs.reflectance_ior(gs.UNCOATED_REFLECTANCE) == pytest.approx(gs.LENS_IOR)
    assert gs.reflectance_ior(0.0) == 1.0
    specs = [frame_spec("round", {}, np.random.default_rng(s)) for s in range(400)]
    coated = np.array([sp.coating == "anti_reflective" for sp in specs])
    assert abs(coated.mean() - gs.AR_SHARE) < 0.07, coated.mean()
    r = np.array([sp.lens_reflectance for sp in specs])
    lo, hi = gs.AR_REFLECTANCE
    assert np.all((r[coated] >= lo) & (r[coated] <= hi)) and r[coated].max() - r[coated].min() > 0.5 * (hi - lo)
    assert np.all(r[~coated] == pytest.approx(0.04))
    for s in range(5):  # the earlier draws are unchanged: the generator's first 8 values
        rng = np.random.default_rng(s)
        first = [rng.uniform(0.046, 0.054), rng.uniform(0.03, 0.038), rng.uniform(0.002, 0.005),
                 rng.uniform(0.016, 0.021), rng.uniform(6.0, 10.0), rng.uniform(2.0, 6.0)]
        sp = specs[s]
        assert (sp.lens_w, sp.bridge, sp.pantoscopic_deg, sp.wrap_deg) == (first[0], first[3], first[4], first[5])
    pinned = frame_spec("round", {"lens_coating": "none"}, np.random.default_rng(0))
    assert pinned.coating == "none" and pinned.lens_reflectance == pytest.approx(0.04)
    pinned = frame_spec("round", {"lens_coating": "anti_reflective", "lens_reflectance": 0.002},
                        np.random.default_rng(0))
    assert pinned.lens_reflectance == 0.002 and pinned.record()["coating"] == "anti_reflective"
    with pytest.raises(ValueError, match="lens_coating"):
        frame_spec("round", {"lens_coating": "mirror"}, np.random.default_rng(0))
    with pytest.raises(ValueError, match="lens_reflectance"):
        frame_spec("round", {"lens_reflectance": 0.5}, np.random.default_rng(0))


@pytest.mark.slow
def test_fit_contact_on_hard_cases(default_head):
    """Every style built at one hard case (the rig's own parameters and generator) and re-fitted
    at another, measured independently of the solver (``contact_report``)."""
    hm = default_head
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
