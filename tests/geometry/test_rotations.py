"""synth.geometry.rotations against scipy's Rotation: axis-angle <-> matrix at and near 0 and
180 degrees, the rigid fit (and a brute-force optimality check) with degenerate input, the
screw axis, the minimal rotation between two directions."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from synth.geometry.normals import normalize
from synth.geometry.rotations import (axis_angle_to_matrix, fit_rigid, matrix_to_axis_angle, rotate_between,
                                      rotation_pivot)

# --------------------------------------------------------------------------- rotations

def _rotvecs(rng):
    axes = normalize(rng.normal(size=(40, 3)))
    return np.concatenate([
        rng.normal(size=(200, 3)),
        rng.normal(size=(30, 3)) * 1e-9, np.zeros((1, 3)),  # near and at zero
        np.pi * np.eye(3), np.pi * axes,  # exactly 180 degrees
        (np.pi - 1e-7) * axes, (np.pi - 1e-4) * axes, (np.pi - 2e-3) * axes,  # near 180 degrees
    ])


def test_axis_angle_to_matrix_matches_scipy():
    r = _rotvecs(np.random.default_rng(3))
    np.testing.assert_allclose(axis_angle_to_matrix(r), Rotation.from_rotvec(r).as_matrix(), atol=1e-14)
    r32 = r.astype(np.float32)
    R32 = axis_angle_to_matrix(r32)
    assert R32.dtype == np.float32
    np.testing.assert_allclose(R32, Rotation.from_rotvec(r32.astype(np.float64)).as_matrix(), atol=1e-6)


def test_matrix_to_axis_angle_matches_scipy():
    r = _rotvecs(np.random.default_rng(4))
    R = Rotation.from_rotvec(r).as_matrix()
    got = matrix_to_axis_angle(R)
    want = Rotation.from_matrix(R).as_rotvec()
    angle = np.linalg.norm(want, axis=1)
    at_pi = angle > np.pi - 1e-6  # r and -r are the same rotation there: compare up to sign
    err = np.linalg.norm(got - want, axis=1)
    err[at_pi] = np.minimum(err[at_pi], np.linalg.norm(got[at_pi] + want[at_pi], axis=1))
    assert err.max() < 1e-7
    assert np.all(np.linalg.norm(got, axis=1) <= np.pi + 1e-12)


def _weighted_cost(R, t, src, dst, w):
    return np.sum(w * np.sum((src @ R.T + t - dst) ** 2, axis=1))


@pytest.mark.parametrize("rotvec", [[0.3, -0.2, 0.5], [np.pi, 0.0, 0.0], [0.0, np.pi - 1e-6, 0.0],
                                    list(np.pi * normalize(np.array([1.0, 2.0, -2.0]))), [1e-10, 0.0, 0.0]])
def test_fit_rigid_recovers_exact_motions(rotvec):
    rng = np.random.default_rng(5)
    src = rng.normal(size=(30, 3))
    R0 = Rotation.from_rotvec(rotvec).as_matrix()
    t0 = np.array([0.1, -2.0, 0.7])
    R, t = fit_rigid(src, src @ R0.T + t0)
    np.testing.assert_allclose(R, R0, atol=1e-12)
    np.testing.assert_allclose(t, t0, atol=1e-12)


def test_fit_rigid_is_the_weighted_optimum():
    rng = np.random.default_rng(6)
    src = rng.normal(size=(50, 3))
    R0 = Rotation.from_rotvec([0.4, 1.1, -0.3]).as_matrix()
    dst = src @ R0.T + [1.0, 2.0, 3.0] + 0.2 * rng.normal(size=src.shape)
    w = rng.uniform(0.1, 2.0, len(src))
    R, t = fit_rigid(src, dst, w)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    best = _weighted_cost(R, t, src, dst, w)
    # no other rotation does better: 2000 random ones and small perturbations in all directions
    # (each with its own optimal translation)
    others = Rotation.random(2000, random_state=7).as_matrix()
    small = Rotation.from_rotvec(1e-3 * normalize(rng.normal(size=(200, 3)))).as_matrix() @ R
    wn = w / w.sum()
    for Rc in np.concatenate([others, small]):
        tc = wn @ dst - Rc @ (wn @ src)
        assert _weighted_cost(Rc, tc, src, dst, w) >= best - 1e-12


def test_fit_rigid_degenerate_input():
    rng = np.random.default_rng(8)
    src = rng.normal(size=(12, 3))
    # mirrored target: still a proper rotation
    R, _ = fit_rigid(src, src * [-1.0, 1.0, 1.0])
    assert np.linalg.det(R) == pytest.approx(1.0)
    # zero weights drop points
    dst = src @ Rotation.from_rotvec([0.2, 0.1, 0.0]).as_matrix().T
    dst[:4] += 5.0  # outliers, weighted out
    w = np.r_[np.zeros(4), np.ones(8)]
    R, t = fit_rigid(src, dst, w)
    R8, t8 = fit_rigid(src[4:], dst[4:])
    np.testing.assert_allclose(R, R8, atol=1e-12)
    np.testing.assert_allclose(t, t8, atol=1e-12)
    # one point: identity rotation, pure translation
    R, t = fit_rigid(src[:1], src[:1] + 1.0)
    np.testing.assert_array_equal(R, np.eye(3))
    np.testing.assert_allclose(t, [1.0, 1.0, 1.0])
    # collinear points: the rotation about the line is undetermined; scipy warns, the line is still aligned
    line = np.outer(np.arange(5.0), [1.0, 0.0, 0.0])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        R, t = fit_rigid(line, line[:, [1, 0, 2]])
    assert caught and np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(line @ R.T + t, line[:, [1, 0, 2]], atol=1e-12)
    with pytest.raises(ValueError):
        fit_rigid(src, src[:5])
    with pytest.raises(ValueError):
        fit_rigid(src, src, -np.ones(len(src)))


def test_rotation_pivot_at_180_degrees():
    R = Rotation.from_rotvec([np.pi, 0.0, 0.0]).as_matrix()
    pivot = np.array([0.0, 0.5, -0.25])
    c, axis, slide = rotation_pivot(R, pivot - R @ pivot, 0)
    np.testing.assert_allclose(np.cross(c - pivot, axis), 0.0, atol=1e-12)  # c lies on the axis through pivot
    assert abs(abs(axis[0]) - 1.0) < 1e-12 and abs(slide) < 1e-12
    with pytest.raises(ValueError, match="no rotation"):
        rotation_pivot(np.eye(3), np.zeros(3))


def test_rotate_between_matches_scipy():
    rng = np.random.default_rng(6)
    a = rng.normal(size=(40, 3))
    b = rng.normal(size=(40, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    x = rng.normal(size=(40, 5, 3))
    got = rotate_between(a, b, x)
    for i in range(40):
        # the minimal rotation a -> b: axis a x b, angle acos(a . b)
        axis = np.cross(a[i], b[i])
        ang = np.arccos(np.clip(a[i] @ b[i], -1, 1))
        R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * ang)
        assert np.allclose(got[i], R.apply(x[i]), atol=1e-10)
        assert np.allclose(rotate_between(a[i:i + 1], b[i:i + 1], a[i][None, None])[0, 0], b[i], atol=1e-10)
    # no rotation when a == b; a quarter turn exactly
    e = np.eye(3)
    np.testing.assert_allclose(rotate_between(e[:1], e[:1], x[:1]), x[:1], atol=1e-15)
    np.testing.assert_allclose(rotate_between(e[:1], e[1:2], e[None, :1]), e[None, 1:2], atol=1e-15)
