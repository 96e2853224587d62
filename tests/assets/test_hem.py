"""The hem that hides the bust's cut (``synth.assets.fit.hem``), against slow references; the
garments' hems on the hard cases are in test_fit_shells.py, the renders in
tests/blender/test_bust_cut.py."""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.fit import hem
from synth.assets.fit.meshops import grid_faces, oriented_boundary_loops


def _slow_segment_distance(p, A, B):
    best = np.inf
    for a, b in zip(A, B):
        ab = b - a
        L2 = float(np.dot(ab, ab))
        t = 0.0 if L2 == 0 else min(1.0, max(0.0, float(np.dot(p - a, ab)) / L2))
        best = min(best, float(np.linalg.norm(p - (a + t * ab))))
    return best


def test_segment_distance_matches_brute_force():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(40, 3))
    B = A + rng.normal(scale=0.3, size=(40, 3))
    B[3] = A[3]  # a degenerate segment (a point)
    P = rng.normal(size=(300, 3))
    got = hem._segment_distance(P, A, B, chunk=64)
    want = np.array([_slow_segment_distance(p, A, B) for p in P])
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_turning_angles_of_known_polygons():
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    np.testing.assert_allclose(hem.turning_angles(sq), 90.0)
    th = np.linspace(0, 2 * np.pi, 36, endpoint=False)
    circle = np.c_[np.cos(th), np.sin(th), np.zeros_like(th)]
    np.testing.assert_allclose(hem.turning_angles(circle), 10.0, atol=1e-9)
    line = np.c_[np.arange(5.0), np.zeros(5), np.zeros(5)]
    np.testing.assert_allclose(hem.turning_angles(line, closed=False), 0.0, atol=1e-6)
    zig = np.c_[np.arange(6.0), np.tile([0.0, 1.0], 3), np.zeros(6)]
    assert hem.turning_angles(zig, closed=False).min() > 80


def _tube(nu=24, nv=12, jag=0.0):
    """An open cylinder (axis z) whose lower rim zig-zags by ``jag``: a toy bust cut."""
    th = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    z = np.linspace(0, 1, nv)
    V = np.array([[np.cos(t), np.sin(t), zz] for t in th for zz in z])
    V[::nv, 2] -= jag * (np.arange(nu) % 2)
    return V, grid_faces(nu, nv, closed_u=True)


def test_cut_loop_is_the_lowest_and_distance_is_zero_on_it():
    V, F = _tube(jag=0.05)
    loop = hem.cut_loop(F, V)
    assert sorted(loop.tolist()) == list(range(0, len(V), 12))  # the lower rim, not the upper one
    d = hem.cut_distance(V, F)
    assert np.all(d[loop] == 0.0)
    assert np.all(np.diff(d.reshape(24, 12), axis=1).mean(0) > 0)  # grows away from the cut, on average
    with pytest.raises(ValueError):
        closed = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])
        hem.cut_loop(closed, np.eye(4, 3))


def test_hidden_polygons_matches_a_loop_over_polygons():
    V, F = _tube(jag=0.05)
    d = hem.cut_distance(V, F)
    rng = np.random.default_rng(1)
    sizes = rng.integers(3, 5, 50)
    idx = rng.integers(0, len(V), sizes.sum())
    off = np.r_[0, np.cumsum(sizes)]
    got = hem.hidden_polygons(V, F, off, idx)
    want = [any(d[i] < hem.HEM_MARGIN for i in idx[a:b]) for a, b in zip(off[:-1], off[1:])]
    assert got.tolist() == want and 0 < got.sum() < len(got)


def test_cap_closes_the_loop_facing_down():
    th = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    P = np.c_[np.cos(th), 0.6 * np.sin(th), 0.1 * np.cos(3 * th)]
    loop = np.arange(30)
    for order in (loop, loop[::-1]):
        Vc, Fc = hem.cap(P, order, inset=0.01)
        assert len(Vc) == 31 and len(Fc) == 30
        n = np.cross(Vc[Fc[:, 1]] - Vc[Fc[:, 0]], Vc[Fc[:, 2]] - Vc[Fc[:, 0]])
        assert (n[:, 2] < 0).all()
        rim = np.linalg.norm(Vc[:30, :2], axis=1)
        assert np.all(rim < np.linalg.norm(P[order, :2], axis=1))  # tucked inside the loop
        assert len(oriented_boundary_loops(Fc)) == 1


def test_smooth_loops_straightens_a_zigzag_only_on_the_hem():
    V, F = _tube(jag=0.05)
    on = np.zeros(len(V), bool)
    on[::12] = True
    out = hem.smooth_loops(V, F, on)
    lo = hem.cut_loop(F, V)
    assert hem.turning_angles(out[lo]).max() < hem.turning_angles(V[lo]).max()
    top = np.arange(11, len(V), 12)
    assert np.array_equal(out[top], V[top])  # the other rim is left alone
