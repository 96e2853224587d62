"""The hair styles added for issue 42 (short back and sides, long layered, locs), groomed by the
worker's numpy groomer on the default head: each does what its name says, measured on the strands."""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.fit import hair
from synth.assets.fit.groom import head_frame
from synth.assets.fit.occlusion import inner_face_triangles, occluding_points
from synth.conventions import spherical_offset
from tests.support import asset_scene


@pytest.fixture(scope="module")
def ctx(default_head):
    return asset_scene.head_arrays(default_head, "neutral", 128, 1, 0)


def _lengths(pts: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(pts, axis=1), axis=2).sum(axis=1)


def test_short_back_and_sides_tapers_from_the_top_to_the_nape(ctx):
    """Top 6 cm, sides 8 mm: strands rooted on the top are about the top's length, those on the
    sides and back below the head's centre about the sides' (the clipper's taper between), and
    hardly any strand is longer than the top's length (the final push-out out of the head
    stretches a few children, as it does those of short_straight). The sides and back lie along
    the scalp at their 1 mm layer, and laying them over it joint by joint (strands.settle)
    stretches them a little: the back's median is 8.8 mm (8.6 if they are not settled; drawn at
    0.85-1 x 8 mm)."""
    g = hair.groom(ctx, {"id": "short_back_and_sides",
                         "params": {"top_length_m": 0.06, "side_length_m": 0.008, "parting": "left"}})
    c = head_frame(ctx)["centre"]
    z = g.pts[:, 0, 2] - c[2]
    L = _lengths(g.pts)
    assert np.median(L[z > 0.06]) > 0.85 * 0.06 and np.percentile(L, 99) <= 0.06 * 1.1
    assert np.median(L[z < -0.03]) < 0.008 * 1.1
    front_half = g.pts[:, 0, 1] < c[1] + 0.02
    assert np.median(L[(z < 0.0) & ~front_half]) < 0.008 * 1.15  # the back, up to the head's centre height
    mid = (z > 0.015) & (z < 0.05) & front_half  # inside the taper: in between, growing with height
    assert 0.008 < np.median(L[mid]) < 0.06
    assert np.corrcoef(z[mid], L[mid])[0, 1] > 0.5


def test_long_layered_ends_at_different_heights(ctx):
    """A layered 40 cm cut (crown layer half as long) against the one-length long_straight cut of
    the same length: strands from the crown are shorter than those from the nape, so the tips
    spread over a taller band (the ends are layers, not one curtain edge), and the cut stands
    further off the head."""
    base = {"length_m": 0.4, "curl": 0.0, "parting": "centre"}
    lay = hair.groom(ctx, {"id": "long_layered", "params": {**base, "layer_ratio": 0.5}})
    one = hair.groom(ctx, {"id": "long_straight", "params": base})
    c = head_frame(ctx)["centre"]
    z = lay.pts[:, 0, 2] - c[2]
    L = _lengths(lay.pts)
    assert np.median(L[z > 0.07]) < 0.65 * np.median(L[z < -0.05])
    assert np.median(L[z < -0.05]) > 0.85 * 0.4
    spread = lambda g: float(np.subtract(*np.percentile(g.pts[:, -1, 2], [90, 10])))  # noqa: E731
    assert spread(lay) > 1.3 * spread(one)
    assert lay.info["layer_ratio"] == 0.5


def test_locs_are_round_ropes_beside_the_face(ctx):
    """60 locs of 25 cm: every strand stays within its rope's radius of the rope's centre line
    below the scalp part (the rope is round: both section axes are used alike), the rope radius is
    within LOC_RADIUS_M, and no strand lies in front of the eyes, nose or mouth from the front or
    30 degrees to either side."""
    g = hair.groom(ctx, {"id": "locs", "params": {"loc_count": 60, "length_m": 0.25}})
    assert g.info["guides"] == 60
    rb = float(np.clip(hair.LOC_FILL * np.sqrt(hair.LOC_SCALP_AREA_M2 / (np.pi * 60)), *hair.LOC_RADIUS_M))
    assert hair.LOC_RADIUS_M[0] <= rb <= hair.LOC_RADIUS_M[1]
    # the rope part of each strand (after the 8 points along the scalp): strands of one rope share
    # their mid point's neighbourhood; group by the nearest of the rope mid points found by tips
    body = g.pts[:, 9:]
    mid = body[:, body.shape[1] // 2]
    # the strands of one rope lie within 2 rb of each other's mean at every point
    from scipy.cluster.vq import kmeans2

    _, lab = kmeans2(mid, 60, seed=1, minit="++")
    spreads, ratios = [], []
    for k in np.unique(lab):
        sel = body[lab == k]
        if len(sel) < 20:
            continue
        centre = sel.mean(axis=0)
        off = sel - centre
        spreads.append(np.percentile(np.linalg.norm(off, axis=2), 90))
        ev = np.linalg.eigvalsh(np.cov(off[:, off.shape[1] // 2].T))
        ratios.append(ev[1] / max(ev[2], 1e-12))  # the section's two axes (the third: along the rope)
    assert np.median(spreads) < 1.6 * rb and np.median(ratios) > 0.25
    lm = head_frame(ctx)["lm"]
    centre = inner_face_triangles(ctx.data, ctx.vertices, lm, centre_only=True)
    az = np.array([0.0, -30.0, 30.0])
    for cam in 0.5 * (lm[36] + lm[45]) + spherical_offset(az, np.zeros_like(az)):
        assert not occluding_points(g.pts[::3], cam, ctx.vertices, centre).any()


@pytest.mark.parametrize("sid, params", [
    ("short_back_and_sides", {"top_length_m": 0.04, "side_length_m": 0.005, "parting": "none"}),
    ("long_layered", {"length_m": 0.3, "layer_ratio": 0.7, "fringe": True}),
    ("locs", {"loc_count": 25, "length_m": 0.1})])
def test_new_styles_are_deterministic_and_finite(ctx, sid, params):
    a = hair.groom(ctx, {"id": sid, "params": params})
    b = hair.groom(ctx, {"id": sid, "params": params})
    assert np.isfinite(a.pts).all() and np.array_equal(a.pts, b.pts)
