"""benchmarks/realism/judge.py: the mediapipe -> ibug68 mapping and the judge's error metric
(pure numpy; mediapipe itself is never needed here)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.realism import judge
from tests.support.scripts import load_script


@pytest.fixture(scope="module")
def J():
    return judge

def _faces(n, seed=0):
    """(n, 68, 2) random point sets with the outer eye corners 36, 45 apart."""
    g = np.random.default_rng(seed)
    return g.uniform(0, 200, (n, 68, 2))

def test_face_errors_against_a_rotation_reference(J):
    truth, pred = _faces(5), _faces(5, 1)
    err = J.face_errors(pred, truth)
    for f in range(5):  # reference: rotate by minus the angle of the eye axis, divide by its length
        d = truth[f, 45] - truth[f, 36]
        a = np.arctan2(d[1], d[0])
        R = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
        np.testing.assert_allclose(err[f], (pred[f] - truth[f]) @ R.T / np.hypot(*d), atol=1e-12)
    # an upright face: x to the right, y down, in inter-ocular units
    t = np.zeros((1, 68, 2))
    t[0, 36], t[0, 45] = (10.0, 50.0), (50.0, 50.0)
    p = t.copy()
    p[0, 30] += (4.0, -2.0)
    np.testing.assert_allclose(J.face_errors(p, t)[0, 30], (0.1, -0.05), atol=1e-12)

@pytest.mark.parametrize("angle", [0.0, np.pi / 2, np.pi, -2.5])
def test_face_errors_invariant_to_similarity(J, angle):
    truth, pred = _faces(3, 2), _faces(3, 3)
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    move = lambda x: 3.7 * x @ R.T + (-40.0, 1e3)  # noqa: E731
    np.testing.assert_allclose(J.face_errors(move(pred), move(truth)), J.face_errors(pred, truth), atol=1e-9)
    assert np.all(J.nme(J.face_errors(truth, truth)) == 0)

def test_fit_mapping_recovers_exact_convex_weights(J):
    g = np.random.default_rng(4)
    mesh = g.normal(0, 50, (30, 10, 2))
    mesh[:, 0], mesh[:, 1] = (0, 0), (40, 0)  # so that ibug 36 and 45 below sit 40 px apart
    cand = np.array([g.choice(10, 4, replace=False) for _ in range(68)])
    w_true = g.dirichlet(np.ones(4), 68)
    w_true[5] = (1.0, 0.0, 0.0, 0.0)  # a vertex of the hull
    truth = np.einsum("lk,slkc->slc", w_true, mesh[:, cand])
    w, rms = J.fit_mapping(mesh, truth, cand)
    np.testing.assert_allclose(w, w_true, atol=1e-5)
    assert rms.max() < 1e-5

def _outside_hull(seed: int, samples: int):
    """Random mesh points (samples, 6, 2) and ibug68 targets mostly outside the hull of the first
    5 (candidates of every target), the outer eye corners 35 px apart."""
    g = np.random.default_rng(seed)
    mesh = g.normal(0, 30, (samples, 6, 2))
    truth = g.normal(0, 30, (samples, 68, 2))
    truth[:, 45] = truth[:, 36] + (35.0, 5.0)
    return mesh, truth, np.tile(np.arange(5), (68, 1))

def test_fit_mapping_outside_the_hull_matches_a_constrained_solver(J):
    from scipy.optimize import minimize

    mesh, truth, cand = _outside_hull(5, 12)
    w, rms = J.fit_mapping(mesh, truth, cand)
    assert np.all(w >= 0) and np.allclose(w.sum(1), 1, atol=1e-6)
    iod = np.linalg.norm(truth[:, 45] - truth[:, 36], axis=-1)
    for j in (0, 30, 67):
        def cost(x, j=j):
            return np.sum(((np.einsum("k,skc->sc", x, mesh[:, :5]) - truth[:, j]) / iod[:, None]) ** 2)
        ref = minimize(cost, np.full(5, 0.2), method="SLSQP", bounds=[(0, 1)] * 5,
                       constraints={"type": "eq", "fun": lambda x: x.sum() - 1}, options={"ftol": 1e-14})
        assert cost(w[j]) <= ref.fun * (1 + 1e-5) + 1e-12
        assert rms[j] == pytest.approx(np.sqrt(cost(w[j]) / len(mesh)), rel=1e-6)

def test_single_candidate_is_the_point_itself(J):
    mesh = _faces(4, 6)[:, :20]
    truth = _faces(4, 7)
    w, _ = J.fit_mapping(mesh, truth, np.full((68, 1), 3))
    np.testing.assert_allclose(w, 1.0)
    np.testing.assert_allclose(J.apply_mapping(mesh, np.full((68, 1), 3), w), np.repeat(mesh[:, 3:4], 68, 1))

def test_mirror_permutation_on_the_default_model(J, default_model):
    """IBUG68_MIRROR is an involution and pairs the default model's landmarks with their
    mirror images (the template is left-right symmetric about x = 0 up to a few mm)."""
    m = J.IBUG68_MIRROR
    assert sorted(m) == list(range(68)) and np.all(m[m] == np.arange(68))
    tri, bary = default_model.landmarks["ibug68"]
    T = np.asarray(default_model.template, np.float64)
    lm = np.einsum("lkc,lk->lc", T[default_model.triangles[tri]], bary)
    mirrored = lm[m] * (-1.0, 1.0, 1.0)
    assert np.abs(mirrored - lm).max() < 0.004  # metres; a wrong pairing is centimetres off
    pts = _faces(2, 8)
    np.testing.assert_allclose(J.unmirror(J.unmirror(pts, 256), 256), pts)
    flipped = J.unmirror(pts, 256)
    np.testing.assert_allclose(flipped[:, 16, 0], 256 - pts[:, 0, 0])

def test_mediapipe_pixels_shift_to_synth_convention(J):
    # mediapipe puts the centre of pixel column 10 at x = 10; synth at 10.5
    np.testing.assert_allclose(J.to_synth_pixels([[10.0, 0.0]]), [[10.5, 0.5]])

def test_relaxed_fit_spans_convex_to_affine_least_squares(J):
    """relax -> infinity keeps the convex weights; relax -> 0 gives the least squares over
    weights summing to one (checked against the KKT system); in between the fit lies between."""
    mesh, truth, cand = _outside_hull(8, 20)
    wc, rc = J.fit_mapping(mesh, truth, cand)
    wb, rb = J.fit_mapping(mesh, truth, cand, relax=1e6)
    np.testing.assert_allclose(wb, wc, atol=1e-4)
    w0, r0 = J.fit_mapping(mesh, truth, cand, relax=1e-12)
    wm, rm = J.fit_mapping(mesh, truth, cand, relax=1e-2)
    np.testing.assert_allclose(w0.sum(1), 1.0, atol=1e-9)
    np.testing.assert_allclose(wm.sum(1), 1.0, atol=1e-9)
    iod = np.linalg.norm(truth[:, 45] - truth[:, 36], axis=-1)
    for j in (0, 30, 67):
        A = (mesh[:, :5] / iod[:, None, None]).transpose(0, 2, 1).reshape(-1, 5)
        b = (truth[:, j] / iod[:, None]).reshape(-1)
        kkt = np.block([[2 * A.T @ A, np.ones((5, 1))], [np.ones((1, 5)), np.zeros((1, 1))]])
        ref = np.linalg.solve(kkt, np.concatenate([2 * A.T @ b, [1.0]]))[:5]
        np.testing.assert_allclose(w0[j], ref, atol=1e-6)
    assert np.any(w0 < -1e-3)  # the random targets lie outside the hull: signs are free
    assert np.all(r0 <= rm + 1e-12) and np.all(rm <= rc + 1e-12)

def test_sample_mapping_beats_the_template_mapping_on_held_out_samples(J, default_model):
    idx, w, rms = J.sample_mapping(default_model, identities=12, views=4)
    c_idx, c_w, _ = J.sample_mapping(default_model, identities=12, views=4, relax=None)
    t_idx, t_w, t_res = J.template_mapping(default_model)
    assert np.allclose(w.sum(1), 1, atol=1e-6) and np.all(idx < J.MESH_POINTS)
    assert np.all(c_w >= 0) and np.allclose(c_w.sum(1), 1, atol=1e-6)
    assert w.min() > -0.5 and w.max() < 1.5  # a little extrapolation, not a blow-up
    mesh, ibug = J.model_samples(default_model, 7, 8, 4)  # another seed: other identities and cameras
    assert not np.isnan(mesh[:, idx]).any()
    new = J.face_errors(J.apply_mapping(mesh, idx, w), ibug)
    convex = J.face_errors(J.apply_mapping(mesh, c_idx, c_w), ibug)
    old = J.nme(J.face_errors(J.apply_mapping(mesh, t_idx, t_w), ibug))
    # convex: 1.2 % with either correspondence (the mirror-symmetric one since 2026-12-01: 1.21 %);
    # builder 8's file (the medial canthus held off the eyeball, derived anew 2026-12-02) spans the
    # nose less well through it: 1.25 % against the template mapping's 1.51 % (builder 7: 1.20 /
    # 1.58 %), while the relaxed mapping the judge uses reads 0.52 % (builder 7: 0.55 %)
    assert np.median(J.nme(convex)) < 0.013 and np.median(J.nme(convex)) < 0.85 * np.median(old)
    assert np.median(J.nme(new)) < 0.5 * np.median(old)
    assert np.median(J.nme(new)) < 0.007  # 0.57 %
    assert np.median(J.nme(new)) < 0.8 * np.median(J.nme(convex))
    # the worst point (a jaw angle, outside mediapipe's face oval) is what the relaxation is for
    worst = lambda e: np.sqrt((np.linalg.norm(e, axis=-1) ** 2).mean(0)).max()  # noqa: E731
    assert worst(new) < 0.6 * worst(convex)
    # the same seed gives the same samples; compared to 1e-12 relative, not bit for bit: float64
    # matrix products may differ in the last bit with the arrays' memory alignment (seen: 1.4e-13 px)
    again = J.model_samples(default_model, 7, 8, 4)
    np.testing.assert_allclose(again[0], mesh, rtol=1e-12, atol=0)

@pytest.mark.parametrize("factor", [0.7, 1.0, 1.2])
def test_shrink_recovers_a_judge_that_scales_shape_variation(J, factor):
    """A judge that reproduces ``factor`` of every frame's deviation from the mean shape, plus a
    fixed per-point offset and small noise, reads as k = factor - 1 in every region, whatever
    the frames' position, size and roll in the image."""
    rng = np.random.default_rng(3)
    F = 40
    base = rng.normal(size=(68, 2))
    base[36], base[45] = (-1.0, 0.0), (1.0, 0.0)
    shapes = base + 0.15 * rng.normal(size=(F, 68, 2))
    shapes[:, 36], shapes[:, 45] = (-1.0, 0.0), (1.0, 0.0)  # eye corners fixed: the face frame is exact
    judged = shapes.mean(0) + factor * (shapes - shapes.mean(0)) + 0.05 + 0.002 * rng.normal(size=shapes.shape)
    judged[:, 36], judged[:, 45] = shapes[:, 36], shapes[:, 45]
    ang = rng.uniform(-0.5, 0.5, F)
    R = np.stack([np.stack([np.cos(ang), -np.sin(ang)], -1), np.stack([np.sin(ang), np.cos(ang)], -1)], -2)
    scale, shift = rng.uniform(20, 60, F), rng.uniform(50, 200, (F, 2))
    place = lambda p: np.einsum("fij,flj->fli", R, p) * scale[:, None, None] + shift[:, None]  # noqa: E731
    truth, pred = place(shapes), place(judged)
    out = J.shrink(J.face_errors(pred, truth), truth)
    assert set(out) == set(J.REGIONS)
    for name, (k, before, after) in out.items():
        r = [i for i in J.REGIONS[name] if i not in (36, 45)]
        assert k == pytest.approx(factor - 1, abs=0.02), name
        assert after <= before + 1e-12
        if factor != 1.0 and len(r) == len(J.REGIONS[name]):
            assert after < 0.5 * before, name


