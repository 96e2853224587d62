"""benchmarks/skin_spectrum.py: band contrast of known patterns and the patch placement."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import skin_spectrum as ss  # noqa: E402


def _grid(n):
    return np.mgrid[0:n, 0:n].astype(np.float64)


@pytest.mark.parametrize("wavelength,band", [(3.0, 0), (6.0, 1), (12.0, 2)])
def test_a_sinusoid_lands_in_its_band_with_its_rms_contrast(wavelength, band):
    y, x = _grid(96)
    amp = 0.04
    patch = 0.5 * (1.0 + amp * np.sin(2 * np.pi * (x + 0.3 * y) / wavelength / np.hypot(1, 0.3)))
    got = ss.band_contrast(patch)
    assert got[band] == pytest.approx(amp / np.sqrt(2), rel=0.15)
    assert all(got[k] < 0.2 * got[band] for k in range(len(ss.BANDS)) if k != band)


def test_shading_and_a_flat_patch_carry_no_detail():
    y, x = _grid(64)
    assert np.allclose(ss.band_contrast(0.3 + 0.002 * x - 0.001 * y), 0.0, atol=1e-6)
    assert np.allclose(ss.band_contrast(np.full((32, 32), 0.7)), 0.0)
    assert np.allclose(ss.band_contrast(np.zeros((32, 32))), 0.0)  # black: no contrast defined, none reported


def test_patches_sit_on_the_cheeks_and_above_the_brows_and_scale_with_the_face():
    lm = np.zeros((68, 2))
    lm[36], lm[45] = (40, 50), (100, 50)  # outer eye corners: IOD 60 px
    lm[41], lm[46] = (48, 55), (92, 55)
    lm[31], lm[35] = (62, 75), (78, 75)
    lm[48], lm[54] = (55, 90), (85, 90)
    lm[2], lm[14] = (35, 85), (105, 85)
    lm[19], lm[24] = (50, 40), (90, 40)
    lm[27], lm[33] = (70, 50), (70, 78)
    t = np.linspace(0, np.pi, 17)
    lm[0:17] = np.stack([70 - 60 * np.cos(t), 50 + 60 * np.sin(t)], 1)  # the face's outline: jaw and brows
    lm[17:27] = np.stack([np.linspace(12, 128, 10), np.full(10, 38.0)], 1)
    lm[19], lm[24] = (50, 40), (90, 40)
    lm[2], lm[14] = (35, 85), (105, 85)
    b = ss.patch_boxes(lm, 0.3)
    (rx, ry, rs), (lx, ly, ls), (fx, fy, fs) = b["cheek_r"], b["cheek_l"], b["forehead"]
    assert rx + lx == pytest.approx(140) and ry == pytest.approx(ly) and rs == ls == pytest.approx(18)
    assert fx == pytest.approx(70) and fy == pytest.approx(40 - 0.35 * 60)
    luma = np.random.default_rng(0).uniform(0.4, 0.6, (140, 140))
    p = ss.face_patches(luma, lm, 120.0, 0.3)  # scaled x2: 36 px patches
    assert {k: v.shape for k, v in p.items()} == {k: (36, 36) for k in b}


def test_a_cheek_patch_across_the_outline_is_left_out():
    t = np.linspace(0, np.pi, 17)
    lm = np.zeros((68, 2))
    lm[0:17] = np.stack([70 - 40 * np.cos(t), 50 + 40 * np.sin(t)], 1)  # jaw: a half circle below y = 50
    lm[17:27] = np.stack([np.linspace(32, 108, 10), np.full(10, 45.0)], 1)
    assert ss.on_the_face(lm, (70, 70, 10))
    assert not ss.on_the_face(lm, (108, 70, 10))  # over the jaw line
