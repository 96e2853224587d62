"""synth.geometry.sdf: distances against a brute-force trimesh oracle, signs against the
winding number (a slow, exact inside test for closed meshes), the three sign rules, open
meshes, subsets and points on the surface."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from synth.geometry.normals import vertex_normals
from synth.geometry.sdf import SignedDistance


def _winding(P, V, F):
    """Generalised winding number (Van Oosterom & Strackee solid angles): ~1 inside, ~0 outside."""
    w = np.zeros(len(P))
    for f in F:
        a, b, c = V[f[0]] - P, V[f[1]] - P, V[f[2]] - P
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        num = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la \
            + np.einsum("ij,ij->i", c, a) * lb
        w += 2.0 * np.arctan2(num, den)
    return w / (4.0 * np.pi)


def _torus():
    m = trimesh.creation.torus(0.1, 0.03, major_sections=32, minor_sections=16)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _brute_distance(P, V, F):
    tri = V[F]
    return np.array([np.linalg.norm(trimesh.triangles.closest_point(tri, np.repeat(p[None], len(F), 0)) - p,
                                    axis=1).min() for p in P])


def test_pseudo_normal_sign_matches_the_winding_number_on_a_closed_non_convex_mesh():
    V, F = _torus()
    rng = np.random.default_rng(0)
    P = rng.uniform(-0.14, 0.14, (400, 3)) * [1, 1, 0.35]
    sd = SignedDistance(V, F, sign="pseudo", k=32)
    h = sd.query(P)
    np.testing.assert_allclose(h.distance, _brute_distance(P, V, F), atol=1e-12)
    inside = _winding(P, V, F) > 0.5
    np.testing.assert_array_equal(h.signed < 0, inside)
    np.testing.assert_array_equal(np.abs(h.signed), h.distance)
    np.testing.assert_allclose(np.linalg.norm(h.normal, axis=1), 1.0)
    np.testing.assert_array_equal(sd(P), h.signed)


def test_pseudo_sign_near_edges_and_vertices():
    """Points just outside and inside a cube, closest to its edges and corners (where face
    normals alone give the wrong sign): the pseudo-normals get every one right."""
    m = trimesh.creation.box((1.0, 1.0, 1.0))
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    rng = np.random.default_rng(1)
    corners = np.array([[sx, sy, sz] for sx in (-.5, .5) for sy in (-.5, .5) for sz in (-.5, .5)])
    edges = np.array([[0.5, 0.5, z] for z in np.linspace(-0.45, 0.45, 10)])
    near = np.concatenate([corners[rng.integers(8, size=150)], edges[rng.integers(10, size=150)]])
    P = np.concatenate([near + 1e-3 * rng.normal(size=near.shape), corners * 0.999, corners * 1.001])
    h = SignedDistance(V, F, sign="pseudo").query(P)
    inside = np.all(np.abs(P) < 0.5, axis=1)
    np.testing.assert_array_equal(h.signed < 0, inside)
    np.testing.assert_allclose(h.distance, _brute_distance(P, V, F), atol=1e-12)


def test_vertex_sign_on_a_sphere_and_on_an_open_cap():
    m = trimesh.creation.icosphere(3, radius=0.1)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    rng = np.random.default_rng(2)
    d = rng.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = rng.uniform(0.05, 0.15, 300)
    sd = SignedDistance(V, F, sign="vertex")
    h = sd.query(d * r[:, None])
    np.testing.assert_allclose(h.signed, r - 0.1, atol=0.002)  # chord error of icosphere(3) at 10 cm
    # the normal is the barycentric blend of the area-weighted vertex normals of the whole mesh
    vn = vertex_normals(V, F)
    blend = np.einsum("nk,nkd->nd", h.bary, vn[F[h.face]])
    np.testing.assert_allclose(h.normal, blend / np.linalg.norm(blend, axis=1, keepdims=True), atol=1e-15)
    # a subset (the upper cap): queries stay on it, normals still come from the whole sphere
    cap = np.flatnonzero(V[F].mean(1)[:, 2] > 0.05)
    hc = SignedDistance(V, F, faces=cap, sign="vertex").query(d * r[:, None])
    assert set(hc.face) <= set(cap)
    up = (d[:, 2] > 0.8)
    np.testing.assert_allclose(hc.signed[up], h.signed[up], atol=1e-12)


def test_face_sign_is_the_height_above_the_closest_face():
    V, F = _torus()
    rng = np.random.default_rng(3)
    P = rng.uniform(-0.14, 0.14, (300, 3)) * [1, 1, 0.35]
    h = SignedDistance(V, F, sign="face", k=32).query(P)
    tri = V[F[h.face]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(h.normal, n, atol=1e-15)
    np.testing.assert_allclose(h.signed, np.einsum("nd,nd->n", P - h.point, n), atol=1e-15)
    interior = (h.bary > 1e-9).all(1)
    assert interior.sum() > 50
    np.testing.assert_allclose(np.abs(h.signed[interior]), h.distance[interior], atol=1e-12)


@pytest.mark.parametrize("sign", ["pseudo", "vertex", "face"])
def test_points_on_the_surface_and_empty_input(sign):
    V, F = _torus()
    sd = SignedDistance(V, F, sign=sign)
    on = np.concatenate([V[:20], V[F[:20]].mean(1), V[F[:20, :2]].mean(1)])  # vertices, centroids, edge midpoints
    h = sd.query(on)
    assert np.all(h.distance < 1e-15) and np.all(np.abs(h.signed) < 1e-15)
    assert sd(np.zeros((0, 3))).shape == (0,)


def test_bad_sign_rule():
    V, F = _torus()
    with pytest.raises(ValueError, match="sign"):
        SignedDistance(V, F, sign="winding")
