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


def test_edge_distance_is_dijkstra_along_the_edges():
    """edge_distance: the shortest path along the mesh's edges from the sources (a brute-force
    Bellman-Ford on the tube), inf where no path leads."""
    V, F = _tube()
    src = np.arange(0, len(V), 12)  # the lower rim
    got = hem.edge_distance(V, F, src)
    E = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0)
    w = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    d = np.full(len(V), np.inf)
    d[src] = 0.0
    for _ in range(len(V)):
        nd = d.copy()
        np.minimum.at(nd, E[:, 1], d[E[:, 0]] + w)
        np.minimum.at(nd, E[:, 0], d[E[:, 1]] + w)
        if np.array_equal(nd, d):
            break
        d = nd
    np.testing.assert_allclose(got, d, atol=1e-12)
    V2 = np.vstack([V, V[:3] + 5.0])  # a separate triangle: unreachable
    F2 = np.vstack([F, [[len(V), len(V) + 1, len(V) + 2]]])
    assert np.isinf(hem.edge_distance(V2, F2, src)[-3:]).all()


def test_an_elbow_beside_the_cut_is_not_near_it(default_head):
    """The default model's elbows hang beside the waist's cut (at +3 SD 6 mm from it): in space
    near the cut, along the body 30 cm and more from it. The cut distance takes the longer (at
    least GEODESIC_SHARE of the way along the edges), so no arm polygon is hidden under a hem
    and every arm vertex is far above the hem."""
    from tests.support import asset_scene

    for case in ("neutral", "id+3_jaw"):
        ctx = asset_scene.head_arrays(default_head, case)
        V, F, reg = ctx.vertices, np.asarray(ctx.data.triangles, np.int64), ctx.data.regions
        arm = np.concatenate([reg["arm_l"], reg["arm_r"]])
        loop = hem.cut_loop(F, V)
        euclid = hem._segment_distance(V[arm], V[loop], V[np.roll(loop, -1)])
        d = hem.cut_distance(V, F)
        assert d[arm].min() > 0.1 > hem.HEM_MARGIN, case
        if case == "id+3_jaw":
            assert euclid.min() < hem.HEM_MARGIN  # the case: in space the elbow is near the cut
        off = np.asarray(ctx.data.poly_offsets, np.int64)
        idx = np.asarray(ctx.data.poly_indices, np.int64)
        hidden = hem.hidden_polygons(V, F, off, idx)
        on_arm = np.isin(idx, arm)
        arm_polys = np.add.reduceat(on_arm.astype(int), off[:-1]) == np.diff(off)
        assert hidden.any() and not (hidden & arm_polys).any(), case
