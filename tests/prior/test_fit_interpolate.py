"""prior.fit.interpolate (paper Eq. 8) against a direct loop."""

from __future__ import annotations

import numpy as np
import pytest

from prior.fit.interpolate import interpolate_codes, interpolate_for_cameras, interpolation_weights
from synth.conventions import invert_rigid, orbit_camera_to_world
from synth.errors import SynthError
from synth.geometry import axis_angle_to_matrix


def _reference(t, cams, codes, eps):
    w = [1.0 / (eps + float(np.sum((t - c) ** 2))) for c in cams]
    z = sum(w)
    return sum(wi / z * ci for wi, ci in zip(w, codes))


def test_matches_direct_loop():
    rng = np.random.default_rng(0)
    cams, codes = rng.normal(0, 1, (3, 3)), rng.uniform(0, 1, (3, 52))
    targets = rng.normal(0, 1, (7, 3))
    got = interpolate_codes(targets, cams, codes, eps=1e-4)
    for t, g in zip(targets, got):
        np.testing.assert_allclose(g, _reference(t, cams, codes, 1e-4), rtol=1e-12)
    np.testing.assert_allclose(interpolation_weights(targets, cams).sum(1), 1.0)


def test_limits_and_invariance():
    c2w = orbit_camera_to_world(np.array([0.0, 45.0, -45.0]), 0.0, 1.1, [0, 0, 0.7])
    w2c = invert_rigid(c2w)
    codes = np.eye(3)
    # at an input camera: that camera's code (up to eps)
    np.testing.assert_allclose(interpolate_for_cameras(w2c[1], w2c, codes)[0], codes[1], atol=1e-5)
    # behind the head: equidistant from the two side cameras, farther from the frontal one
    mid = orbit_camera_to_world(180.0, 0.0, 1.1, [0, 0, 0.7])
    w = interpolation_weights(mid[:3, 3], c2w[:, :3, 3])[0]
    assert w[1] == pytest.approx(w[2]) and w[0] < w[1]
    # a rigid motion of all cameras (the gauge) changes nothing; so does a single input
    R = axis_angle_to_matrix(np.array([0.3, -0.2, 0.5]))
    moved = lambda p: p @ R.T + [0.1, 2.0, -1.0]  # noqa: E731
    t = np.array([0.4, -0.9, 0.8])
    np.testing.assert_allclose(interpolation_weights(moved(t), moved(c2w[:, :3, 3])),
                               interpolation_weights(t, c2w[:, :3, 3]), atol=1e-12)
    np.testing.assert_allclose(interpolate_codes(t, c2w[:1, :3, 3], codes[:1]), codes[:1])


def test_bad_input():
    with pytest.raises(SynthError, match="2 codes for 3 input cameras"):
        interpolate_codes(np.zeros(3), np.eye(3), np.zeros((2, 5)))
    with pytest.raises(SynthError, match="eps must be positive"):
        interpolation_weights(np.zeros(3), np.eye(3), eps=0.0)
    with pytest.raises(SynthError, match="camera positions"):
        interpolation_weights(np.zeros(3), np.zeros((0, 3)))
