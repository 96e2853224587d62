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
    mats = bmat.head_materials(None, (0.5, 0.3, 0.2))
    from synth.dataset.segmentation import CLASSES

    bsdf = bmat.principled(mats[CLASSES["teeth"]])
    np.testing.assert_allclose(tuple(bsdf.inputs["Base Color"].default_value)[:3], TOOTH_ALBEDO, atol=1e-6)


@pytest.mark.parametrize("sd", [0.0, 3.0, -3.0])
def test_arch_coordinate_puts_the_gaps_along_the_arch(default_head, sd):
    """Per jaw: 0 on the midline, mirror vertices get opposite values, the value grows along the
    arch from the midline to the last molar (7 teeth a side: its end at +-7), for the mean head
    and +-3 SD identities."""
    from synth.appearance.teeth import CROWN_WIDTHS_MM, arch_attribute, arch_coordinate

    hm = default_head
    d = hm.data
    beta = sd * np.where(np.arange(d.identity_dims) % 2 == 0, 1.0, -1.0)
    V = hm.evaluate(beta, np.zeros(d.expression_dims), np.zeros((hm.J, 3))).vertices[0].astype(np.float64)
    for name, jaw in (("teeth_upper", "upper"), ("teeth_lower", "lower")):
        idx = np.asarray(d.regions[name])
        P = V[idx]
        u = arch_coordinate(P, jaw)
        assert np.isfinite(u).all()
        n_teeth = len(CROWN_WIDTHS_MM[jaw])
        assert np.abs(u).max() == pytest.approx(n_teeth, abs=1e-9) and np.abs(u).max() <= n_teeth
        assert np.all(np.abs(u[np.abs(P[:, 0]) < 1e-6]) < 1e-6)  # the midline
        # mirror partners (x -> -x) get opposite values
        mirror = np.array([np.argmin(np.linalg.norm(P - p * [-1, 1, 1], axis=1)) for p in P])
        close = np.linalg.norm(P[mirror] - P * [-1, 1, 1], axis=1) < 1e-5
        assert close.mean() > 0.9
        np.testing.assert_allclose(u[mirror[close]], -u[close], atol=0.05)
        # along the arch: ordered by the angle around the arch's back midpoint, the value grows
        c = np.array([0.5 * (P[:, 0].min() + P[:, 0].max()), P[:, 1].max()])
        th = np.arctan2(P[:, 0] - c[0], -(P[:, 1] - c[1]))
        assert np.all(np.diff(u[np.argsort(th, kind="stable")]) >= -1e-9)
    arch = arch_attribute(len(V), d.regions, V)
    assert arch.shape == (len(V),) and np.isfinite(arch).all()
    assert np.all(arch[np.setdiff1d(np.arange(len(V)), d.regions["teeth"])] == 0.5)


def test_arch_coordinate_rejects_bad_input():
    from synth.appearance.teeth import arch_attribute, arch_coordinate

    with pytest.raises(ValueError, match="8 finite"):
        arch_coordinate(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="8 finite"):
        arch_coordinate(np.full((20, 3), np.nan))
    assert arch_attribute(10, {"teeth": np.arange(3)}, np.zeros((10, 3))) is None
