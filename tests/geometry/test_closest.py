"""synth.geometry.closest against trimesh (per triangle and on whole meshes) and brute force,
with degenerate triangles and points on vertices and edges."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from synth.geometry.closest import ClosestPoints, closest_on_triangles, nearest_on_candidates


def _segment(p, a, b):
    ab = b - a
    t = 0.0 if ab @ ab == 0 else min(max((p - a) @ ab / (ab @ ab), 0.0), 1.0)
    return a + t * ab


def _reference(p, a, b, c):
    """Slow, obviously correct closest point: the projection on the plane when it falls inside
    the triangle, else the best of the three edges (degenerate triangles: edges only)."""
    cands = [_segment(p, a, b), _segment(p, b, c), _segment(p, c, a)]
    M = np.stack([b - a, c - a], 1)
    if np.linalg.matrix_rank(M, tol=1e-12 * max(np.abs(M).max(), 1e-300)) == 2:
        uv = np.linalg.lstsq(M, p - a, rcond=None)[0]
        if uv.min() >= 0 and uv.sum() <= 1:
            cands.append(a + M @ uv)
    return min(cands, key=lambda q: np.linalg.norm(q - p))


def _oracle(P, V, F):
    """Closest point over *all* triangles, by trimesh (a brute-force reference)."""
    tri = V[F]
    best_d, best_q = np.full(len(P), np.inf), np.zeros((len(P), 3))
    for i, p in enumerate(P):
        q = trimesh.triangles.closest_point(tri, np.repeat(p[None], len(F), 0))
        d = np.linalg.norm(q - p, axis=1)
        j = int(np.argmin(d))
        best_d[i], best_q[i] = d[j], q[j]
    return best_q, best_d


def test_closest_on_triangles_matches_trimesh_and_brute_force():
    rng = np.random.default_rng(0)
    A, B, C = rng.normal(size=(3, 500, 3))
    P = rng.normal(size=(500, 3)) * 2
    q, bary = closest_on_triangles(P, A, B, C)
    np.testing.assert_allclose(q, trimesh.triangles.closest_point(np.stack([A, B, C], 1), P), atol=1e-9)
    assert np.allclose(bary.sum(1), 1) and (bary >= 0).all()
    assert np.allclose(q, bary[:, :1] * A + bary[:, 1:2] * B + bary[:, 2:] * C)
    # a dense barycentric grid is never closer than the analytic answer
    g = np.array([(u, v) for u in np.linspace(0, 1, 41) for v in np.linspace(0, 1, 41) if u + v <= 1 + 1e-12])
    S = A[:, None] * (1 - g.sum(1))[None, :, None] + B[:, None] * g[None, :, :1] + C[:, None] * g[None, :, 1:]
    brute = np.linalg.norm(S - P[:, None], axis=2).min(1)
    mine = np.linalg.norm(q - P, axis=1)
    assert np.all(mine <= brute + 1e-9)
    assert np.all(brute - mine < 0.05 * np.maximum(1.0, np.linalg.norm(B - A, axis=1)))


def test_closest_on_triangles_broadcasts():
    rng = np.random.default_rng(1)
    tri = rng.normal(size=(7, 3, 3))
    P = rng.normal(size=(5, 3))
    q, bary = closest_on_triangles(P[:, None], tri[None, :, 0], tri[None, :, 1], tri[None, :, 2])
    assert q.shape == (5, 7, 3) and bary.shape == (5, 7, 3)
    for i in range(5):
        np.testing.assert_allclose(q[i], trimesh.triangles.closest_point(tri, np.repeat(P[i][None], 7, 0)),
                                   atol=1e-12)


def test_points_on_vertices_edges_and_faces():
    a, b, c = np.eye(3)
    P = np.array([a, b, c, (a + b) / 2, (b + c) / 2, (a + c) / 2, (a + b + c) / 3,
                  a + [5, -1, -1], (a + b) / 2 + [1, 1, -2]])  # beyond A; beyond edge AB
    q, bary = closest_on_triangles(P, a, b, c)
    want = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [.5, .5, 0], [0, .5, .5], [.5, 0, .5], [1 / 3] * 3,
                     [1, 0, 0], [.5, .5, 0]])
    np.testing.assert_allclose(bary, want, atol=1e-15)
    assert np.array_equal(bary[:3], np.eye(3)) and np.array_equal(bary[7], [1.0, 0.0, 0.0])  # exact corners
    np.testing.assert_allclose(q[:7], P[:7], atol=1e-15)


@pytest.mark.parametrize("tri", [
    [[0, 0, 0], [1, 0, 0], [2, 0, 0]],  # collinear
    [[0, 0, 0], [1, 1, 1], [1, 1, 1]],  # two corners coincide
    [[0.5, 0.5, 0.5]] * 3,  # a point
])
def test_degenerate_triangles_match_trimesh(tri):
    tri = np.asarray(tri, np.float64)
    rng = np.random.default_rng(2)
    P = rng.normal(size=(300, 3)) * 2
    with np.errstate(all="raise"):  # no warning leaks out
        q, bary = closest_on_triangles(P, tri[0], tri[1], tri[2])
    assert np.isfinite(q).all() and np.allclose(bary.sum(1), 1)
    ref = trimesh.triangles.closest_point(np.repeat(tri[None], len(P), 0), P)
    np.testing.assert_allclose(np.linalg.norm(q - P, axis=1), np.linalg.norm(ref - P, axis=1), atol=1e-9)


@pytest.mark.parametrize("scale,offset", [(1e-7, 0.0), (1e-3, 1e4), (1e3, 0.0)])
def test_extreme_scales(scale, offset):
    rng = np.random.default_rng(3)
    tri = rng.normal(size=(200, 3, 3)) * scale + offset
    P = rng.normal(size=(200, 3)) * scale * 2 + offset
    q, _ = closest_on_triangles(P, tri[:, 0], tri[:, 1], tri[:, 2])
    ref = np.array([_reference(p, *t) for p, t in zip(P, tri)])  # trimesh's tolerances fail here
    tol = 1e-9 * scale + 1e-15 * abs(offset)
    np.testing.assert_allclose(np.linalg.norm(q - P, axis=1), np.linalg.norm(ref - P, axis=1), rtol=1e-6, atol=tol)


def test_closest_points_on_a_mesh_match_the_brute_force_oracle():
    m = trimesh.creation.torus(0.1, 0.03, major_sections=24, minor_sections=12)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    rng = np.random.default_rng(4)
    P = rng.uniform(-0.15, 0.15, (150, 3)) * [1, 1, 0.4]
    got = ClosestPoints(V, F, k=24)(P)
    q, d = _oracle(P, V, F)
    np.testing.assert_allclose(got.distance, d, atol=1e-12)
    np.testing.assert_allclose(got.point, q, atol=1e-9)
    tri = V[F[got.face]]
    np.testing.assert_allclose(np.einsum("nk,nkd->nd", got.bary, tri), got.point, atol=1e-12)


def test_closest_points_on_a_subset_chunked_and_empty():
    m = trimesh.creation.icosphere(2, radius=0.1)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    upper = np.flatnonzero(V[F].mean(1)[:, 2] > 0)
    rng = np.random.default_rng(5)
    P = rng.normal(size=(100, 3)) * 0.1
    got = ClosestPoints(V, F, upper, k=1000, chunk=7)(P)  # k above the subset size: all candidates
    assert set(got.face) <= set(upper)
    _, d = _oracle(P, V, F[upper])
    np.testing.assert_allclose(got.distance, d, atol=1e-12)
    empty = ClosestPoints(V, F)(np.zeros((0, 3)))
    assert empty.point.shape == (0, 3) and empty.face.shape == (0,)
    with pytest.raises(ValueError):
        ClosestPoints(V, F, np.zeros(0, np.int64))(P)


def test_nearest_on_candidates_ties_go_to_the_first_candidate():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0]], np.float64)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    P = np.array([[0.0, 0.5, 1.0]])  # above the shared edge 0-2: both triangles at distance 1
    assert nearest_on_candidates(P, V, F, [[0, 1]]).face[0] == 0
    assert nearest_on_candidates(P, V, F, [[1, 0]]).face[0] == 1
    assert nearest_on_candidates(P, V, F, [[1, 0]]).distance[0] == 1.0


def test_near_ties_by_squared_distance_or_by_distance():
    """A point above an edge shared by two triangles: the closest points computed on either
    triangle differ by round-off, so their squared distances differ by an ulp while the
    distances (square roots) are equal. ``by="squared"`` takes the smaller, ``by="distance"``
    the first candidate; both report the same distance."""
    V = np.array([[-0.43138603184179836, 0.9574239667720826, -1.2387743263168363],
                  [1.2929511646847092, 0.47479931873797876, -0.22838809024354395],
                  [-0.14232728717871945, 0.8299271042495487, -1.4313942795106365],
                  [2.040761939896942, -0.8134195295344778, -0.7652832419470891]])
    F = np.array([[0, 1, 2], [1, 0, 3]])
    P = np.array([[1.242270374823056, 2.222182821423372, -0.7891898989840453]])
    q, _ = closest_on_triangles(P, V[F[:, 0]], V[F[:, 1]], V[F[:, 2]])
    d2 = ((q - P) ** 2).sum(-1)
    assert d2[0] < d2[1] and np.sqrt(d2[0]) == np.sqrt(d2[1])
    sq = nearest_on_candidates(P, V, F, [[1, 0]], by="squared")
    di = nearest_on_candidates(P, V, F, [[1, 0]], by="distance")
    assert sq.face[0] == 0 and di.face[0] == 1 and sq.distance[0] == di.distance[0]
    assert ClosestPoints(V, F, by="distance")(P).distance[0] == sq.distance[0]
    with pytest.raises(ValueError, match="by"):
        nearest_on_candidates(P, V, F, [[0, 1]], by="manhattan")
