"""The gaze's truncated normal (synth.plan.expressions.truncated_normal_ppf, computed by
synth.geometry.exact so that it is the same bits on every machine) agrees with
scipy.stats.truncnorm.ppf to rounding, and the plan's 8-decimal values of it are scipy's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import truncnorm

from synth.plan.expressions import truncated_normal_ppf

LIMITS = [(-25.0, 25.0, 6.0), (-15.0, 15.0, 6.0), (-50.0, 3.0, 0.1), (-1.0, 45.0, 90.0), (-30.0, 10.0, 12.5),
          (-0.5, 0.25, 0.1), (1.5, 6.0, 3.0), (-9.0, -2.0, 1.0)]


@pytest.mark.parametrize("lo, hi, sd", LIMITS)
def test_agrees_with_scipy(lo, hi, sd):
    rng = np.random.default_rng(0)
    u = np.concatenate([rng.random(50_000), [0.0, 1.0, 1e-300, 1e-30, 1 - 1e-16, 0.5], np.linspace(0, 1, 1001)])
    got, want = truncated_normal_ppf(u, lo / sd, hi / sd), truncnorm.ppf(u, lo / sd, hi / sd)
    assert np.all((got >= lo / sd) & (got <= hi / sd))
    assert np.max(np.abs(got - want)) < 2e-14
    assert np.array_equal(np.round(got * sd, 8), np.round(want * sd, 8))  # what a plan stores, in degrees


def test_monotone_and_ends():
    u = np.linspace(0.0, 1.0, 20001)
    x = truncated_normal_ppf(u, -2.0, 3.0)
    assert x[0] == -2.0 and x[-1] == 3.0 and np.all(np.diff(x) >= 0.0)
    assert np.array_equal(truncated_normal_ppf(np.array([-0.5, 1.5]), -1.0, 1.0), [-1.0, 1.0])
