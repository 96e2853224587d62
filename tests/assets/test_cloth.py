"""Folds, drape and collars of the garments (``synth.assets.fit.folds``, ``synth.assets.fit.collars``),
measured on the built shells against the same shells without folds, at the neutral head and at
+-3 SD (``asset_scene`` cases); pure numpy."""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.fit.body import Body, Parts, fit_shell
from synth.assets.fit.collars import LEAF_GAP, RIB_PITCH, rolled_collar, shirt_collar
from synth.assets.fit.folds import DRAPES, NECK_FADE, WAIST_BAND, Drape, Folds
from synth.assets.fit.garment import CLEARANCE, garment_shell
from synth.assets.fit.garment_parts import crew_neckline, torso_shell, vee_neckline
from synth.assets.fit.meshops import oriented_boundary_loops
from synth.geometry.normals import face_normals
from synth.geometry.sdf import SignedDistance
from tests.support import asset_scene

CASES = ("neutral", "id+3_brows", "id-3_brows")
BASE = 0.004


@pytest.fixture(scope="module")
def bodies(default_head):
    return {c: Body.of(asset_scene.head_arrays(default_head, c, resolution=256)) for c in CASES}


def _pair(body: Body, drape: Drape, seed: int = 0):
    """(folded P, smooth P, faces, folds): the same crew-neck T-shirt shell with and without folds."""
    out = []
    folds = None
    for d in (drape, Drape(0.0, drape.wavelength, 0.0)):
        parts = Parts()
        f = Folds(body, np.random.default_rng(seed), BASE, d)
        if d is drape:
            folds = f
        P, F, _ = torso_shell(body, parts, crew_neckline(body, 0.008, 0.0), f, sleeves="short")
        out.append((P, F))
    assert np.array_equal(out[0][1], out[1][1])
    return out[0][0], out[1][0], out[0][1], folds


def _dominant_wavelength(x: np.ndarray, d: np.ndarray, lo: float, hi: float) -> float:
    """The wavelength in [lo, hi] whose cosine/sine pair explains most of ``d`` along ``x``."""
    d = d - d.mean()
    best, arg = -1.0, lo
    for L in np.linspace(lo, hi, 120):
        A = np.stack([np.cos(2 * np.pi * x / L), np.sin(2 * np.pi * x / L)], 1)
        c, *_ = np.linalg.lstsq(A, d, rcond=None)
        p = float(np.sum((A @ c) ** 2))
        if p > best:
            best, arg = p, L
    return float(arg)


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("kind", ["fitted", "loose"])
def test_folds_have_their_height_and_wavelength_where_the_rule_puts_them(bodies, case, kind):
    body = bodies[case]
    drape = DRAPES[kind]
    # the folds alone (the bridge: test_the_cloth_bridges_under_the_chest)
    Pf, Ps, F, folds = _pair(body, Drape(drape.amp, drape.wavelength, 0.0))
    n = Pf - Ps
    d = np.linalg.norm(n, axis=1)
    # outward only: never nearer the skin than the smooth shell
    from synth.assets.fit.attach import body_query

    q = body_query(body.V, body.F, body.skin_tris)
    sf, ss = q.query(Pf).signed, q.query(Ps).signed
    # (but on the boundary loops, spread along themselves after the offset, where the smooth shell
    # itself is inside, and in the crease between arm and torso, where the closest skin flips from
    # one side to the other and which the fit trims)
    inner = np.ones(len(Pf), bool)
    inner[np.concatenate(oriented_boundary_loops(F))] = False
    inner &= ss > CLEARANCE
    from scipy.spatial import cKDTree

    inner &= folds.fields[cKDTree(body.V).query(Ps)[1], 5] > 0.0
    # (0.2 mm: the interpolated normals lean off the closest skin's on curved skin)
    assert (sf[inner] >= ss[inner] - 2e-4).all(), (ss - sf)[inner].max()
    z_neck = folds.z_neck
    # fields at the shell's points (nearest body vertex: only to select regions)
    from scipy.spatial import cKDTree

    _, k = cKDTree(body.V).query(Ps)
    member, hem = folds.fields[k, 0], folds.fields[k, 2]
    torso = member < 0.1
    front = torso & (np.abs(Ps[:, 0] - folds.center[0]) < 0.04) & (Ps[:, 1] < folds.center[1])
    waist = front & (hem > 0.015) & (hem < WAIST_BAND - 0.03)
    # the upper chest in the middle (at the edge of the armpits' reach)
    upper = front & (Ps[:, 2] < z_neck - NECK_FADE) & (Ps[:, 2] > folds.z_chest + 0.01)
    on_loop = np.zeros(len(Pf), bool)
    on_loop[np.concatenate(oriented_boundary_loops(F))] = True
    neck = torso & (Ps[:, 2] > z_neck + 0.008) & ~on_loop  # (the skin under it above the base)
    assert waist.sum() > 20 and upper.sum() > 20
    # height: the waist's crests reach the garment's fold height, the bare neck has none
    assert 0.5 * drape.amp < np.percentile(d[waist], 95) < 1.4 * drape.amp, np.percentile(d[waist], 95)
    assert d[neck].max() < 1e-5 if neck.any() else True
    # where: the waist folds more than the upper chest between the armpits' reach
    assert d[waist].mean() > 1.5 * d[upper].mean(), (d[waist].mean(), d[upper].mean())
    # wavelength: the waist's folds are horizontal, 0.6 of the garment's wavelength apart in z
    lam = _dominant_wavelength(Ps[waist, 2], d[waist], 0.25 * drape.wavelength, 1.5 * drape.wavelength)
    assert abs(lam - 0.6 * drape.wavelength) < 0.25 * 0.6 * drape.wavelength, (lam, 0.6 * drape.wavelength)


