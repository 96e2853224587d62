"""The lips' own colour (synth.appearance.lips): measured lips against the skin around them are
redder in hue, of about the same chroma, and darker except on the darkest skin; and the
``vermilion`` attribute marks the model's lips with the border on their outer loop."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance.lips import BORDER_VALUE, lip_albedo, vermilion_attribute
from synth.appearance.skin import cielab, melanin_for_ita, skin_albedo


def _lch(rgb):
    lab = cielab(np.asarray(rgb, np.float64))
    return lab[0], float(np.hypot(lab[1], lab[2])), float(np.degrees(np.arctan2(lab[2], lab[1])))


@pytest.mark.parametrize("haemoglobin", [0.005, 0.02, 0.05])  # the catalogue's range (skin.toml)
@pytest.mark.parametrize("ita", [70, 55, 41, 28, 10, -30, -55])
def test_lips_are_redder_same_chroma_and_darker_except_on_dark_skin(ita, haemoglobin):
    mel = float(melanin_for_ita(np.array([float(ita)]), np.array([haemoglobin]))[0])
    Ls, Cs, hs = _lch(skin_albedo(mel, haemoglobin))
    Ll, Cl, hl = _lch(lip_albedo(mel, haemoglobin))
    print(f"ITA {ita:+d}, blood {haemoglobin}: dL {Ll - Ls:+.1f}, dC {Cl - Cs:+.1f}, dh {hl - hs:+.1f}")
    assert hl < hs - 3.0  # redder: a smaller hue angle (skin is more yellow)
    assert abs(Cl - Cs) < 4.5  # chroma about the same
    if ita >= 28:  # light and intermediate skin: the vermilion is darker
        assert Ll < Ls - 0.5
    if ita <= -30:  # dark skin: not darker
        assert Ll > Ls - 1.0


def test_lip_albedo_stays_in_range_at_the_limits():
    for mel in (0.0, 1.0):
        for hb in (0.0, 1.0):
            rgb = np.asarray(lip_albedo(mel, hb))
            assert np.all(np.isfinite(rgb)) and np.all((rgb >= 0) & (rgb <= 1)), (mel, hb, rgb)


def test_vermilion_attribute_marks_the_lips_with_the_border_on_their_outer_loop():
    from synth.model.default import load_default_model

    d = load_default_model()
    V = d.num_vertices
    a = vermilion_attribute(V, d.regions, d.triangles)
    lips = np.zeros(V, bool)
    lips[np.asarray(d.regions["lips"])] = True
    assert a.shape == (V,) and np.all(a[~lips] == 0.0) and np.all(a[lips] > 0.0)
    border = a == BORDER_VALUE
    assert np.all(lips[border])
    # the border is one closed loop of the lips' outermost vertices: each border vertex touches
    # skin outside the lips, each other lips vertex does not
    t = d.triangles.astype(np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    mouth = np.zeros(V, bool)
    mouth[np.asarray(d.regions["mouth_interior"])] = True
    outside = ~lips & ~mouth
    touches = np.zeros(V, bool)
    touches[e[outside[e[:, 1]], 0]] = True
    touches[e[outside[e[:, 0]], 1]] = True
    assert np.array_equal(border, lips & touches)
    nb = border.sum()
    ring_edges = e[border[e[:, 0]] & border[e[:, 1]]]
    deg = np.bincount(np.unique(np.sort(ring_edges, 1), axis=0).ravel(), minlength=V)[border]
    assert nb >= 20 and np.all(deg >= 2), (nb, deg.min())
    # it surrounds the mouth: the mouth corners (ibug 48, 54) lie inside its x extent
    T = d.template.astype(np.float64)
    x = T[border, 0]
    assert x.min() < -0.02 and x.max() > 0.02


def test_no_vermilion_without_a_lips_region():
    assert vermilion_attribute(10, {"eyes": np.arange(3)}, np.zeros((0, 3), np.int64)) is None
    assert vermilion_attribute(10, {"lips": np.zeros(0, np.int64)}, np.zeros((0, 3), np.int64)) is None
