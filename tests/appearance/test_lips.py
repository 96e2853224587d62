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
    from synth.model.meshutil import barycentric_points, connected_components, triangle_edges

    d = load_default_model()
    V = d.num_vertices
    a = vermilion_attribute(V, d.regions, d.triangles)
    lips = np.zeros(V, bool)
    lips[np.asarray(d.regions["lips"])] = True
    mouth = np.zeros(V, bool)
    mouth[np.asarray(d.regions["mouth_interior"])] = True
    assert a.shape == (V,) and np.all(a[lips] > 0.0) and np.all(a[~lips & ~mouth] == 0.0)
    e = np.unique(np.sort(triangle_edges(d.triangles), 1), axis=0)
    # the inner lip: mouth-interior vertices next to the lips carry the lips' value, the rest 0
    next_to = np.zeros(V, bool)
    next_to[e[lips[e[:, 0]], 1]] = True
    next_to[e[lips[e[:, 1]], 0]] = True
    assert np.all(a[mouth & next_to] == 1.0) and np.all(a[mouth & ~next_to] == 0.0)
    # the border value lies on one closed loop round the mouth: a single cycle of edges
    border = np.nonzero(a == BORDER_VALUE)[0]
    ring = e[(a[e[:, 0]] == BORDER_VALUE) & (a[e[:, 1]] == BORDER_VALUE)]
    deg = np.bincount(ring.ravel(), minlength=V)[border]
    assert len(border) >= 20 and np.all(deg == 2), (len(border), np.unique(deg))
    assert np.unique(connected_components(ring, V, subset=border)[border]).size == 1  # connected: one loop
    # outside it nothing of the lips; it encloses the mouth corners (ibug 48 / 54) and the
    # lips' middle (ibug 51 above, 57 below) in the frontal (x, z) plane
    T = d.template.astype(np.float64)
    tri, bary = d.landmarks["ibug68"]
    lm = barycentric_points(T, d.triangles, tri, bary)
    x, z = T[border, 0], T[border, 2]
    assert x.min() <= lm[48, 0] and x.max() >= lm[54, 0]
    assert z.max() >= lm[51, 2] and z.min() <= lm[57, 2]


def test_no_vermilion_without_a_lips_region():
    assert vermilion_attribute(10, {"eyes": np.arange(3)}, np.zeros((0, 3), np.int64)) is None
    assert vermilion_attribute(10, {"lips": np.zeros(0, np.int64)}, np.zeros((0, 3), np.int64)) is None