@pytest.mark.parametrize("case", CASES)
def test_folds_keep_the_shell_from_folding_over(bodies, case):
    """No face of the folded shell turns over against the smooth one (no visible self-intersection),
    for the garment with the largest folds."""
    Pf, Ps, F, _ = _pair(bodies[case], DRAPES["loose"])
    cos = np.einsum("ij,ij->i", face_normals(Pf, F), face_normals(Ps, F))
    # (but the faces on a boundary loop: the loops are spread along themselves after the offset)
    on_loop = np.zeros(len(Pf), bool)
    on_loop[np.concatenate(oriented_boundary_loops(F))] = True
    inner = ~on_loop[F].any(1)
    # slivers the clips leave (edges of 1-2 mm) may turn over unseen: at most 0.1 % of the area,
    # and no face with all edges over 4 mm
    area = 0.5 * np.linalg.norm(np.cross(Ps[F[:, 1]] - Ps[F[:, 0]], Ps[F[:, 2]] - Ps[F[:, 0]]), axis=1)
    edge = np.linalg.norm(Ps[F] - Ps[np.roll(F, 1, 1)], axis=2).min(1)
    bad = inner & (cos < 0.3)
    assert area[bad].sum() < 1e-3 * area.sum(), area[bad].sum() / area.sum()
    assert not (bad & (edge > 0.004)).any(), edge[bad].max()


def test_the_cloth_bridges_under_the_chest(bodies):
    """Under the chest's high point the front stands off the skin by up to the garment's bridge
    (the cloth hangs from the chest), and above it not at all."""
    for case in CASES:
        body = bodies[case]
        gap = body.bridge_gap
        assert (gap >= 0).all()
        coat = DRAPES["coat"]
        Pf, Ps, F, folds = _pair(body, Drape(0.0, coat.wavelength, coat.bridge))
        fwd = Ps[:, 1] - Pf[:, 1]  # forward (-y) displacement
        above = Ps[:, 2] > folds.z_neck - 0.03
        assert np.abs(fwd[above]).max() < 1e-4  # (0.1 mm: the necklines spread along themselves)
        assert fwd.min() >= -1e-6 and fwd.max() <= coat.bridge + BASE  # (the offset turns forward too)
    # the body with the deepest hollow under its chest: a visible bridge
    assert max(bodies[c].bridge_gap.max() for c in CASES) > 0.008


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("open_front", [False, True])
def test_shirt_collar_leaf_rests_on_the_shirt(bodies, case, open_front):
    body = bodies[case]
    parts = Parts()
    folds = Folds(body, np.random.default_rng(1), BASE, DRAPES["shirt"])
    depth = 0.045 if open_front else 0.0
    P, F, _ = torso_shell(body, parts, vee_neckline(body, 0.006, depth, 0.35), folds, sleeves="long")
    rec = shirt_collar(body, parts, 0, BASE, open_front, (P, F))
    band_P, band_F = parts.P[-3], parts.F[-3]
    G, arcs, over_band = rec["rows"], rec["arcs"], rec["over_band"]
    shell = SignedDistance(P, F, sign="vertex")
    bandq = SignedDistance(band_P, band_F, sign="vertex")
    past = (over_band == 0) & (arcs > 0)  # the leaf's rows over the shirt's shell
    over = (over_band == 1) & (arcs > 0.004)  # over the band (below the fold)
    hs = shell.query(G[past])
    # only where the shell is under the leaf (an open front's V has none)
    on = hs.distance < 0.006
    assert on.mean() > 0.8
    gap = hs.signed[on]
    assert gap.min() > 0.0 and np.percentile(gap, 99) < 0.0025, (gap.min(), np.percentile(gap, 99))
    hb = bandq.query(G[over])
    under = hb.distance < 0.006  # where the band is under the leaf (see the report: +3 SD's back)
    assert under.mean() > 0.7, under.mean()
    ok = (hb.signed[under] > 0.0) & (hb.signed[under] < 0.003)
    assert ok.mean() > 0.9 and hb.signed[under].max() < 0.006, (ok.mean(), np.round(1000 * hb.signed[under][~ok], 1))
    # the leaf hangs down: its edge under its fold all round, and at least 2 cm under it on most of
    # the way round (at -3 SD the chin rests on the chest in front of the neck: there the leaf has
    # no room to fall)
    drop = G[:, 0, 2] - G[:, -1, 2]
    assert drop.min() > 0.0 and (drop > 0.02).mean() > 0.85, (drop.min(), (drop > 0.02).mean())
    assert LEAF_GAP < 0.002


