"""The gaze's truncated normal (synth.plan.expressions.truncated_normal_ppf) gives
scipy.stats.truncnorm.ppf's values bit for bit, so plans stay byte-identical while planning no
longer imports scipy.stats."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import truncnorm

from synth.plan.expressions import truncated_normal_ppf


@pytest.mark.parametrize("lo, hi, sd", [(-25.0, 25.0, 6.0), (-15.0, 15.0, 6.0), (-50.0, 3.0, 0.1), (-1.0, 45.0, 90.0),
                                        (-30.0, 10.0, 12.5), (-0.5, 0.25, 0.1)])
def test_bit_identical_to_scipy(lo, hi, sd):
    rng = np.random.default_rng(0)
    u = np.concatenate([rng.random(200_000), [0.0, 1.0, 1e-300, 1 - 1e-16, 0.5], np.linspace(0, 1, 1001)])
    got, want = truncated_normal_ppf(u, lo / sd, hi / sd), truncnorm.ppf(u, lo / sd, hi / sd)
    assert np.array_equal(got, want)


def test_limits_not_around_zero_use_scipy():
    u = np.linspace(0.01, 0.99, 7)
    assert np.array_equal(truncated_normal_ppf(u, 0.5, 2.0), truncnorm.ppf(u, 0.5, 2.0))
