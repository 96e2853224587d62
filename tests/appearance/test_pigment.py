"""Hair pigment model: named colours -> melanin concentrations -> Blender's Melanin inputs."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance import pigment as pig

MANIFEST_COLOURS = ("black", "dark_brown", "brown", "light_brown", "blonde", "red", "grey", "white")


def test_every_manifest_colour_is_defined_and_in_range():
    for name in MANIFEST_COLOURS:
        p = pig.pigment(name)
        assert 0.0 <= p.melanin < 1.0 and 0.0 <= p.redness <= 1.0
        assert 0.0 <= p.white_fraction <= 1.0
        assert np.all(p.absorption() > 0)
    with pytest.raises(ValueError):
        pig.pigment("green")


def test_blender_mapping_round_trips():
    eu = np.array([0.0, 0.2, 1.3, 8.0])
    ph = np.array([0.1, 0.1, 0.3, 0.3])
    m, r = pig.to_blender(eu, ph)
    eu2, ph2 = pig.from_blender(m, r)
    np.testing.assert_allclose(eu2, eu, atol=1e-9)
    np.testing.assert_allclose(ph2, ph, atol=1e-9)
    # Blender's default (Melanin 0.8, Redness 1.0) is pure pheomelanin of -ln(0.2)
    e, p = pig.from_blender(0.8, 1.0)
    assert e == pytest.approx(0.0) and p == pytest.approx(-np.log(0.2))


def test_colours_are_ordered_by_lightness_and_red_is_red():
    lum = {n: float(pig.approx_reflectance(pig.COLOURS[n].eumelanin, pig.COLOURS[n].pheomelanin)
                    @ [0.2126, 0.7152, 0.0722]) for n in MANIFEST_COLOURS}
    assert lum["black"] < lum["dark_brown"] < lum["brown"] < lum["light_brown"] < lum["blonde"]
    rgb = pig.approx_reflectance(pig.COLOURS["red"].eumelanin, pig.COLOURS["red"].pheomelanin)
    assert rgb[0] > 2 * rgb[1] > 0 and rgb[1] > rgb[2]
    assert pig.COLOURS["red"].redness > 0.8 > pig.COLOURS["brown"].redness
    assert pig.COLOURS["white"].white_fraction > pig.COLOURS["grey"].white_fraction > 0


def test_sample_is_deterministic_and_close():
    a = pig.sample("brown", np.random.default_rng(3))
    b = pig.sample("brown", np.random.default_rng(3))
    assert a == b
    ref = pig.COLOURS["brown"]
    assert 0.5 < a.eumelanin / ref.eumelanin < 2.0
    d = a.as_dict()
    assert set(d) >= {"melanin", "melanin_redness", "eumelanin", "pheomelanin", "white_fraction"}
