"""The body below and beside a garment: the prism under its hem (synth.assets.fit.torso), the bust's
arms under its sleeves, the forearms and hair kept off the sleeves (synth.assets.fit.arms). The
torso and the sleeves against every fitted garment are in tests/assets/test_fit_shells.py."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from synth.assets.fit.body import Body, fit_shell
from synth.assets.fit.garment import CLEARANCE as GARMENT_CLEARANCE
from synth.assets.fit.garment import garment_shell


def test_torso_rejects_bad_input():
    from types import SimpleNamespace

    from synth.assets.fit import torso

    with pytest.raises(ValueError, match="not finite"):
        torso.torso_continuation(np.full((10, 3), np.nan))
    with pytest.raises(ValueError, match="positive"):
        torso.torso_continuation(np.random.default_rng(0).normal(size=(50, 3)), length=0.0)
    capless = SimpleNamespace(P=np.zeros((3, 3)), F=np.array([[0, 1, 2]]), M=np.zeros(1, int), inside=None)
    with pytest.raises(ValueError, match="no hem cap"):
        torso.hem_rim(capless)


@pytest.fixture(scope="module")
def neutral(default_head):
    """(HeadContext arrays, Body) of the neutral default head."""
    from tests.support import asset_scene

    ctx = asset_scene.head_arrays(default_head, "neutral")
    return ctx, Body.of(ctx)


def test_arm_frame_runs_down_each_upper_arm(neutral):
    """The arm frame: t 0 at the armhole's centre and 1 at the elbow loop's, both arms alike
    (the body is mirror-symmetric), membership 1 on the arms and 0 on the torso away from them;
    a model without the arms has none."""
    from synth.assets.fit import arms

    ctx, body = neutral
    fr = body.arms
    V, reg = body.V, body.regions
    for s, sign in (("L", 1.0), ("R", -1.0)):
        elbow = np.asarray(reg[arms.ARM_REGIONS[s][1]])
        np.testing.assert_allclose(fr.t[elbow].mean(), 1.0, atol=1e-9)
        assert fr.elbow[s][0] * sign > fr.shoulder[s][0] * sign * 0.5  # out at the side
        assert 0.18 < fr.length[s] < 0.32 and fr.shoulder[s][2] - fr.elbow[s][2] > 0.15  # hanging down
        assert 0.0 < fr.armpit_t[s] < arms.SHORT_SLEEVE_T - arms.SLEEVE_BELOW_ARMPIT
    assert fr.length["L"] == pytest.approx(fr.length["R"], abs=1e-9)
    arm = fr.side != 0
    assert (fr.member[arm] > 0.3).all() and np.median(fr.member[arm]) > 0.99
    torso = np.asarray(reg["torso"])
    far = torso[np.abs(V[torso, 0]) < 0.05]  # the chest's and back's middle
    assert (fr.member[far] == 0).all()
    no_arms = {k: v for k, v in reg.items() if k not in ("arm_l", "arm_r")}
    assert arms.arm_frame(V, body.F, no_arms) is None and arms.sleeve_field(None, "short") is None


@pytest.mark.parametrize("gid,kind", [("sweater", "long"), ("tshirt_crew", "short"), ("tank_top", "none")])
def test_sleeves_of_each_kind(neutral, gid, kind):
    """A garment's sleeves over the bust's arms: long ones cover each whole upper arm and its elbow,
    short ones end round each arm at SHORT_SLEEVE_T (one boundary loop a side, every vertex at that t),
    none (a tank top) leaves the arms bare, the garment off every arm vertex."""
    from scipy.spatial import cKDTree

    from synth.assets.fit import arms
    from synth.assets.fit.garment import sleeves_of
    from synth.assets.fit.meshops import oriented_boundary_loops

    ctx, body = neutral
    assert sleeves_of(gid) == kind
    s = fit_shell(body, garment_shell(body, {"id": gid, "params": {}}, ctx.rng("garment")), GARMENT_CLEARANCE)
    assert s.info["sleeves"] == kind
    fr = body.arms
    d, _ = cKDTree(s.P).query(body.V)  # each body vertex's nearest garment vertex
    reach = s.info["cloth_reach_m"] + 0.004
    for side, sign in (("L", 1.0), ("R", -1.0)):
        on = fr.side == sign
        mid = on & (np.abs(fr.t - 0.7) < 0.1)  # the lower upper arm, below any short sleeve
        top = on & (np.abs(fr.t - 0.3) < 0.05) & (fr.member > 0.99)  # under a short sleeve
        elbow = np.asarray(body.regions[arms.ARM_REGIONS[side][1]])
        if kind == "long":
            assert (d[mid] < reach).all() and (d[elbow] < reach + 0.01).all()
        elif kind == "short":
            assert np.mean(d[top] < reach) > 0.95 and (d[mid] > 0.01).all()
        else:
            assert (d[top] > 0.01).all() and (d[mid] > 0.01).all()
    if kind == "short":
        # the sleeves' ends: the boundary loops whose base lies on an arm, one a side, at the sleeve's t
        ends = []
        for lo in oriented_boundary_loops(np.asarray(s.F)):
            p = s.P[lo]
            _, nb = cKDTree(body.V).query(p)
            if (fr.side[nb] != 0).mean() > 0.9:
                ends.append((np.sign(p[:, 0].mean()), lo))
        assert sorted(e[0] for e in ends) == [-1.0, 1.0]
        te = s.info["sleeve_end_t"]
        for sign, lo in ends:
            S, E = fr.shoulder["L" if sign > 0 else "R"], fr.elbow["L" if sign > 0 else "R"]
            t = (s.P[lo] - S) @ (E - S) / ((E - S) @ (E - S))
            assert np.abs(t - te).max() < 0.06, (gid, np.abs(t - te).max())


def test_forearms_go_on_from_the_elbows(neutral):
    """Each forearm: a closed, outward tube whose wall at the elbow is the elbow loop (offset outward
    by ``offset``), FOREARM_LENGTH long, hanging FOREARM_BEND_DEG forward of the vertical, tapered."""
    from synth.assets.fit import arms

    ctx, body = neutral
    for offset in (0.0, 0.004):
        V, F = arms.forearms(body.V, body.F, body.regions, offset)
        parts = trimesh.Trimesh(V, F, process=False).split(only_watertight=False)
        assert len(parts) == 2
        for p in parts:
            tm = trimesh.Trimesh(p.vertices, p.faces, process=True)
            assert tm.is_watertight and tm.is_winding_consistent and tm.volume > 0
        for s, sign in (("L", 1.0), ("R", -1.0)):
            loop = body.V[np.asarray(body.regions[arms.ARM_REGIONS[s][1]])]
            c = loop.mean(0)
            mine = V[np.sign(V[:, 0]) == sign]
            # the elbow's ring: every loop vertex within offset + 1 mm of the tube's vertices
            dist = np.linalg.norm(loop[:, None] - mine[None], axis=2).min(1)
            assert dist.max() < offset + 0.012  # the ring is resampled along the loop (40 points)
            end = V[np.sign(V[:, 0]) == sign][-1]  # the end cap's centre (its fan's last vertex)
            d = end - c
            # (c: the mean of the loop's 20 vertices; the tube's: of the 40 resampled along it)
            assert np.linalg.norm(d) == pytest.approx(arms.FOREARM_LENGTH, abs=0.003)
            assert np.degrees(np.arctan2(-d[1], -d[2])) == pytest.approx(arms.FOREARM_BEND_DEG, abs=1.0)
            assert abs(d[0]) < 0.003
    no_arms = {k: v for k, v in body.regions.items() if k not in ("elbow_l", "elbow_r")}
    V, F = arms.forearms(body.V, body.F, no_arms, 0.0)
    assert V.shape == (0, 3) and F.shape == (0, 3)


def test_keep_hair_off_the_arms(neutral):
    """Strands hung over an upper arm from above the shoulder, out of the skin as a groom leaves them
    (1 mm): after ArmKeepOut every point but the roots whose closest skin point is on an arm lies at
    least the clearance off it; points already clear and the roots stay where they were, and the
    count is the points moved; points nearer the torso are not the keep-out's."""
    from synth.assets.fit import arms
    from synth.assets.fit.attach import push_out

    ctx, body = neutral
    clearance = 0.006
    keep = arms.ArmKeepOut(body.V, body.F, body.regions, clearance)
    S = body.arms.shoulder["L"]
    rng = np.random.default_rng(3)
    n = 400
    roots = np.column_stack([S[0] + rng.uniform(-0.08, 0.06, n), S[1] + rng.uniform(-0.06, 0.06, n),
                             np.full(n, S[2] + 0.12)])
    pts = roots[:, None] + np.linspace(0.0, 0.35, 24)[None, :, None] * np.array([0.0, 0.0, -1.0])
    pts = push_out(pts.reshape(-1, 3), body.query, 0.001, iterations=6).reshape(pts.shape)

    def short(q):
        d, on_arm = keep.distance(q[:, 1:])
        return ((d < clearance - 1e-7) & (d > -arms.HAIR_MAX_DEPTH) & on_arm).reshape(n, -1)

    bad0 = short(pts)
    assert bad0.sum() > 300  # the strands do lie on the arm, closer than the clearance
    out, moved = keep.push(pts)
    np.testing.assert_array_equal(out[:, 0], pts[:, 0])
    changed = (out[:, 1:] != pts[:, 1:]).any(-1)
    assert (changed <= bad0).all() and moved == changed.sum() and changed.sum() > 0.9 * bad0.sum()
    d, _ = keep.distance(out[:, 1:])
    d = d.reshape(n, -1)
    assert d[changed].min() >= 0.0  # no point moved went into the skin
    # every point is kept off the arm but in the crease between arm and torso, where the clearance
    # does not fit (pushed part of the way, or left)
    left = short(out)
    assert left.sum() < 0.1 * bad0.sum() and ((d >= 0.0) | ~changed)[left].all()
    # the arms do not move with an expression: following the same body changes nothing
    keep.follow(body.V)
    again, _ = keep.push(pts)
    np.testing.assert_array_equal(again, out)


