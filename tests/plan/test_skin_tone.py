"""Skin tones in the plan: ITA targets over the six categories (synth.plan.skin)."""

from __future__ import annotations

import numpy as np
import pytest

from synth.appearance.skin import ita_category
from synth.config import load_config
from synth.configkit import ConfigError
from synth.plan.skin import apply_skin_tones, category_intervals, ita_from_uniform

LIMITS = (-55.0, 62.0)


def test_intervals_follow_the_dermatology_scale():
    iv = category_intervals(LIMITS)
    assert iv.tolist() == [[55, 62], [41, 55], [28, 41], [10, 28], [-30, 10], [-55, -30]]


def test_uniform_weights_fill_every_category_equally():
    u = (np.arange(60000) + 0.5) / 60000
    ita = ita_from_uniform(u, [1] * 6, LIMITS)
    assert np.all(np.diff(ita) < 0) and ita.max() < 62 and ita.min() > -55
    assert np.bincount(ita_category(ita), minlength=6).tolist() == [10000] * 6
    # uniform within a category: the 'tan' draws are evenly spread over 10..28
    tan = np.sort(ita[ita_category(ita) == 3])
    assert np.allclose(tan, np.linspace(28, 10, tan.size)[::-1], atol=0.01)


def test_weights_and_edges():
    u = np.linspace(0.0, 1.0, 10001)[:-1]  # uniforms lie in [0, 1)
    ita = ita_from_uniform(u, [0, 0, 1, 0, 3, 0], LIMITS)
    counts = np.bincount(ita_category(ita), minlength=6)
    assert counts[[0, 1, 3, 5]].sum() == 0 and abs(counts[4] / counts[2] - 3.0) < 0.01
    assert ita_from_uniform(0.0, [1] * 6, LIMITS) == pytest.approx(62.0)
    assert ita_from_uniform(np.nextafter(1.0, 0.0), [1] * 6, LIMITS) == pytest.approx(-55.0)
    top = np.nextafter(1.0, 0.0)
    assert ita_category(ita_from_uniform(top, [1, 1, 1, 1, 1, 0], LIMITS)) == 4  # never the empty 'dark'
    assert ita_category(ita_from_uniform(0.0, [0, 1, 1, 1, 1, 1], LIMITS)) == 1  # nor 'very light'


def test_tones_depend_on_the_identity_index_only():
    cfg = load_config()

    def assets(ids):
        a = [{"skin": {"params": {"haemoglobin": 0.005 + 0.001 * int(i)}}} for i in ids]
        apply_skin_tones(7, ids, a, cfg.skin)
        return [x["skin"]["params"] for x in a]

    whole, part = assets(np.arange(12)), assets(np.array([5, 6]))
    assert part == whole[5:7]
    assert all(set(p) == {"haemoglobin", "ita_deg", "melanin"} and 0 <= p["melanin"] <= 1 for p in whole)
    none = [{"skin": None}]
    apply_skin_tones(7, [0], none, cfg.skin)  # no skin pick: left alone
    assert none == [{"skin": None}]


@pytest.mark.parametrize("override,match", [("skin.ita_weights=[1, 1, 1]", "6 weights"),
                                            ("skin.ita_weights=[0, 0, 0, 0, 0, 0]", "not all zero"),
                                            ("skin.ita_limits_deg=[-20, 62]", "below -30")])
def test_bad_skin_config_is_refused(override, match):
    with pytest.raises(ConfigError, match=match):
        load_config(None, [override])
