"""The denoised alpha's merge rule (synth.dataset.alpha): exact 0/1 regions keep the raw alpha,
the coverage edges take the denoised one, clipped."""

from __future__ import annotations

import numpy as np

from synth.dataset.alpha import coverage_edges, merge_denoised_alpha


def test_edges_are_fractional_pixels_and_their_neighbours():
    a = np.zeros((7, 7), np.float32)
    a[:, 4:] = 1.0  # a hard vertical edge between columns 3 and 4
    e = coverage_edges(a)
    assert e[:, 3:5].all() and not e[:, :3].any() and not e[:, 5:].any()
    a[3, 1] = 0.25  # one fractional pixel in the empty part: it and its 8 neighbours
    e = coverage_edges(a)
    assert e[2:5, 0:3].all() and e.sum() == 14 + 9
    assert not coverage_edges(np.ones((4, 5))).any() and not coverage_edges(np.zeros((4, 5))).any()
    assert coverage_edges(np.full((3, 3), 0.5)).all()  # a uniformly translucent region (a lens)


def test_merge_takes_the_denoised_alpha_on_edges_only():
    rng = np.random.default_rng(0)
    truth = np.clip(np.linspace(-0.5, 1.5, 32), 0, 1)[None, :].repeat(16, 0)  # a soft ramp
    raw = np.clip(truth + rng.binomial(16, truth) / 16.0 - truth, 0, 1).astype(np.float32)  # 16-sample coverage
    raw[:, :6], raw[:, -6:] = 0.0, 1.0
    smooth = truth + rng.normal(0, 0.01, truth.shape)  # what a denoiser returns: near the truth
    smooth[0, 16] = np.nan
    out = merge_denoised_alpha(raw, smooth - 0.02)  # slightly negative at the empty end
    e = coverage_edges(raw)
    assert out.dtype == np.float32 and out.min() >= 0.0 and out.max() <= 1.0
    np.testing.assert_array_equal(out[~e], raw[~e])  # exact interior and background kept
    assert e[0, 16] and out[0, 16] == 0.0  # NaN from the denoiser: no coverage, never NaN
    e[0, 16] = False
    assert np.abs(out[e] - truth[e]).mean() < 0.5 * np.abs(raw[e] - truth[e]).mean()
