"""Tooth enamel colour (synth.appearance.teeth) and the CIELAB inverse it is built with."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance.skin import cielab, linear_srgb_from_cielab
from synth.appearance.teeth import TOOTH_ALBEDO, TOOTH_CIELAB


def test_cielab_inverse_round_trips_including_the_dark_linear_segment():
    rng = np.random.default_rng(0)
    rgb = np.concatenate([rng.uniform(0.0, 1.0, (500, 3)), rng.uniform(0.0, 0.006, (200, 3)), np.eye(3),
                          np.zeros((1, 3)), np.ones((1, 3))])
    np.testing.assert_allclose(linear_srgb_from_cielab(cielab(rgb)), rgb, atol=1e-10)
    np.testing.assert_allclose(linear_srgb_from_cielab([100.0, 0.0, 0.0]), [1.0, 1.0, 1.0], atol=1e-9)


def test_teeth_have_the_measured_enamel_colour():
    """The teeth's albedo sits at the lightness of measured natural incisors (L* 80.6; b* chosen by
    eye below the measured 24), inside the sRGB gamut; the flat colour before (0.85, 0.82, 0.72)
    was L* 92.5, b* 6.8: lighter and whiter than teeth."""
    lab = cielab(np.asarray(TOOTH_ALBEDO))
    np.testing.assert_allclose(lab, TOOTH_CIELAB, atol=0.05)
    assert all(0.0 < c < 1.0 for c in TOOTH_ALBEDO)
    assert 78.0 <= lab[0] <= 85.0 and 10.0 <= lab[2] <= 25.0
    old = cielab(np.array([0.85, 0.82, 0.72]))
    assert old[0] > 90 and old[2] < 10


@pytest.mark.blender
def test_teeth_material_uses_the_measured_colour():
    pytest.importorskip("bpy")
    from blender_scripts import materials as bmat
    from blender_scripts import scene as bscene

    bscene.reset()
    mats = bmat.head_materials({}, (0.5, 0.3, 0.2))
    from synth.dataset.segmentation import CLASSES

    bsdf = bmat.principled(mats[CLASSES["teeth"]])
    np.testing.assert_allclose(tuple(bsdf.inputs["Base Color"].default_value)[:3], TOOTH_ALBEDO, atol=1e-6)
