"""The band under the eyebrow strands (synth.assets.fit.eyebrows.band), without Blender: it lies
where the strands grow, in the brow's style, follows the skin under expressions, makes up the
optical depth the strands lack at each resolution, and is deterministic. The rendered band:
tests/blender/test_brow_band.py."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance import pigment as pig
from synth.assets.fit import eyebrows as fe
from synth.assets.fit.strands import Surface
from tests.support import asset_scene

NATURAL = {"thickness": 0.9, "density": 0.9, "arch": 0.3, "colour": "dark_brown"}


def _band(hm, sid="natural", params=NATURAL, case="neutral", resolution=256):
    ctx = asset_scene.head_arrays(hm, case, resolution)
    entry = {"id": sid, "params": dict(params)}
    g = fe.groom(ctx, entry)
    return ctx, g, fe.band(ctx, entry, g)


def _skin_samples(ctx, n=60000):
    """Area-uniform points on the brow and face triangles within 4 cm of the brows: (triangles,
    barycentrics, points). Fixed generator: the same points for every band compared."""
    surface = Surface(ctx)
    lm = ctx.landmarks["ibug68"]
    tris = surface.region_triangles(("brow", "face"), "any")
    cen = surface.V[surface.T[tris]].mean(1)
    tris = tris[np.linalg.norm(cen[:, None] - lm[None, 17:27], axis=2).min(1) < 0.04]
    tri, bary = surface.sample(tris, n, np.random.default_rng(0))
    return surface, tri, bary, surface.points(tri, bary)


def _interpolated(surface, tri, bary, coords):
    """The coordinates as the shader reads them: linear over each triangle."""
    return np.einsum("nk,nkd->nd", bary, coords[surface.T[tri]])


def test_the_band_covers_the_strands_roots_and_nothing_far_away(default_head):
    ctx, g, b = _band(default_head)
    surface = Surface(ctx)
    roots = _interpolated(surface, g.tri, g.bary, b.coords)
    cov = fe.band_coverage(roots, b.depth)
    assert np.median(cov) > 0.5 and np.mean(cov > 0.2) > 0.9, np.percentile(cov, [5, 50])
    lm = ctx.landmarks["ibug68"]
    far = np.linalg.norm(ctx.vertices[:, None] - lm[None, 17:27], axis=2).min(1) > 0.03
    assert far.sum() > 1000 and fe.band_coverage(b.coords[far], b.depth).max() == 0.0
    # the eyes, below the brows, stay bare
    eyes = np.asarray(ctx.data.regions["eyes"])
    assert fe.band_coverage(b.coords[eyes], b.depth).max() < 1e-6


def _covered_area(hm, params, case="neutral"):
    ctx, g, b = _band(hm, params=params, case=case)
    surface, tri, bary, _ = _skin_samples(ctx)
    cov = fe.band_coverage(_interpolated(surface, tri, bary, b.coords), b.depth)
    return float(cov.mean()), float((cov > 0.5).mean())


def test_thickness_and_density_change_the_band_monotonically(default_head):
    by_thick = [_covered_area(default_head, dict(NATURAL, thickness=t))[1] for t in (0.4, 0.9, 1.5)]
    assert by_thick[0] < by_thick[1] < by_thick[2] and by_thick[2] > 2 * by_thick[0], by_thick
    by_dens = [_covered_area(default_head, dict(NATURAL, density=d))[0] for d in (0.3, 0.9, 1.4)]
    assert by_dens[0] < by_dens[1] < by_dens[2], by_dens


def test_arch_lifts_the_middle_of_the_band(default_head):
    z = {}
    for arch in (0.0, 0.8):
        ctx, g, b = _band(default_head, params=dict(NATURAL, arch=arch))
        surface, tri, bary, p = _skin_samples(ctx)
        c = _interpolated(surface, tri, bary, b.coords)
        cov = fe.band_coverage(c, b.depth) * (np.abs(c[:, 0] - 0.5) < 0.15)
        z[arch] = float((cov * p[:, 2]).sum() / cov.sum())
    assert z[0.8] - z[0.0] > 0.003, z  # (0.8 - 0.0) x 8 mm x sin(...) ~ 6 mm at the middle


def _offsets(p, cov, c, roots, rc):
    """Per brow and fifth of its length: the band's coverage-weighted height less the mean height
    of ``roots`` (strand points, (N, 3), at brow coordinates ``rc``) (m)."""
    out = []
    for left in (False, True):
        for k in range(5):
            lo, hi = k / 5, (k + 1) / 5
            sel = (p[:, 0] >= 0) == left
            w = cov * sel * (c[:, 0] >= lo) * (c[:, 0] < hi)
            r = ((roots[:, 0] >= 0) == left) & (rc[:, 0] >= lo) & (rc[:, 0] < hi)
            out.append((w * p[:, 2]).sum() / w.sum() - roots[r, 2].mean())
    return np.array(out)


@pytest.mark.parametrize("built,case", [("neutral", "brows"), ("id+3", "id+3_brows"), ("id-3", "id-3_brows")])
def test_the_band_follows_a_brow_raise(default_head, built, case):
    """Built on a face at rest, then the brows raised (the worker changes expressions in place):
    the band, carried by the vertices, lies where the strands are and rises with the brows as
    their roots do, along the whole brow, to a millimetre (the skin stretches under the raise)."""
    hm = default_head
    ctx, g, b = _band(hm, case=built)
    surface, tri, bary, p0 = _skin_samples(ctx)
    c = _interpolated(surface, tri, bary, b.coords)
    cov = fe.band_coverage(c, b.depth)
    rc = _interpolated(surface, g.tri, g.bary, b.coords)
    hair = _offsets(p0, cov, c, g.pts.mean(1), rc)
    assert np.abs(hair).max() < 0.002, hair  # the band is where the hairs are
    before = _offsets(p0, cov, c, surface.points(g.tri, g.bary), rc)
    lm0 = ctx.landmarks["ibug68"][17:27].copy()
    asset_scene.set_case_arrays(ctx, hm, case)
    moved = Surface(ctx)
    p1 = moved.points(tri, bary)
    rise_lm = float((ctx.landmarks["ibug68"][17:27] - lm0)[:, 2].mean())
    rise_band = float((cov * (p1[:, 2] - p0[:, 2])).sum() / cov.sum())
    assert rise_lm > 0.003 and rise_band > 0.5 * rise_lm, (rise_lm, rise_band)  # the expression does raise them
    after = _offsets(p1, cov, c, moved.points(g.tri, g.bary), rc)
    assert np.abs(after - before).max() < 0.001, after - before  # a band left in place: the rise, 3-5 mm


def test_the_band_tops_up_the_strands_to_the_styles_depth(default_head):
    """The strands' share grows with the resolution (their count does); the band makes up the
    rest, so the total is the style's at every resolution."""
    got = {}
    for res in (256, 512):
        _, _, b = _band(default_head, resolution=res)
        got[res] = b.record
        assert b.record["optical_depth"] + b.record["strand_depth"] == pytest.approx(
            fe.BAND_DEPTH * NATURAL["density"], abs=2e-4)
    assert got[512]["strand_depth"] > got[256]["strand_depth"] and got[512]["optical_depth"] < got[256]["optical_depth"]


