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
