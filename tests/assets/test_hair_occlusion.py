"""Strands in front of the face (synth.assets.fit.occlusion) against an analytic reference."""

from __future__ import annotations

import numpy as np

from synth.assets.fit.occlusion import inner_face_triangles, occluding_points, strands_in_front_of_face


def _square(n=6, half=0.05):
    """A flat 'face': a grid of triangles in the plane y = 0, x and z in [-half, half]."""
    g = np.linspace(-half, half, n + 1)
    X, Z = np.meshgrid(g, g, indexing="ij")
    V = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], 1)
    idx = np.arange(V.shape[0]).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F


def _reference(points, cam, half=0.05):
    """In front of the plane y = 0 (camera side) and the camera ray crosses it inside the square."""
    d = points - cam
    t = -cam[1] / d[..., 1]  # ray parameter at the plane
    hit = cam + t[..., None] * d
    inside = (np.abs(hit[..., 0]) <= half) & (np.abs(hit[..., 2]) <= half)
    return (t > 1.0) & inside


def test_strands_in_front_behind_and_beside_the_face():
    V, F = _square()
    cam = np.array([0.0, -1.0, 0.0])
    z = np.linspace(-0.03, 0.03, 5)
    front = np.stack([np.zeros(5), np.full(5, -0.02), z], 1)  # hangs in front of the face
    behind = front * [1, -1, 1]  # inside the head (behind the surface)
    beside = front + [0.2, 0.0, 0.0]  # to the side, not over the face
    crossing = np.stack([np.zeros(5), np.linspace(0.02, -0.02, 5), z], 1)  # from behind to the front
    S = np.stack([front, behind, beside, crossing])
    occ = occluding_points(S, cam, V, F)
    assert occ[0].all() and not occ[1].any() and not occ[2].any()
    assert occ[3].tolist() == [False, False, False, True, True]  # y = 0 is on the surface: not in front
    r = strands_in_front_of_face(S, [cam, [0.0, 1.0, 0.0]], V, F)
    assert r["strands"].tolist() == [2, 2] and r["points"][0] == 7  # from behind, 'behind' is in front
    assert np.isclose(r["strand_fraction"][0], 0.5)


def test_random_points_match_the_analytic_reference():
    V, F = _square(n=9)
    rng = np.random.default_rng(3)
    for cam in (np.array([0.0, -0.8, 0.0]), np.array([0.3, -0.6, 0.2])):
        pts = rng.uniform([-0.12, -0.1, -0.12], [0.12, 0.1, 0.12], size=(400, 3, 3))
        assert np.array_equal(occluding_points(pts, cam, V, F), _reference(pts, cam))


def test_degenerate_inputs():
    V, F = _square()
    cam = np.array([0.0, -1.0, 0.0])
    assert occluding_points(np.zeros((0, 4, 3)), cam, V, F).shape == (0, 4)
    assert not occluding_points(np.full((2, 3, 3), -0.01), cam, V, F[:0]).any()


def _neutral(hm):
    """Vertices and ibug68 landmarks of the mean identity, neutral expression, no rotation."""
    d = hm.data
    ev = hm.evaluate(np.zeros(d.identity_dims), np.zeros(d.expression_dims), np.zeros((hm.J, 3)))
    return ev.vertices[0].astype(np.float64), ev.landmarks["ibug68"][0].astype(np.float64)


def test_inner_face_excludes_the_forehead_and_the_rest_of_the_head(default_head):
    data = default_head.data
    verts, lm = _neutral(default_head)
    tri = inner_face_triangles(data, verts, lm)
    assert 0 < len(tri) < len(data.triangles) // 3
    z = verts[tri][..., 2]
    assert z.max() < lm[17:27, 2].max() and z.min() < lm[8, 2] + 0.02  # brows .. chin
    face = set(np.asarray(data.regions["face"]).tolist())
    assert set(np.unique(tri).tolist()) <= face
    # a point 1 cm in front of the nose tip occludes the face from a frontal camera
    nose = lm[30]
    cam = nose + [0.0, -1.0, 0.0]
    assert occluding_points(np.array([[nose + [0.0, -0.01, 0.0]]]), cam, verts, tri)[0, 0]
    assert not occluding_points(np.array([[nose + [0.0, 0.01, 0.0]]]), cam, verts, tri)[0, 0]


def test_centre_of_the_face_lies_between_the_outer_eye_corners(default_head):
    data = default_head.data
    verts, lm = _neutral(default_head)
    inner = inner_face_triangles(data, verts, lm)
    centre = inner_face_triangles(data, verts, lm, centre_only=True)
    assert 0 < len(centre) < len(inner)
    x = verts[centre][..., 0]
    assert x.min() > min(lm[36, 0], lm[45, 0]) and x.max() < max(lm[36, 0], lm[45, 0])
    # a strand hanging over the cheek, outside the eye corners, is in front of the inner face only
    cheek = np.array([[0.5 * (lm[2] + lm[31]) + [0.0, -0.04, 0.0]]])  # x beyond the eye corner
    cam = cheek[0, 0] + [0.0, -1.0, 0.0]
    assert occluding_points(cheek, cam, verts, inner)[0, 0] and not occluding_points(cheek, cam, verts, centre)[0, 0]