def test_the_band_is_deterministic_and_leaves_the_strands_as_they_were(default_head):
    a = _band(default_head)
    b = _band(default_head)
    assert a[2].coords.tobytes() == b[2].coords.tobytes() and a[2].record == b[2].record
    assert a[1].pts.tobytes() == b[1].pts.tobytes()


@pytest.mark.parametrize("case", ["id+3_jaw", "id-3_jaw"])
def test_extreme_identities_get_a_band_on_their_brows(default_head, case):
    for sid, params in (("bushy", {"thickness": 1.6, "density": 1.4, "monobrow": True, "colour": "black"}),
                        ("thin_arched", {"thickness": 0.35, "arch": 0.9, "colour": "brown"})):
        ctx, g, b = _band(default_head, sid, params, case=case)
        assert np.all(np.isfinite(b.coords)) and b.depth > 0
        roots = _interpolated(Surface(ctx), g.tri, g.bary, b.coords)
        assert np.median(fe.band_coverage(roots, b.depth, b.mono_share)) > 0.4, (case, sid)


def test_the_monobrow_bridges_the_glabella(default_head):
    mid = {}
    for mono in (False, True):
        ctx, g, b = _band(default_head, "bushy", {"thickness": 1.5, "density": 1.2, "monobrow": mono})
        lm = ctx.landmarks["ibug68"]
        centre = 0.5 * (lm[21] + lm[22])
        near = np.linalg.norm(ctx.vertices - centre, axis=1) < 0.004
        mid[mono] = fe.band_coverage(b.coords[near], b.depth, b.mono_share).max()
    assert mid[False] < 0.05 and mid[True] > 0.3, mid


def test_band_colour_follows_the_pigment():
    lum = {n: float(np.dot(fe.band_colour(p), (0.2126, 0.7152, 0.0722))) for n, p in pig.COLOURS.items()}
    assert lum["black"] < lum["dark_brown"] < lum["brown"] < lum["light_brown"] < lum["blonde"]
    assert lum["black"] < 0.05 and lum["brown"] < lum["grey"] < lum["white"]
    white = np.array(fe.band_colour(pig.COLOURS["white"]))
    assert white.max() - white.min() < 0.1 * white.mean()  # a grey, not a tint
    r, gg, bb = fe.band_colour(pig.COLOURS["red"])
    assert r > 2 * gg > 2 * bb
