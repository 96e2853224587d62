"""prior.encoding against exact rational moments and Monte-Carlo expectations."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import torch

from prior import encoding


def exact_moments(t0: float, t1: float, r: float):
    """(mean_t, var_t, var_r) of a point uniform in the frustum [t0, t1] of a cone with
    radius r t, in exact rational arithmetic: the density of t is prop. to t^2, so
    E[t^k] = 3 / (k + 3) (t1^(k+3) - t0^(k+3)) / (t1^3 - t0^3), and a point uniform in the
    disc of radius r t has per-axis variance (r t)^2 / 4."""
    a, b, rr = Fraction(t0), Fraction(t1), Fraction(r)
    if a == b:
        return float(a), 0.0, float(rr * rr * a * a / 4)

    def moment(k):
        return Fraction(3, k + 3) * (b ** (k + 3) - a ** (k + 3)) / (b ** 3 - a ** 3)

    m1, m2 = moment(1), moment(2)
    return float(m1), float(m2 - m1 * m1), float(rr * rr * m2 / 4)


CASES = [(0.5, 1.5, 0.01), (0.0, 1.0, 0.1), (1.0, 1.0001, 0.002), (100.0, 100.01, 0.001),
         (0.2, 0.2, 0.05), (3.0, 40.0, 0.3), (1e-4, 2e-4, 1.0), (0.9, 1.1, 0.0)]


@pytest.mark.parametrize("t0, t1, r", CASES)
def test_frustum_moments_match_exact_rational_moments(t0, t1, r):
    got = encoding.conical_frustum_moments(torch.tensor([t0]), torch.tensor([t1]), torch.tensor([r]))
    want = exact_moments(t0, t1, r)
    scale_t = max(abs(t1), 1e-12)
    assert got[0].item() == pytest.approx(want[0], rel=1e-6, abs=1e-7 * scale_t)
    # variances: float32 relative accuracy, even for short intervals far from the apex
    assert got[1].item() == pytest.approx(want[1], rel=2e-3, abs=1e-12)
    assert got[2].item() == pytest.approx(want[2], rel=1e-5, abs=1e-14)


def test_frustum_moments_zero_interval_at_origin_is_finite():
    got = encoding.conical_frustum_moments(torch.zeros(3), torch.zeros(3), torch.ones(3))
    for x in got:
        assert torch.isfinite(x).all() and (x == 0).all()


def test_frustum_gaussians_match_monte_carlo_points_in_the_frustum():
    rng = np.random.default_rng(0)
    o = np.array([0.1, -0.2, 0.3])
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    t0, t1, r, n = 0.6, 1.4, 0.08, 400_000
    # t with density prop. to t^2 on [t0, t1]; a uniform point in the disc of radius r t
    t = np.cbrt(t0 ** 3 + rng.random(n) * (t1 ** 3 - t0 ** 3))
    rho = r * t * np.sqrt(rng.random(n))
    phi = rng.random(n) * 2 * np.pi
    u = np.cross(d, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    pts = o + t[:, None] * d + (rho * np.cos(phi))[:, None] * u + (rho * np.sin(phi))[:, None] * v
    means, variances = encoding.frustum_gaussians(
        torch.tensor(o, dtype=torch.float32)[None], torch.tensor(d, dtype=torch.float32)[None],
        torch.tensor([[t0, t1]], dtype=torch.float32), torch.tensor([r], dtype=torch.float32))
    np.testing.assert_allclose(means[0, 0].numpy(), pts.mean(axis=0), atol=2e-3)
    np.testing.assert_allclose(variances[0, 0].numpy(), pts.var(axis=0), rtol=2e-2)


def test_ipe_matches_monte_carlo_expectation_of_sin_and_cos():
    rng = np.random.default_rng(1)
    mean = np.array([0.3, -0.7, 0.05])
    var = np.array([0.01, 0.0004, 0.09])
    levels, n = 5, 1_000_000
    x = mean + rng.normal(size=(n, 3)) * np.sqrt(var)
    want_sin = [np.sin(x * 2.0 ** l).mean(axis=0) for l in range(levels)]
    want_cos = [np.cos(x * 2.0 ** l).mean(axis=0) for l in range(levels)]
    want = np.concatenate([np.concatenate(want_sin), np.concatenate(want_cos)])
    got = encoding.integrated_pos_enc(torch.tensor(mean, dtype=torch.float32),
                                      torch.tensor(var, dtype=torch.float32), levels).numpy()
    assert got.shape == (encoding.ipe_dim(levels),)
    np.testing.assert_allclose(got, want, atol=5e-3)


def test_ipe_limits_zero_and_huge_variance():
    mean = torch.tensor([[0.25, -1.5, 2.0]])
    plain = encoding.pos_enc(mean, 6, include_input=False)
    np.testing.assert_allclose(encoding.integrated_pos_enc(mean, torch.zeros(1, 3), 6).numpy(),
                               plain.numpy(), atol=1e-6)
    huge = encoding.integrated_pos_enc(mean, torch.full((1, 3), 1e30), 6)
    assert torch.isfinite(huge).all() and huge.abs().max() == 0


def test_pos_enc_layout_matches_explicit_formula():
    x = torch.tensor([[0.6, -0.8, 0.0]])
    got = encoding.pos_enc(x, 4).numpy()[0]
    xs = x.numpy()[0].astype(np.float64)
    want = [*xs]
    want += [math.sin(2.0 ** l * xk) for l in range(4) for xk in xs]
    want += [math.cos(2.0 ** l * xk) for l in range(4) for xk in xs]
    assert got.shape == (encoding.dir_enc_dim(4),)
    np.testing.assert_allclose(got, want, atol=1e-6)
    assert encoding.pos_enc(x, 0).shape == (1, 3)
