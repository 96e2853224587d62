"""`python -m benchmarks.realism skin --frames` (benchmarks/realism/skin.py): the lips' pixels are left out of the mean skin pixel
(they have their own colour, synth.appearance.lips) by the ibug68 outer lip contour."""

from __future__ import annotations

import numpy as np

from benchmarks.realism import skin


def test_polygon_mask_takes_the_pixels_whose_centres_are_inside():
    mask = skin._polygon_mask
    # synth's pixel centres are at +0.5: a box from 1 to 5 by 1 to 4 holds columns 1-4, rows 1-3
    m = mask(np.array([[1.0, 1.0], [5.0, 1.0], [5.0, 4.0], [1.0, 4.0]]), 6, 7)
    want = np.zeros((6, 7), bool)
    want[1:4, 1:5] = True
    assert np.array_equal(m, want)
    # a triangle: the centre (x + 0.5, y + 0.5) is inside when x + y + 1 < 6
    m = mask(np.array([[0.0, 0.0], [6.0, 0.0], [0.0, 6.0]]), 6, 6)
    y, x = np.mgrid[0:6, 0:6]
    assert np.array_equal(m, x + y + 1 < 6)
    # a concave outline (the lip contour is one): the notch stays outside
    m = mask(np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 6.0], [3.0, 2.0], [0.0, 6.0]]), 6, 6)
    assert m[0, 3] and not m[4, 3] and not m[3, 3] and m[4, 0] and m[4, 5]
