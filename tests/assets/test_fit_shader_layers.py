"""The numpy side of the shader-layer rigs (no Blender): makeup and skin-detail masks
(synth.assets.fit.masks) on the default head, and the iris's eye coordinates
(synth.assets.fit.eyes) on synthetic eyeballs with a known answer."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from synth.assets.fit.eyes import eye_coordinates
from synth.assets.fit.masks import (BEARD_FEATHER_M, JAW_LINE_TOP, distance_to, feather, jaw_line, makeup_masks,
                                    region_mask, segment_distance, skin_detail_mask, skin_only, skin_tint_mask,
                                    soft_region)
from synth.model.meshutil import fit_sphere


@pytest.fixture(scope="module")
def head(default_head):
    hm = default_head
    d = hm.data
    ev = hm.evaluate(np.zeros(d.identity_dims), np.zeros(d.expression_dims), np.zeros((hm.J, 3)))
    return d, ev.vertices[0].astype(np.float64), ev.landmarks["ibug68"][0].astype(np.float64)


# --------------------------------------------------------------------------- building blocks


def test_the_assets_jaw_line_starts_below_the_canthi_and_ends_at_the_chin(head):
    """masks.jaw_line: the jaw contour cut at JAW_LINE_TOP canthus-to-chin heights below each
    lateral canthus (ibug68 0/16 start at the canthi's height), the chin kept, each half evenly
    spaced in arc length; a contour that starts lower than the cut is kept from its start."""
    data, V, lm = head
    J = jaw_line(lm)
    for top, canthus in ((0, 36), (16, 45)):
        assert abs(J[top, 2] - (lm[canthus, 2] - JAW_LINE_TOP * (lm[canthus, 2] - lm[8, 2]))) < 1e-9
    np.testing.assert_allclose(J[8], lm[8], atol=1e-12)
    np.testing.assert_allclose(J[16 - np.arange(17)] * [-1, 1, 1], J, atol=1e-4)  # symmetric like the points
    for half in (J[:9], J[8:]):
        steps = np.linalg.norm(np.diff(half, axis=0), axis=1)
        assert steps.max() < 1.2 * steps.min()
    low = lm.copy()
    low[[0, 16], 2] = lm[8, 2] + 0.5 * (lm[[36, 45], 2] - lm[8, 2])  # a contour starting below the cut
    np.testing.assert_allclose(jaw_line(low)[[0, 16]], low[[0, 16]], atol=1e-12)


def test_feather_distance_and_segment_distance_against_brute_force():
    d = np.array([-1.0, 0.0, 0.1, 0.2, 0.3, 0.5, 9.0])
    np.testing.assert_allclose(feather(d, 0.1, 0.3), [1, 1, 1, 0.5, 0, 0, 0], atol=1e-12)
    assert feather(np.array([0.5]), 0.5, 0.5)[0] == 1.0  # inner == outer: a step, no division by zero
    rng = np.random.default_rng(0)
    V, pts = rng.normal(size=(200, 3)), rng.normal(size=(30, 3))
    np.testing.assert_allclose(distance_to(V, pts), cdist(V, pts).min(1))
    assert np.isinf(distance_to(V, pts[:0])).all()
    a, b = rng.normal(size=3), rng.normal(size=3)
    dense = a + np.linspace(0, 1, 20001)[:, None] * (b - a)
    np.testing.assert_allclose(segment_distance(V, a, b), cdist(V, dense).min(1), atol=1e-4)
    np.testing.assert_allclose(segment_distance(V, a, a), np.linalg.norm(V - a, axis=1))  # zero-length segment


# --------------------------------------------------------------------------- makeup and skin detail


def test_makeup_masks(head):
    data, V, lm = head
    m1, m2 = makeup_masks(data, V, lm, extent=0.6, liner=0.6, wing=False)
    assert m1.shape == m2.shape == (len(V), 4) and m1.min() >= 0 and m1.max() <= 1 and m2.min() >= 0
    off_skin = ~skin_only(data, len(V))
    assert not m1[off_skin].any() and not m2[off_skin, 0].any()
    lips = region_mask(data.regions, ["lips"], len(V)) & ~off_skin
    assert np.all(m1[lips, 0] == 1.0) and m1[:, 0].sum() < 3 * lips.sum()
    assert not m2[:, 1].any() and not m2[:, 2:].any()  # no wing asked for
    # shadow and liner sit above the eyes' corners, blush below them, on both sides
    eyes_z = lm[36:48, 2].mean()
    for col, above in ((1, True), (2, True), (3, False)):
        sel = m1[:, col] > 0.5
        assert sel.sum() > 10 and (np.all(V[sel, 2] > eyes_z - 0.004) if above else np.all(V[sel, 2] < eyes_z))
        assert (V[sel, 0] > 0).any() and (V[sel, 0] < 0).any()
    wider, _ = makeup_masks(data, V, lm, extent=1.0)
    assert (wider[:, 1] > 0.5).sum() > (m1[:, 1] > 0.5).sum()
    _, winged = makeup_masks(data, V, lm, wing=True)
    assert (winged[:, 1] > 0.5).any()


def test_makeup_falls_back_to_the_landmark_lips(head):
    data, V, lm = head
    from types import SimpleNamespace

    no_lips = SimpleNamespace(regions={k: v for k, v in data.regions.items() if k != "lips"})
    m1, _ = makeup_masks(no_lips, V, lm)
    near = distance_to(V, lm[48:60]) < 0.0005
    assert np.all(m1[near & skin_only(data, len(V)), 0] == 1.0)


def test_skin_tint_mask_lies_under_the_eyes_and_on_the_ears(head):
    """masks.skin_tint_mask: X under each eye (below the lower lid's line, within 2 cm of it,
    centred on the nose's side of the lid's middle, both eyes alike), nothing above the lids, on
    the lips, the nose tip or off the skin; Y the ears and a few millimetres around them."""
    data, V, lm = head
    m = skin_tint_mask(data, V, lm)
    assert m.shape == (len(V), 3) and m.min() >= 0 and m.max() <= 1 and not m[:, 2].any()
    assert not m[~skin_only(data, len(V))].any()
    ue = m[:, 0]
    for lower, sign in (((40, 41), 1.0), ((46, 47), -1.0)):
        lid = lm[list(lower)].mean(0)
        side = np.sign(V[:, 0] - lm[27][0]) == np.sign(lid[0] - lm[27][0])
        core = side & (ue > 0.8)
        assert core.sum() > 20
        assert np.all(V[ue > 0, 2] < lid[2] + 1e-9)  # below the lid's line: the shadow is not on the lid above it
        c = V[core].mean(0)
        assert -0.012 < c[2] - lid[2] < -0.002 and np.linalg.norm(V[side & (ue > 0)] - lid, axis=1).max() < 0.03
        assert np.sign(lm[27][0] - lid[0]) * (c[0] - lid[0]) > 0.002  # toward the nose
    assert ue[region_mask(data.regions, ["lips"], len(V))].max() == 0
    assert ue[np.argmin(np.linalg.norm(V - lm[30], axis=1))] == 0
    halves = [(ue > 0.5) & (np.sign(V[:, 0] - lm[27][0]) == s) for s in (-1, 1)]
    assert abs(int(halves[0].sum()) - int(halves[1].sum())) <= 0.1 * max(int(halves[0].sum()), 1)
    ears = region_mask(data.regions, ["ears"], len(V))
    assert ears.sum() > 100 and np.mean(m[ears, 1] > 0.5) > 0.9
    assert np.all(m[~ears, 1][distance_to(V[~ears], V[ears]) > 0.011] == 0)


def test_skin_detail_mask(head):
    data, V, lm = head
    m = skin_detail_mask(data, V, lm)
    assert m.shape == (len(V), 4) and m.min() >= 0 and m.max() <= 1
    skin = skin_only(data, len(V))
    assert not m[~skin].any()
    beard = region_mask(data.regions, ["beard"], len(V))
    assert np.all(m[~beard, 3][distance_to(V[~beard], V[beard]) > 2.5 * BEARD_FEATHER_M] == 0)
    assert np.all(m[region_mask(data.regions, ["lips"], len(V)), 3] == 0)
    assert m[np.argmin(np.linalg.norm(V - lm[30], axis=1)), 0] == 1.0  # the nose tip is in the cheeks+nose zone
    forehead = m[:, 2] > 0.5
    assert forehead.any() and np.all(V[forehead, 2] > lm[36:48, 2].mean() - 0.01)


@pytest.mark.parametrize("reach", [0.0, 0.3, 1.0])
def test_stubble_shadow_follows_the_cheek_line_and_reaches_the_lips(head, reach):
    """The skin-detail beard area (the stubble shadow) ends at the beard's cheek line, the same
    line as the strands (within its fade), and covers the upper lip and the skin under the lower
    lip fully: the 8 mm fade of the region's open edges no longer applies at the lips and nose."""
    from synth.assets.fit.masks import CHEEK_FADE_M, cheek_line

    data, V, lm = head
    a = skin_detail_mask(data, V, lm, reach)[:, 3]
    xs, zs = cheek_line(lm, reach)
    xc = 0.5 * (lm[0, 0] + lm[16, 0])
    above = V[:, 2] - np.interp(np.abs(V[:, 0] - xc), xs, zs)
    assert a[above >= CHEEK_FADE_M].max() == 0.0 and a[above < -0.01].max() == 1.0
    hw = 0.5 * abs(lm[54, 0] - lm[48, 0])
    lip_skin = region_mask(data.regions, ["beard"], len(V)) & (np.abs(V[:, 0] - xc) < 0.8 * hw) & (
        V[:, 1] < lm[51, 1] + 0.02) & (((V[:, 2] > lm[51, 2]) & (V[:, 2] < lm[33, 2])) | (
            (V[:, 2] < lm[57, 2]) & (V[:, 2] > lm[57, 2] - 0.01)))
    assert lip_skin.sum() >= 4 and a[lip_skin].min() > 0.9, a[lip_skin]


def test_beard_area_fades_over_rows_of_vertices(head):
    """The beard area (stubble shadow, and the roots of the whole-region beards) fades over a
    few rows of the region's 7-11 mm triangles: a 0/1 mask ended in their staircase."""
    data, V, lm = head
    inside = region_mask(data.regions, ["beard"], len(V))
    a = soft_region(V, inside, BEARD_FEATHER_M)
    T = np.asarray(data.triangles)
    E = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    cross = E[inside[E[:, 0]] != inside[E[:, 1]]]
    rim_in = np.unique(np.where(inside[cross[:, 0]], cross[:, 0], cross[:, 1]))
    rim_out = np.unique(np.where(inside[cross[:, 0]], cross[:, 1], cross[:, 0]))
    assert len(rim_in) > 50
    assert np.mean((a[rim_in] > 0.1) & (a[rim_in] < 0.9)) > 0.6  # the last row in is partly faded
    assert np.mean(a[rim_out] > 0.05) > 0.4  # and the first row out partly covered
    assert np.median(a[rim_in]) > np.median(a[rim_out]) + 0.3  # the fall is centred on the edge
    deep = inside & (distance_to(V, V[~inside]) > 2 * BEARD_FEATHER_M)
    assert np.percentile(a[deep], 5) > 0.95 and a.max() == 1.0
    assert np.all(a[distance_to(V, V[inside]) > 2.5 * BEARD_FEATHER_M] == 0)
    # degenerate inputs: an empty region, no smoothing
    assert not soft_region(V, np.zeros(len(V), bool), BEARD_FEATHER_M).any()
    np.testing.assert_array_equal(soft_region(V, inside, 0.0), inside.astype(float))


# --------------------------------------------------------------------------- eye coordinates


def _eyeballs(centres, radius=0.012, limbus_deg=30.0, n=2000, seed=0):
    """Two spherical eyeballs looking toward -Y; the iris is the cap within ``limbus_deg``."""
    rng = np.random.default_rng(seed)
    V, regions = [], {}
    for side, c in zip("lr", centres):
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        base = len(V) * n
        V.append(np.asarray(c) + radius * d)
        ang = np.degrees(np.arccos(np.clip(d @ [0.0, -1.0, 0.0], -1, 1)))
        regions[f"eye_{side}"] = base + np.arange(n)
        regions[f"iris_{side}"] = base + np.nonzero(ang <= limbus_deg)[0]
    from types import SimpleNamespace

    V = np.concatenate(V + [np.zeros((5, 3))])  # 5 vertices on no eye
    return SimpleNamespace(regions=regions), V


def test_eye_coordinates_on_synthetic_eyeballs():
    centres = [(0.032, 0.0, 0.0), (-0.032, 0.0, 0.0)]
    data, V = _eyeballs(centres)
    out, info = eye_coordinates(data, V)
    assert np.all(out[-5:] == 9.0)
    for side, c in zip("lr", centres):
        np.testing.assert_allclose(info[side]["centre"], c, atol=1e-6)
        np.testing.assert_allclose(fit_sphere(V[data.regions[f"eye_{side}"]])[0], c, atol=1e-9)
        e, i = data.regions[f"eye_{side}"], data.regions[f"iris_{side}"]
        # the definition, from the true centre: axis to the iris centroid, limbus = widest iris angle
        f = V[i].mean(0) - c
        f /= np.linalg.norm(f)
        q = (V[e] - c) / np.linalg.norm(V[e] - c, axis=1, keepdims=True)
        ang = np.arccos(np.clip(q @ f, -1, 1))
        limbus = np.arccos(np.clip(q[np.isin(e, i)] @ f, -1, 1)).max()
        rho = out[e, 2]
        np.testing.assert_allclose(rho, ang / limbus, atol=1e-5)
        assert rho[np.isin(e, i)].max() == pytest.approx(1.0) and rho.min() < 0.05
        np.testing.assert_allclose(np.hypot(out[e, 0], out[e, 1]), rho, atol=1e-12)
        assert info[side]["limbus_rad"] == pytest.approx(limbus, abs=1e-5)  # rounded to 5 decimals
    # phi is mirrored: a point toward +X (temporal on the left eye, nasal on the right) gets
    # opposite cos(phi) signs on the two eyes, so temporal is cos(phi) < 0 on both
    for side, sgn in (("l", -1.0), ("r", 1.0)):
        e = data.regions[f"eye_{side}"]
        lateral = e[(V[e, 0] - centres["lr".index(side)][0]) > 0.006]
        lateral = lateral[out[lateral, 2] < 1.5]
        assert np.sign(np.median(out[lateral, 0])) == sgn


def test_eye_coordinates_without_iris_regions():
    data, V = _eyeballs([(0.03, 0.0, 0.0), (-0.03, 0.0, 0.0)])
    for s in "lr":
        del data.regions[f"iris_{s}"]
    out, info = eye_coordinates(data, V)
    assert info["l"]["forward"] == [0.0, -1.0, 0.0] and info["l"]["limbus_rad"] == 0.5
    del data.regions["eye_r"]
    out, info = eye_coordinates(data, V)
    assert set(info) == {"l"}


@pytest.mark.parametrize("liner", [0.3, 1.0])
def test_eyeliner_wing_is_a_line_not_blobs(head, liner):
    """The wing is drawn per shading point from affine coordinates (masks.wing_coordinates,
    wing_line) inside a per-vertex envelope: on points sampled over the skin's triangles it is
    a continuous band along its axis and nothing beside it. Drawn per vertex as before (the skin's
    vertices are 2-6 mm apart there), the same wing had gaps along its axis and smudges
    millimetres beside it: the dark dot at the tip of the production sheet's winged liner."""
    from synth.assets.fit.masks import (WING_EDGE_M, WING_TIP_M, wing_coordinates, wing_line, wing_width)

    data, V, lm = head
    T = np.asarray(data.triangles)
    _, m2 = makeup_masks(data, V, lm, liner=liner, wing=True)
    rng = np.random.default_rng(0)
    for uv, corner in zip(wing_coordinates(V, lm), (lm[36], lm[45])):
        face = region_mask(data.regions, ["face"], len(V))
        tris = T[(np.linalg.norm(V[T] - corner, axis=2) < 0.015).any(1) & face[T].all(1)]
        b = rng.dirichlet(np.ones(3), size=(len(tris), 400))
        interp = lambda f: np.einsum("tsk,tk...->ts...", b, f[tris]).reshape(-1, *f.shape[1:])  # noqa: E731
        P, q, env = interp(V), interp(uv), interp(m2[:, 1])
        u, v = q[:, 0], q[:, 1]
        line = wing_line(u, v, liner) * env
        tip = corner + np.array([np.sign(corner[0] - 0.5 * (lm[36, 0] + lm[45, 0])), 1, 1]) * WING_TIP_M
        t = (tip - corner) / np.linalg.norm(tip - corner)
        # seen along the wing's depth axis (toward the viewer), the frontmost skin on its axis: the
        # lids' folds put other sheets of skin under the wing too, and the envelope keeps it off them
        depth = (P - corner) @ np.cross(t, np.cross([0.0, -1.0, 0.0], t) / np.linalg.norm(np.cross([0.0, -1.0, 0.0], t)))
        hw = wing_width(liner) * (1 - 0.75 * np.clip(u, 0, 1))
        axis = np.abs(v) < 0.3 * hw
        front = []
        for k in range(10):
            s = np.flatnonzero(axis & (u >= k / 10) & (u < (k + 1) / 10))
            assert len(s) > 0, k  # samples all along the wing
            front.append(s[np.argmax(depth[s])])
        assert line[front].min() > 0.99, line[front]
        assert line[np.abs(v) > hw + WING_EDGE_M].max() == 0.0
        # the old per-vertex line, interpolated the same way: gaps on the axis or smudges beside it
        old = interp(feather(segment_distance(V, corner, tip), 0.0005 * (1 + liner), 0.0015))
        assert old[front].min() < 0.5 or old[np.abs(v) > 0.002].max() > 0.5


@pytest.mark.parametrize("recession", [0.0, 0.6])
def test_scalp_shadow_covers_where_the_hair_grows(default_head, recession):
    """The skin-detail scalp shadow (masks.scalp_hair_area): 1 on the crown, 0 off the skin and on
    the face beyond the hairline's fade, at most 0.15 within it; a receding hairline bares the front of the scalp in the shadow as in the groom:
    every root the hair groom plants lies where the shadow is full or fading, and with recession
    the shadow is 0 where the groom's rule (masks.hair_grows) plants no hair, 1.5 cm and more
    inside the bare front."""
    from synth.assets.fit.groom import head_frame
    from synth.assets.fit.hair import groom
    from synth.assets.fit.masks import SCALP_FEATHER_M, hair_grows, scalp_hair_area
    from tests.support import asset_scene

    ctx = asset_scene.head_arrays(default_head, "neutral", 64, 1, 0)
    V = np.asarray(ctx.vertices, np.float64)
    hf = head_frame(ctx)
    a = scalp_hair_area(ctx.data, V, hf, recession)
    scalp = region_mask(ctx.data.regions, ["scalp"], len(V))
    assert a.min() >= 0.0 and a.max() <= 1.0 and not a[~skin_only(ctx.data, len(V))].any()
    face = region_mask(ctx.data.regions, ["face"], len(V)) & ~scalp
    assert a[face].max() < 0.15  # the top row of the forehead, at the hairline's fade
    assert a[face & (distance_to(V, V[scalp]) > 2.5 * SCALP_FEATHER_M)].max() == 0.0
    crown = scalp & (V[:, 2] > hf["top"] - 0.03) & (V[:, 1] > hf["centre"][1])  # its back half
    assert crown.sum() > 10 and a[crown].min() == 1.0
    g = groom(ctx, {"id": "short_straight", "params": {"hairline_recession": recession}})
    roots = g.pts[:, 0]
    near = cKDTree(V).query(roots)[1]
    assert np.median(a[near]) == 1.0 and np.mean(a[near] > 0.0) > 0.99
    bare = scalp & ~hair_grows(V, hf, recession)
    if recession == 0.0:
        assert not bare.any()
    else:
        deep = bare & (distance_to(V, V[scalp & ~bare]) > 2.5 * SCALP_FEATHER_M)
        assert deep.sum() > 5 and a[deep].max() == 0.0
        assert not hair_grows(roots, hf, recession).__invert__().any()
