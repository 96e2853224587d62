"""`python -m benchmarks.realism body-end` (benchmarks/realism/frames.py): which frames show the body
ending inside the image, and the scalp measure."""

from __future__ import annotations

import numpy as np

from benchmarks.realism import frames


def test_body_ends_in_frame():
    r = frames
    seg = np.zeros((8, 8), np.uint32)
    assert not r.body_ends_in_frame(seg)  # no body at all: not counted
    seg[2:5, 3:5] = 9  # a garment floating in the frame
    assert r.body_ends_in_frame(seg)
    seg[5:, 3:5] = 1  # the neck's skin reaching the bottom row
    assert not r.body_ends_in_frame(seg)
    seg[5:, 3:5] = 5  # hair reaching it does not count as the body
    assert r.body_ends_in_frame(seg)


def test_scalp_measure_compares_skin_above_the_brows_with_the_face():
    from synth.dataset.segmentation import CLASSES as SEG

    r = frames
    H = W = 64
    lm = np.zeros((68, 2))
    lm[36], lm[45] = (20, 30), (44, 30)  # inter-ocular distance 24 px
    lm[17:27] = (32, 26)  # brows at row 26: the scalp lies above row 26 - 0.6 * 24 = 11.6
    lm[51] = (32, 44)  # upper lip: the face skin lies between rows 30 and 44
    seg = np.zeros((H, W), np.uint32)
    seg[:4] = SEG["hair"]
    seg[4:11, 10:54] = SEG["skin"]  # scalp between strands
    seg[11:60, 10:54] = SEG["skin"]
    alpha = np.ones((H, W))
    rgb = np.full((H, W, 3), 0.4)
    rgb[4:11] = 0.1  # a dark scalp
    rgb[:4] = 0.04  # the hair
    pixels, scalp_face, hair_face = r.scalp_measure(seg, rgb * alpha[..., None], alpha, lm)
    assert pixels == 8 * 44  # rows 4-11 (row 11 is above 11.6 too)
    assert np.isclose(scalp_face, 0.25) and np.isclose(hair_face, 0.1)
    # half-transparent scalp pixels (premultiplied colour): the alpha is divided out, so the ratio stays
    half = alpha.copy()
    half[4:12] = 0.5
    assert np.allclose(r.scalp_measure(seg, rgb * half[..., None], half, lm)[1:], (0.25, 0.1))
    seg[:4] = 0  # no hair in the frame: nothing to measure
    assert r.scalp_measure(seg, rgb, alpha, lm) is None