@pytest.mark.parametrize("case", CASES)
def test_turtleneck_roll_is_a_ribbed_fold_on_the_collar(bodies, case):
    body = bodies[case]
    fr = body.frame
    parts = Parts()

    def z(t):
        return np.minimum(fr.z_ring(t) + 0.07, fr.z_cap(t))
    torso_shell(body, parts, z, Folds(body, np.random.default_rng(2), BASE, DRAPES["knit"]), sleeves="long")
    P, F = parts.P[0], parts.F[0]
    rec = rolled_collar(body, parts, 0, z, BASE, 0.005, 0.03, np.random.default_rng(3))
    G, off = rec["rows"], rec["offset"]
    # outside the collar (which stands BASE off the neck here), resting on it: a fabric's thickness
    # plus the gap (6.5 mm, less 1 mm) over it, to 2 cm off the neck (swell, ribs, creases)
    # (where the jaw leaves room for a collar: at -3 SD the chin rests on the chest all round the
    # front and the collar is capped under it; the fit trims what lies in that crease)
    th = fr.theta(G[:, 0])
    room = (fr.z_cap(th) - fr.z_ring(th)) > 0.04
    if case != "id-3_brows":
        assert room.mean() > 0.6
    if room.any():
        h = body.torso_query.query(G[room, 1:].reshape(-1, 3))
        lo = BASE + 0.005 + 0.0015 - 0.001
        assert np.percentile(h.signed, 1) > lo and h.signed.max() < 0.02, (h.signed.min(), h.signed.max())
        # the collar under it: the roll's rows (but the fold) are within 13 mm of the collar's shell
        assert np.percentile(SignedDistance(P, F).query(G[room, 1:].reshape(-1, 3)).distance, 99) < 0.013
    # ribs: the offset round the neck carries the rib pitch
    row = off[:, ROW_RIBS]
    u = np.cumsum(np.r_[0.0, np.linalg.norm(np.diff(G[:, ROW_RIBS], axis=0), axis=1)])
    lam = _dominant_wavelength(u, row, 0.5 * RIB_PITCH, 3 * RIB_PITCH)
    assert abs(lam - RIB_PITCH) < 0.15 * RIB_PITCH, lam
    # creases: the roll's lower half is not a tube (its offset varies by more than the ribs)
    assert np.ptp(off[:, -2]) > 0.002


ROW_RIBS = 3


@pytest.mark.parametrize("case", ["id+3_jaw", "id-3_jaw"])
def test_cloth_is_deterministic(default_head, case):
    out = []
    for _ in range(2):
        ctx = asset_scene.head_arrays(default_head, case, resolution=256, identity_index=5, run_seed=3)
        body = Body.of(ctx)
        for aid, params in (("shirt_collar", {"top_button_open": True}), ("turtleneck", {"fabric": "wool_knit"}),
                            ("hoodie", {"hood_up": False})):
            s = fit_shell(body, garment_shell(body, {"id": aid, "params": params}, ctx.rng("garment")), CLEARANCE)
            out.append((s.P.tobytes(), s.F.tobytes(), s.info))
    half = len(out) // 2
    assert out[:half] == out[half:]


def test_folds_follow_an_expression(default_head):
    """The folds are carried by the binding: after a jaw opening the shell below the neck keeps its
    folded positions exactly, and no vertex goes into the skin."""
    ctx = asset_scene.head_arrays(default_head, "neutral", resolution=256)
    body = Body.of(ctx)
    s = fit_shell(body, garment_shell(body, {"id": "hoodie", "params": {"hood_up": False}}, ctx.rng("garment")),
                  CLEARANCE)
    V = np.array(ctx.vertices)
    chin = V[:, 2] > body.frame.center[2]
    V[chin] += np.array([0.0, -0.004, -0.01])  # the head moved (the body below the neck did not)
    P = s.follow(V, ctx.data.triangles)
    low = s.P[:, 2] < body.frame.center[2] - 0.1
    assert np.array_equal(P[low], s.P[low])
