"""Camera framing on the head: bounding spheres (brute force oracle) and fitted distances
(projection oracle)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
from synth.errors import SynthError
from synth.plan.assets import hair_reach_m
from synth.plan.cameras import fit_distances
from synth.plan.identities import head_spheres


def test_head_spheres_against_every_head_vertex(default_model):
    m = default_model
    rng = np.random.default_rng(5)
    codes = np.concatenate([rng.normal(size=(4, m.identity_dims)), 3.0 * np.ones((1, m.identity_dims)),
                            -3.0 * np.ones((1, m.identity_dims))])
    c, r = head_spheres(m, codes, 0.01)
    head = np.setdiff1d(m.regions["skin"], np.concatenate([m.regions["neck"], m.regions["shoulders"]]))
    B = m.identity_basis.astype(np.float64) * m.identity_scale.astype(np.float64)[:, None, None]
    for n in range(len(codes)):
        v = m.template[head] + np.einsum("k,kvc->vc", codes[n], B[:, head])
        box = 0.5 * (v.min(0) + v.max(0))
        assert np.allclose(c[n], box, atol=5e-4)  # extreme-vertex candidates: within half a millimetre
        assert r[n] - 0.01 == pytest.approx(np.linalg.norm(v - box, axis=1).max(), abs=5e-4)
        assert 0.08 < r[n] < 0.25


@pytest.mark.parametrize("W,H", [(64, 64), (320, 240), (200, 400)])
def test_fitted_distance_puts_the_sphere_at_the_fill(W, H):
    cam = SimpleNamespace(head_fill=(0.5, 1.0), near_m=0.05, far_m=10.0)
    rad = np.array([[0.15, 0.15, 0.2]])
    u = np.array([[1.0, 0.0, 1.0]])
    d = fit_distances(rad, u, cam, 30.0, (W, H))
    K = intrinsics(W, H, 30.0)
    centre = np.array([0.01, -0.05, 0.7])
    for j in range(3):
        c2w = orbit_camera_to_world(20.0, 10.0, d[0, j], centre)
        # the sphere's silhouette: points on it whose direction from the camera is tangent
        dirs = np.random.default_rng(j).normal(size=(20000, 3))
        pts = centre + rad[0, j] * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        uv, z = project(K, invert_rigid(c2w), pts)
        half = np.abs(uv - K[:2, 2])
        reach = max(half[:, 0].max() / (W / 2), half[:, 1].max() / (H / 2))
        fill = 1.0 if u[0, j] == 1.0 else 0.5
        if fill == 1.0:  # touches the shorter side, never crosses it
            assert 0.99 < reach <= 1.0 + 1e-6
        else:
            assert reach < 0.6
        assert (z > 0).all()


def test_fitted_distance_outside_near_far_is_refused():
    cam = SimpleNamespace(head_fill=(0.5, 0.6), near_m=0.05, far_m=0.5)
    with pytest.raises(SynthError, match="near_m"):
        fit_distances(np.array([[0.15]]), np.array([[0.5]]), cam, 24.0, (64, 64))


def test_hair_reach_from_the_planned_parameters():
    got = hair_reach_m([{"hair": {"params": {"length_m": 0.05}}}, {"hair": {"params": {"length_m": 0.5}}},
                        {"hair": {"params": {"bun_radius_m": 0.04}}, "headwear": {"id": "beanie"}},
                        {"hair": None}, {}])
    assert np.allclose(got, [0.03, 0.08, 0.08 + 0.03, 0.0, 0.0])
