"""prior.fit.align: the similarity between a fit's frame and the ground truth's, against known
transforms and scipy's orthogonal Procrustes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import orthogonal_procrustes
from scipy.spatial.transform import Rotation

from prior.fit.align import align_cameras, camera_points, umeyama
from synth.conventions import orbit_camera_to_world
from synth.errors import SynthError


def _sim(seed):
    rng = np.random.default_rng(seed)
    return 10 ** rng.uniform(-1, 1), Rotation.random(random_state=seed).as_matrix(), rng.normal(0, 2, 3)


@pytest.mark.parametrize("seed", range(5))
def test_recovers_a_known_similarity(seed):
    s, R, t = _sim(seed)
    src = np.random.default_rng(seed + 10).normal(size=(7, 3))
    sim = umeyama(src, s * src @ R.T + t)
    assert sim.scale == pytest.approx(s, rel=1e-10)
    np.testing.assert_allclose(sim.rotation, R, atol=1e-10)
    np.testing.assert_allclose(sim.translation, t, atol=1e-9)
    assert sim.rms < 1e-9 and np.linalg.det(sim.rotation) == pytest.approx(1.0)


def test_rotation_matches_orthogonal_procrustes_on_noisy_points():
    rng = np.random.default_rng(3)
    src = rng.normal(size=(30, 3))
    R = Rotation.random(random_state=4).as_matrix()
    dst = src @ R.T + 0.05 * rng.normal(size=src.shape)
    sim = umeyama(src, dst, with_scale=False)
    a, b = src - src.mean(0), dst - dst.mean(0)
    Rs, _ = orthogonal_procrustes(a, b)  # minimises |a Rs - b|: Rs = R^T
    np.testing.assert_allclose(sim.rotation, Rs.T, atol=1e-10)
    # a reflection would fit a mirrored set better; the result stays a proper rotation
    mirrored = umeyama(src, src * np.array([1, 1, -1]))
    assert np.linalg.det(mirrored.rotation) == pytest.approx(1.0)


def test_cameras_map_back_and_one_view_is_enough():
    s, R, t = _sim(7)
    c2w_fit = orbit_camera_to_world(np.array([0.0, 40.0, -40.0]), np.array([0.0, 5.0, 5.0]), 1.1, np.zeros(3))
    face_fit = np.array([0.0, -0.05, 0.02])
    c2w_true = c2w_fit.copy()
    c2w_true[:, :3, :3] = R @ c2w_fit[:, :3, :3]
    c2w_true[:, :3, 3] = s * c2w_fit[:, :3, 3] @ R.T + t
    face_true = s * R @ face_fit + t
    for n in (1, 2, 3):
        sim = align_cameras(c2w_fit[:n], face_fit, c2w_true[:n], face_true)
        assert sim.scale == pytest.approx(s, rel=1e-9)
        np.testing.assert_allclose(sim.camera_to_source(c2w_true), c2w_fit, atol=1e-9)
    pts = camera_points(c2w_fit[:1], face_fit)
    assert pts.shape == (4, 3)
    np.testing.assert_allclose(np.linalg.norm(pts[3] - pts[0]), np.linalg.norm(face_fit - pts[0]))


def test_degenerate_input_is_one_line():
    with pytest.raises(SynthError, match="all equal"):
        umeyama(np.zeros((4, 3)), np.ones((4, 3)))
    with pytest.raises(SynthError, match="point sets"):
        umeyama(np.zeros((2, 3)), np.zeros((2, 3)))
