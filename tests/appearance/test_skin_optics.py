"""Skin reflectance beyond the albedo (``synth.appearance.skin_optics``)."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance import skin_optics as so


def test_subsurface_radii_reproduce_jensen_2001():
    # Jensen et al. 2001, skin 1: the diffuse falloff (1/sigma_tr) it implies, by hand per channel
    want = [1.0 / np.sqrt(3 * a * (a + s)) for a, s in zip(so.SIGMA_A, so.SIGMA_S_REDUCED)]
    np.testing.assert_allclose(so.diffuse_mean_free_path_mm(), want, rtol=1e-12)
    np.testing.assert_allclose(want, [3.67, 1.37, 0.68], atol=0.01)
    radius, scale = so.subsurface(1.0)
    assert radius[0] == 1.0 and radius[0] > radius[1] > radius[2] > 0  # red scatters furthest
    assert scale == pytest.approx(0.00367, abs=1e-5)
    assert so.subsurface(1.2)[1] == pytest.approx(1.2 * scale)


def test_sharp_lobe_is_sharper_and_grows_with_oil():
    a, b = so.sharp_lobe(0.5, 0.0), so.sharp_lobe(0.5, 0.8)
    assert a["Coat Roughness"] < 0.5 and b["Coat Weight"] > a["Coat Weight"]
    assert so.sharp_lobe(0.5, 100.0)["Coat Weight"] == 1.0


@pytest.mark.parametrize("pixel,period,want", [(0.001, 0.002, 1.0), (0.001, 0.005, 1.0), (0.001, 0.001, 0.0),
                                               (0.001, 0.0005, 0.0), (0.001, 0.0015, 0.5), (0.0, 0.001, 1.0)])
def test_detail_weight_rule(pixel, period, want):
    assert so.detail_weight(pixel, period) == pytest.approx(want)


def test_subpixel_roughness():
    assert so.subpixel_roughness(0.4, [(1.0, 0.5)]) == pytest.approx(0.4)  # resolved: unchanged
    assert so.subpixel_roughness(0.4, [(0.0, 0.09)]) == pytest.approx(0.5)  # sqrt(0.16 + 0.09)
    assert so.subpixel_roughness(0.9, [(0.0, 5.0)]) == 1.0


def test_pixel_footprint_from_cameras():
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world
    from synth.plan.records import Camera

    target = np.array([0.0, -0.1, 0.7])
    cams = []
    for radius, res in ((1.0, 256), (0.5, 256), (1.0, 512)):
        K = intrinsics(res, res, 24.0)
        c2w = orbit_camera_to_world(30.0, 10.0, radius, target)
        cams.append(Camera(K, invert_rigid(c2w), c2w, res, res, 0.05, 10.0, 30.0, 10.0, radius, tuple(target)))
    fx = [np.asarray(c.K)[0, 0] for c in cams]
    got = so.pixel_footprint_m(cams)
    assert got == pytest.approx(min(1.0 / fx[0], 0.5 / fx[1], 1.0 / fx[2]))
    assert so.pixel_footprint_m([], 256) == pytest.approx(0.2 / (0.6 * 256))
    with pytest.raises(ValueError):
        so.pixel_footprint_m(None)
