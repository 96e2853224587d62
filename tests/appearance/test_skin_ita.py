"""The Individual Typology Angle against colour-science (sRGB -> XYZ -> CIELAB, D65)."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance.skin import individual_typology_angle, skin_albedo

colour = pytest.importorskip("colour", reason="colour-science (the render extra) is the oracle")


def _oracle(rgb):
    xyz = colour.RGB_to_XYZ(rgb, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False)
    L, _, b = colour.XYZ_to_Lab(xyz, colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])
    return np.degrees(np.arctan2(L - 50.0, b))


@pytest.mark.parametrize("rgb", [(0.266418, 0.098258, 0.020971), (0.6, 0.45, 0.35), (0.05, 0.03, 0.02),
                                 (0.001, 0.0008, 0.0005), (0.9, 0.9, 0.9)])
def test_ita_matches_colour_science(rgb):
    assert individual_typology_angle(rgb) == pytest.approx(_oracle(np.asarray(rgb)), abs=0.05)


def test_ita_orders_the_skin_model_by_melanin():
    itas = [float(individual_typology_angle(skin_albedo(m, 0.02))) for m in (0.02, 0.1, 0.3, 0.6)]
    assert itas == sorted(itas, reverse=True)
    assert itas[0] > 41 and itas[-1] < 10  # light through brown on the dermatology scale
    batch = individual_typology_angle(np.array([skin_albedo(0.02, 0.02), skin_albedo(0.6, 0.02)]))
    assert batch.shape == (2,) and batch[0] == pytest.approx(itas[0])


def test_cielab_matches_colour_science():
    from synth.appearance.skin import cielab

    rgb = np.array([[0.266418, 0.098258, 0.020971], [0.6, 0.45, 0.35], [0.001, 0.0008, 0.0005], [1.0, 1.0, 1.0]])
    xyz = colour.RGB_to_XYZ(rgb, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False)
    ref = colour.XYZ_to_Lab(xyz, colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])
    assert np.allclose(cielab(rgb), ref, atol=0.02)


def test_vectorised_albedo_matches_colour_science_integration():
    """albedos() (one linear map) against colour-science's own spectral integration per sample."""
    from synth.appearance.skin import WAVELENGTHS, albedos, reflectance

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    for m, hb in [(0.0, 0.005), (0.13, 0.02), (0.5, 0.05), (1.0, 1.0)]:
        sd = colour.SpectralDistribution(dict(zip(WAVELENGTHS.tolist(), reflectance(m, hb).tolist())))
        xyz = colour.sd_to_XYZ(sd, cmfs=cmfs, illuminant=colour.SDS_ILLUMINANTS["D65"]) / 100.0
        ref = np.clip(colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_encoding=False), 0, 1)
        assert np.allclose(albedos(m, hb), ref, atol=1e-9)
        assert np.allclose(skin_albedo(m, hb), ref, atol=1e-9)
    batch = albedos(np.array([[0.1, 0.2]]), np.array([[0.01, 0.03]]))
    assert batch.shape == (1, 2, 3) and np.allclose(batch[0, 1], albedos(0.2, 0.03))
    with pytest.raises(ValueError):
        albedos(1.2, 0.01)


def test_calibrated_model_stays_inside_measured_skin_colours():
    """Over the whole sampled range (ITA -55..62, haemoglobin 0.005-0.05) the albedo stays in
    the envelope of published skin measurements (docs/realism.md): L* 28-82, a* 6-20, b* 6-26."""
    from synth.appearance.skin import albedos, cielab, melanin_for_ita

    ita = np.linspace(-55.0, 62.0, 40)
    for hb in (0.005, 0.02, 0.05):
        lab = cielab(albedos(melanin_for_ita(ita, hb), hb))
        assert np.all((lab[:, 0] > 28) & (lab[:, 0] < 82)), lab[:, 0]
        assert np.all((lab[:, 1] > 6) & (lab[:, 1] < 20)), lab[:, 1]
        assert np.all((lab[:, 2] > 6) & (lab[:, 2] < 26)), lab[:, 2]
        # b* peaks in between: lower for very light and for dark skin than for tan skin
        assert lab[0, 2] < lab[len(ita) // 2, 2] and lab[-1, 2] < lab[len(ita) // 2, 2]


def test_melanin_for_ita_against_a_dense_search():
    from synth.appearance.skin import albedos, melanin_for_ita

    grid = np.linspace(0.0, 1.0, 20001)
    for hb in (0.005, 0.04):
        ita_grid = individual_typology_angle(albedos(grid, hb))
        assert np.all(np.diff(ita_grid) < 0)  # monotone: the bisection is well posed
        targets = np.array([-50.0, -30.0, 0.0, 10.0, 28.0, 41.0, 55.0, 60.0])
        m = melanin_for_ita(targets, hb)
        ref = np.interp(-targets, -ita_grid, grid)
        assert np.allclose(m, ref, atol=2e-4)
        assert np.allclose(individual_typology_angle(albedos(m, hb)), targets, atol=1e-4)
    # beyond the model's reach: the nearest end of [0, 1]
    assert melanin_for_ita(89.0, 0.02) < 1e-6 and melanin_for_ita(-89.0, 0.02) > 1 - 1e-6


def test_ita_categories():
    from synth.appearance.skin import ita_category

    got = ita_category(np.array([70.0, 55.0, 54.9, 41.0, 30.0, 28.0, 10.0, 0.0, -30.0, -30.1, -60.0]))
    assert got.tolist() == [0, 1, 1, 2, 2, 3, 4, 4, 5, 5, 5]


def test_precomputed_spectrum_to_srgb_is_colour_sciences_value_for_value():
    """synth.appearance.cie_srgb (so planning never imports colour-science) is exactly the
    matrix colour-science's integration gives."""
    from synth.appearance.cie_srgb import SPECTRUM_TO_LINEAR_SRGB, from_colour_science

    assert np.array_equal(SPECTRUM_TO_LINEAR_SRGB, from_colour_science())


def test_cielab_goes_back_through_colour_sciences_srgb_matrix():
    """CIELAB of linear sRGB uses the inverse of the matrix the spectra went through to linear
    sRGB, so a spectrum's XYZ comes back as colour-science computes it, and the sRGB white is
    L* 100, a* = b* = 0."""
    import colour

    from synth.appearance.cie_srgb import LINEAR_SRGB_TO_XYZ, srgb_to_xyz_from_colour_science
    from synth.appearance.skin import cielab

    assert np.array_equal(LINEAR_SRGB_TO_XYZ, srgb_to_xyz_from_colour_science())
    rgb = np.random.default_rng(3).random((50, 3))
    white = LINEAR_SRGB_TO_XYZ.sum(axis=1)
    want = colour.XYZ_to_Lab(rgb @ LINEAR_SRGB_TO_XYZ.T, colour.XYZ_to_xy(white))
    np.testing.assert_allclose(cielab(rgb), want, atol=1e-9)
    np.testing.assert_allclose(cielab([1.0, 1.0, 1.0]), [100.0, 0.0, 0.0], atol=1e-9)


def test_planning_does_not_import_colour_science():
    import subprocess
    import sys

    code = ("import sys; from synth.plan.skin import *; from synth.appearance.skin import melanin_for_ita;"
            "melanin_for_ita([20.0], [0.02]); print('colour' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout == "False\n"
