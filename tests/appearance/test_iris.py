"""The iris colour model (synth.appearance.iris): melanin over a scattering stroma."""

from __future__ import annotations

import numpy as np


def test_iris_colour_model():
    from synth.appearance.iris import iris_colour, iris_palette, pupil_ratio

    blue = np.array(iris_colour(0.05, 0.8))
    grey = np.array(iris_colour(0.12, 0.45))
    brown = np.array(iris_colour(0.9, 0.6))
    assert blue[2] > blue[0] and blue[2] > blue[1]  # low melanin: scattering blue
    assert brown[0] > brown[1] > brown[2]  # high melanin: brown
    assert grey.sum() < blue.sum()  # weaker scattering: greyer, darker
    lum = [np.dot(iris_colour(m, 0.6), (0.2126, 0.7152, 0.0722)) for m in np.linspace(0, 1, 11)]
    assert np.all(np.diff(lum) < 0)  # more melanin, darker
    assert all(0 <= c <= 1 for c in brown)
    assert pupil_ratio(0.0) < pupil_ratio(1.0) < 0.7
    pal = iris_palette({"melanin": 0.5, "central_heterochromia": 0.6})
    assert set(pal) == {"base", "light", "dark", "inner", "limbal"}