def test_presence_bracket_from_the_thresholds_that_found_a_mesh():
    M = load_script("benchmarks/mediapipe_judge.py", "mediapipe_judge")
    grid = M.PRESENCE_GRID
    n = len(grid)
    assert M.bracket([True] * n) == [grid[-1], 1.0]
    assert M.bracket([False] * n) == [0.0, grid[0]]
    i = grid.index(0.5)
    assert M.bracket([True] * i + [False] * (n - i)) == [grid[i - 1], 0.5]  # no mesh at the default 0.5
    assert M.bracket([True] * (i + 1) + [False] * (n - i - 1)) == [0.5, grid[i + 1]]
    assert M.bracket([False] + [True] * (n - 1)) is None  # found above a threshold that failed
    assert M.bracket([True] * (n - 1)) is None  # not one answer per threshold


def test_presence_report_counts_and_flags_a_mesh_that_contradicts_its_bracket(J, capsys):
    det = {"a": {"mesh": [[0, 0]], "presence": [0.999, 1.0]}, "b": {"mesh": [[0, 0]], "presence": [0.8, 0.9]},
           "c": {"mesh": None, "presence": [0.4, 0.5]}, "d": {"mesh": None, "presence": [0.95, 0.98]},
           "e": {"mesh": None}}
    got = J.presence_report(det, list(det))
    out = capsys.readouterr().out
    assert set(got) == {"a", "b", "c", "d"}
    assert "below 0.5: 1, below 0.9: 2, below 0.99: 3" in out
    assert "lowest: c 0.4-0.5, b 0.8-0.9, d 0.95-0.98, a 0.999-1" in out
    assert "disagrees with its bracket: d" in out  # no mesh although the score reached 0.5
    assert J.presence_report({"x": {"mesh": None}}, ["x"]) is None  # detections from before the brackets
