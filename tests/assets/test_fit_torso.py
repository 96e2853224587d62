"""The torso and arms below a garment (synth.assets.fit.torso): bad input refused, hair kept out of
the arms, and a torso under a back hem that rides high. The torso against every fitted garment is
in tests/assets/test_fit_shells.py."""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.fit.body import Body, fit_shell
from synth.assets.fit.garment import CLEARANCE as GARMENT_CLEARANCE
from synth.assets.fit.garment import garment_shell


def test_torso_rejects_bad_input():
    from synth.assets.fit import torso

    with pytest.raises(ValueError, match="not finite"):
        torso.torso_continuation(np.full((10, 3), np.nan))
    with pytest.raises(ValueError, match="positive"):
        torso.torso_continuation(np.random.default_rng(0).normal(size=(50, 3)), length=0.0)
    with pytest.raises(ValueError, match="not finite"):
        torso.arm_params(np.full((10, 3), np.nan))
    with pytest.raises(ValueError, match="positive"):
        torso.arm_params(np.random.default_rng(0).normal(size=(50, 3)), length=-1.0)


def test_keep_strands_out_of_arms():
    """Strand points inside an arm move out of it (ray parity, against the arm's mesh), onto its cap
    from above or out from its axis; roots and points outside stay where they were."""
    from synth.assets.fit import torso
    from synth.geometry.raycast import ray_hit_counts

    arm = torso.Arm(axis=(0.17, 0.0), z_base=0.52, radius=0.045, z_bottom=-0.3, side=1.0)
    V, F = arm.mesh()
    rng = np.random.default_rng(3)
    # strands hanging straight down from above the shoulder, over and beside the arm
    roots = np.column_stack([rng.uniform(0.10, 0.24, 400), rng.uniform(-0.07, 0.07, 400), np.full(400, 0.70)])
    pts = roots[:, None] + np.linspace(0.0, 0.35, 24)[None, :, None] * np.array([0.0, 0.0, -1.0])
    before = ray_hit_counts(pts.reshape(-1, 3), np.tile([0.0, 0.0, 1.0], (pts.size // 3, 1)), V, F, t_min=1e-9) % 2 == 1
    assert before.sum() > 1000  # the test's strands do pass through the arm
    out, moved = torso.keep_strands_out([arm], pts)
    # the analytic arm holds its faceted mesh, and a few points between the two
    assert before.sum() <= moved <= 1.03 * before.sum()
    flat = out.reshape(-1, 3)
    for d in ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]):
        assert not (ray_hit_counts(flat, np.tile(d, (len(flat), 1)), V, F, t_min=1e-9) % 2 == 1).any(), d
    np.testing.assert_array_equal(out[:, 0], pts[:, 0])
    inside = before.reshape(pts.shape[:2])
    m = (out != pts).any(-1)
    assert (m | ~inside).all() and moved == m.sum()
    # besides the points inside the mesh only those between its facets and the analytic surface
    # (the cap's six rings lie up to about 1.3 mm inside it)
    step = np.linalg.norm(out - pts, axis=-1)
    assert (step[m & ~inside] < torso.ARM_HAIR_CLEARANCE + 0.0015).all()
    # a point moved lies ARM_HAIR_CLEARANCE beyond the analytic surface: on the cap or the tube
    q = out[m]
    rho = np.linalg.norm(q[:, :2] - arm.axis, axis=1)
    on_tube = np.abs(rho - arm.radius_at(np.minimum(q[:, 2], arm.z_base)) - torso.ARM_HAIR_CLEARANCE) < 1e-9
    on_cap = np.abs(q[:, 2] - arm.cap_z(q[:, :2]) - torso.ARM_HAIR_CLEARANCE) < 1e-9
    assert (on_tube | on_cap).all()
    assert on_cap.sum() > 100  # strands from above drape over the shoulder


def test_torso_and_arms_under_a_back_hem_that_rides_high(default_head):
    """A work shirt on the first identity of seed 11 ends 5 cm higher at the back than at the
    front. The back once counted as an arm stump's opening: one chord across more than half a
    turn, a torso section 2 m wide, and no garment shoulder within reach of the arms (a crash)."""
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
    Q = np.asarray(s.P)[torso.torso_shell_vertices(s)]
    c, r, zmin = torso.section(Q)
    phi = (np.arange(len(r)) + 0.5) / len(r) * 2 * np.pi - np.pi
    assert (zmin[np.sin(phi) > 0.9] > Q[:, 2].min() + torso.STUMP_RISE).all()  # the case: the back rides high
    reach = np.linalg.norm(Q[:, :2] - c, axis=1).max()
    assert r.max() <= reach  # the section stays within the garment
    V, F = torso.arms(Q)
    breadth = V[:, 0].max() - V[:, 0].min()
    assert 1.3 < breadth / (2 * r[np.abs(np.cos(phi)) > 0.99].max()) < 1.8
