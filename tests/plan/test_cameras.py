"""Cameras: separation, look-at, feasibility bound, poles and degenerate ranges (hypothesis)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synth.config import CameraConfig
from synth.conventions import (blender_to_opencv_c2w, intrinsics, invert_rigid, look_at, opencv_to_blender_c2w,
                               orbit_camera_to_world, position_to_spherical, project, spherical_offset,
                               spherical_to_position)
from synth.errors import SynthError
from synth.plan import cameras


def _rigid_ok(M, tol=1e-9):
    R = M[..., :3, :3]
    eye = np.einsum("...ji,...jk->...ik", R, R)
    return np.allclose(eye, np.eye(3), atol=tol) and np.allclose(np.linalg.det(R), 1.0, atol=tol) and \
        np.all(np.isfinite(M))


@st.composite
def camera_regions(draw):
    a0 = draw(st.floats(-180, 180))
    aw = draw(st.sampled_from([0.0, 1.0, 30.0, 90.0, 200.0, 360.0]) | st.floats(0, 360))
    e0 = draw(st.sampled_from([-90.0, -45.0, 0.0, 89.0]) | st.floats(-90, 90))
    e1 = draw(st.sampled_from([90.0, e0]) | st.floats(e0, 90))
    r0 = draw(st.floats(0.3, 2.0))
    r1 = draw(st.sampled_from([r0]) | st.floats(r0, 3.0))
    sep = draw(st.sampled_from([0.0, 5.0, 25.0, 60.0]) | st.floats(0, 120))
    return CameraConfig(azimuth_deg=(a0, min(a0 + aw, 360.0)), elevation_deg=(e0, e1), radius_m=(r0, r1),
                        min_separation_deg=sep, elevation_sampling=draw(st.sampled_from(["area", "angle"])),
                        roll_deg=draw(st.sampled_from([(0.0, 0.0), (-20.0, 20.0)])),
                        max_candidates=4000, restarts=4)


@settings(max_examples=120, deadline=None)
@given(cam=camera_regions(), frac=st.floats(0.05, 0.35), seed=st.integers(0, 2**64 - 1))
def test_views_are_separated_inside_the_region_and_look_at_the_target(cam, frac, seed):
    bound = cameras.max_views(cam.azimuth_deg, cam.elevation_deg, cam.min_separation_deg)
    n = 12 if bound is None else max(1, min(12, int(frac * bound)))
    ii, ee = np.array([0, 0, 5]), np.array([0, 1, 2])
    v = cameras.sample_views(seed, ii, ee, n, cam)
    az, el, r = v.azimuth_deg, v.elevation_deg, v.radius_m
    assert np.all((az >= cam.azimuth_deg[0]) & (az <= cam.azimuth_deg[1]))
    assert np.all((el >= cam.elevation_deg[0]) & (el <= cam.elevation_deg[1]))
    assert np.all((r >= cam.radius_m[0]) & (r <= cam.radius_m[1]))
    if n > 1:
        sep = cameras.effective_separation(cam.min_separation_deg)
        assert cameras.min_pairwise_angle_deg(az, el).min() >= sep * (1 - 1e-6) - 1e-9
    target = np.array([0.01, -0.08, 0.03])
    roll = np.full(az.shape, 7.5)
    c2w = orbit_camera_to_world(az, el, r, target, roll)
    w2c = invert_rigid(c2w)
    assert _rigid_ok(c2w) and np.allclose(w2c @ c2w, np.eye(4), atol=1e-9)
    K = intrinsics(64, 48, 30.0, (1.5, -2.0))
    uv, z = project(K, w2c.reshape(-1, 4, 4), np.broadcast_to(target, (az.size, 1, 3)))
    assert np.allclose(uv[:, 0], [K[0, 2], K[1, 2]], atol=1e-7)  # the target is on the optical axis
    assert np.allclose(z[:, 0], r.ravel(), rtol=1e-9)  # at the sampled distance, in front
    # the viewing direction is the optical axis
    assert np.allclose(c2w[..., :3, 2], -spherical_offset(az, el), atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(cam=camera_regions(), seed=st.integers(0, 2**32))
def test_views_are_order_independent(cam, seed):
    bound = cameras.max_views(cam.azimuth_deg, cam.elevation_deg, cam.min_separation_deg)
    n = 6 if bound is None else max(1, min(6, bound // 4))
    ii = np.repeat(np.arange(10), 3)
    ee = np.tile(np.arange(3), 10)
    a = cameras.sample_views(seed, ii, ee, n, cam)
    perm = np.random.default_rng(seed).permutation(ii.size)[:11]
    b = cameras.sample_views(seed, ii[perm], ee[perm], n, cam)
    for f in ("azimuth_deg", "elevation_deg", "radius_m", "candidates", "restarts"):
        assert np.array_equal(getattr(a, f)[perm], getattr(b, f))


@pytest.mark.parametrize("el", [90.0, -90.0, 89.9999999, -89.9999999])
@pytest.mark.parametrize("az", [0.0, 37.0, -180.0, 180.0])
def test_look_at_is_well_defined_at_the_poles(az, el):
    target = np.array([0.0, 0.0, 1.6])
    c2w = orbit_camera_to_world(az, el, 1.0, target)
    assert _rigid_ok(c2w)
    _, z = project(np.eye(3), invert_rigid(c2w), target[None])
    assert np.isclose(z[0], 1.0)
    # a general look-at from the same eye agrees on the optical axis and stays rigid
    L = look_at(c2w[:3, 3], target)
    assert _rigid_ok(L) and np.allclose(L[:3, 2], c2w[:3, 2], atol=1e-6)


def test_orbit_frame_is_continuous_through_the_pole():
    a = orbit_camera_to_world(20.0, 90.0 - 1e-7, 1.0, np.zeros(3))
    b = orbit_camera_to_world(20.0, 90.0, 1.0, np.zeros(3))
    assert np.allclose(a, b, atol=1e-6)


def test_look_at_uses_world_up_and_matches_the_orbit_frame():
    for az, el in ((0, 0), (45, 20), (-120, -30), (170, 60)):
        o = orbit_camera_to_world(az, el, 2.0, np.array([0.1, 0.2, 0.3]))
        L = look_at(o[:3, 3], [0.1, 0.2, 0.3])
        assert np.allclose(o, L, atol=1e-9)
    front = orbit_camera_to_world(0.0, 0.0, 1.0, np.zeros(3))
    assert np.allclose(front[:3, :3].T, [[1, 0, 0], [0, 0, -1], [0, 1, 0]])  # rows: x right = +X, y down = -Z,
    # z forward = +Y
    with pytest.raises(ValueError):
        look_at([0, 0, 0], [0, 0, 0])


def test_zero_width_ranges_and_single_radius():
    cam = CameraConfig(azimuth_deg=(30.0, 30.0), elevation_deg=(10.0, 10.0), radius_m=(1.0, 1.0),
                       min_separation_deg=0.0)
    v = cameras.sample_views(1, np.array([0]), np.array([0]), 5, cam)
    assert np.all(v.azimuth_deg == 30.0) and np.all(v.elevation_deg == 10.0) and np.all(v.radius_m == 1.0)
    assert cameras.max_views((30, 30), (10, 10), 5.0) == 1
    with pytest.raises(SynthError, match="at most 1"):
        cameras.check_feasible(dataclasses.replace(cam, min_separation_deg=5.0), 2)


def test_spherical_round_trip_and_conventions():
    rng = np.random.default_rng(0)
    az, el, r = rng.uniform(-179, 179, 50), rng.uniform(-89, 89, 50), rng.uniform(0.1, 3, 50)
    t = rng.normal(size=3)
    a2, e2, r2 = position_to_spherical(spherical_to_position(az, el, r, t), t)
    assert np.allclose(a2, az) and np.allclose(e2, el) and np.allclose(r2, r)
    assert np.allclose(spherical_to_position(90.0, 0.0, 1.0, np.zeros(3)), [1, 0, 0], atol=1e-12)  # subject's left
    assert np.allclose(spherical_to_position(0.0, 0.0, 1.0, np.zeros(3)), [0, -1, 0], atol=1e-12)  # in front
    c2w = orbit_camera_to_world(az, el, r, t)
    assert np.allclose(blender_to_opencv_c2w(opencv_to_blender_c2w(c2w)), c2w)
    bl = opencv_to_blender_c2w(c2w)
    assert np.allclose(bl[..., :3, 2], -c2w[..., :3, 2]) and np.allclose(bl[..., :3, 1], -c2w[..., :3, 1])


def test_packing_bound_known_cases():
    full = ((-180, 180), (-90, 90))
    assert cameras.max_views(*full, 180.0) == 2  # antipodes
    assert cameras.max_views(*full, 90.0) == 6  # octahedron (tight)
    assert cameras.max_views(*full, 0.0) is None
    # the bound grows as the angle shrinks, and the region matters
    assert cameras.max_views(*full, 25.0) > cameras.max_views((-180, 180), (-45, 70), 25.0) > \
        cameras.max_views((-90, 90), (-30, 30), 25.0)


@pytest.mark.parametrize("az, el, deg", [((-180, 180), (-45, 70), 12.5), ((-60, 40), (-20, 30), 10.0),
                                         ((-170, 170), (-90, -80), 30.0), ((0, 0), (85, 90), 20.0)])
def test_grown_region_area_matches_monte_carlo(az, el, deg):
    r = np.deg2rad(deg)
    rng = np.random.default_rng(1)
    x = rng.standard_normal((60000, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    a = np.linspace(*az, 181)
    e = np.degrees(np.arcsin(np.linspace(*np.sin(np.deg2rad(el)), 181)))
    A, E = np.meshgrid(a, e)
    pts = spherical_offset(A.ravel(), E.ravel())
    inside = np.zeros(len(x), bool)
    for s in range(0, len(x), 5000):
        inside[s:s + 5000] = (x[s:s + 5000] @ pts.T).max(axis=1) >= np.cos(r)
    mc = 4 * np.pi * inside.mean()
    sigma = 4 * np.pi * np.sqrt(inside.mean() * (1 - inside.mean()) / len(x))
    assert abs(cameras.expanded_area(az, el, r) - mc) < 4 * sigma + 0.01 * mc


def test_infeasible_requests_are_refused_with_the_largest_count():
    cam = CameraConfig(azimuth_deg=(-30.0, 30.0), elevation_deg=(-10.0, 10.0))
    n_max = cameras.max_views(cam.azimuth_deg, cam.elevation_deg, 25.0)
    cameras.check_feasible(cam, n_max)
    with pytest.raises(SynthError) as e:
        cameras.check_feasible(cam, n_max + 1)
    assert f"at most {n_max} fit" in str(e.value) and "\n" not in str(e.value)


def test_sampling_is_bounded_and_reports_failure():
    cam = CameraConfig(max_candidates=3000, restarts=2)
    n = cameras.max_views(cam.azimuth_deg, cam.elevation_deg, cam.min_separation_deg)  # feasible by the bound
    t = time.perf_counter()
    with pytest.raises(SynthError, match="could not place"):
        cameras.sample_views(0, np.arange(4), np.zeros(4, int), n, cam)
    assert time.perf_counter() - t < 10
    v = cameras.sample_views(0, np.arange(4), np.zeros(4, int), n, cam, strict=False)
    assert not v.filled.any() and np.all(v.candidates <= cam.max_candidates)


def test_default_region_fits_the_paper_setting_comfortably():
    cam = CameraConfig()
    v = cameras.sample_views(7, np.repeat(np.arange(50), 13), np.tile(np.arange(13), 50), 30, cam)
    assert v.restarts.sum() == 0 and cameras.min_pairwise_angle_deg(v.azimuth_deg, v.elevation_deg).min() >= 25.0
