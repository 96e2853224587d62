"""synth.appearance.srgb, the one sRGB transfer function, against colour-science's."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance.srgb import linear_to_srgb, srgb8, srgb_to_linear

colour = pytest.importorskip("colour")


def test_matches_colour_science_and_round_trips():
    x = np.linspace(0.0, 1.0, 10001)
    assert np.allclose(linear_to_srgb(x), colour.cctf_encoding(x, function="sRGB"), rtol=0, atol=1e-12)
    assert np.allclose(srgb_to_linear(x), colour.cctf_decoding(x, function="sRGB"), rtol=0, atol=1e-12)
    assert np.allclose(srgb_to_linear(linear_to_srgb(x)), x, rtol=0, atol=1e-12)


def test_eight_bit_clips_and_rounds():
    assert srgb8(np.array([-1.0, 0.0, 1.0, 5.0])).tolist() == [0, 0, 255, 255]
    assert srgb8(srgb_to_linear(np.array([0.497, 0.503]))).tolist() == [127, 128]  # 126.7 and 128.3, rounded