def test_torso_under_a_back_hem_that_rides_high(default_head):
    """A work shirt on the first identity of seed 11: its hem (the rim of the cap that closes it)
    rises toward the back; the prism's section stays within the hem and is as wide as the torso."""
    from synth.assets.classes import rig_rng
    from synth.assets.fit import torso
    from synth.config import load_config
    from synth.plan import identities

    hm, d = default_head, default_head.data
    code = identities.sample_identities(11, np.arange(1), identities.prior_of(d),
                                        identities.truncation_radius(d.identity_dims, load_config().identity))[0]
    ev = hm.evaluate(code, np.zeros(d.expression_dims), np.zeros((hm.J, 3)))
    body = Body(ev.vertices[0].astype(np.float64), d.triangles, d.regions, ev.landmarks["ibug68"][0].astype(np.float64))
    entry = {"id": "uniform", "params": {"style": "work_shirt"}}
    s = fit_shell(body, garment_shell(body, entry, rig_rng(11, 0, "garment")), GARMENT_CLEARANCE)
    Q = np.asarray(s.P)[torso.hem_rim(s)]
    c, r, zmin = torso.section(Q)
    reach = np.linalg.norm(Q[:, :2] - c, axis=1).max()
    assert r.max() <= reach  # the section stays within the hem
    waist = body.V[np.asarray(d.regions["bust_bottom"]), 0]  # the bust's bottom loop, 2.5 cm under the hem
    phi = (np.arange(len(r)) + 0.5) / len(r) * 2 * np.pi - np.pi
    width = (c[0] + r * np.cos(phi)).max() - (c[0] + r * np.cos(phi)).min()
    assert 0.9 < width / (waist.max() - waist.min()) < 1.2
