"""synth.geometry.exact: machine-independent float arithmetic is accurate, handles the edge
values numpy handles, and its linear algebra agrees with numpy's to rounding."""

from __future__ import annotations

import math

import numpy as np
import pytest

from synth.geometry import exact


def _ulps(got, ref) -> float:
    got, ref = np.asarray(got, np.float64), np.asarray(ref, np.float64)
    return float(np.max(np.abs(got - ref) / np.spacing(np.maximum(np.abs(ref), np.finfo(float).tiny))))


RNG = np.random.default_rng(20261203)
CASES = {
    "sin": (exact.sin, math.sin, RNG.uniform(-50.0, 50.0, 4000)),
    "cos": (exact.cos, math.cos, RNG.uniform(-50.0, 50.0, 4000)),
    "exp": (exact.exp, math.exp, RNG.uniform(-700.0, 700.0, 4000)),
    "log": (exact.log, math.log, 10.0 ** RNG.uniform(-300.0, 300.0, 4000)),
    "asin": (exact.asin, math.asin, RNG.uniform(-1.0, 1.0, 4000)),
    "acos": (exact.acos, math.acos, RNG.uniform(-1.0, 1.0, 4000)),
    "atan": (exact.atan, math.atan, RNG.normal(size=4000) * 10.0 ** RNG.uniform(-6.0, 6.0, 4000)),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_within_four_ulps_of_libm(name):
    f, ref, x = CASES[name]
    assert _ulps(f(x), [ref(v) for v in x]) <= 4.0


def test_sin_cos_near_multiples_of_half_pi_and_small_angles():
    k = np.arange(-2000, 2001, dtype=np.float64)
    x = np.concatenate([k * (math.pi / 2), k * (math.pi / 2) + 1e-9, [1e-300, 1e-20, 0.0, -0.0]])
    assert np.max(np.abs(exact.sin(x) - np.sin(x))) < 1e-15 * 2000
    assert np.max(np.abs(exact.cos(x) - np.cos(x))) < 1e-15 * 2000
    assert exact.sin(1e-20) == 1e-20 and exact.cos(0.0) == 1.0


def test_trig_of_huge_arguments_stays_close_and_finite():
    x = np.array([1e7, -3.3e9, 1e15, 4.1e6])
    assert np.all(np.isfinite(exact.sin(x))) and np.all(np.isfinite(exact.cos(x)))
    assert np.max(np.abs(exact.sin(x[:2]) - np.sin(x[:2]))) < 1e-6  # what the float 2 pi allows there


def test_atan2_quadrants_zeros_and_axes_match_c():
    y = np.array([0.0, -0.0, 0.0, -0.0, 1.0, -1.0, 0.0, 3.0, -3.0, 1e-300, 1e300])
    x = np.array([0.0, 0.0, -0.0, -0.0, 0.0, 0.0, -5.0, -3.0, -3.0, -1.0, 1e-300])
    got, ref = exact.atan2(y, x), np.arctan2(y, x)
    assert np.array_equal(np.signbit(got), np.signbit(ref))
    assert _ulps(got, ref) <= 2.0
    yy, xx = RNG.normal(size=(2, 4000))
    assert _ulps(exact.atan2(yy, xx), [math.atan2(a, b) for a, b in zip(yy, xx)]) <= 4.0


def test_inverse_trig_clamps_at_the_ends():
    assert exact.asin(1.0) == np.float64(math.pi / 2) and exact.acos(-1.0) == np.float64(math.pi)
    assert exact.acos(1.0 + 1e-15) == 0.0  # clipped, not nan


def test_exp_log_edge_values():
    assert np.array_equal(exact.exp([800.0, -800.0, 0.0]), [np.inf, 0.0, 1.0])
    assert np.isnan(exact.exp(np.nan))
    out = exact.log([0.0, -1.0, np.inf, np.nan, 1.0, 5e-324])
    assert out[0] == -np.inf and np.isnan(out[1]) and out[2] == np.inf and np.isnan(out[3]) and out[4] == 0.0
    assert abs(out[5] - math.log(5e-324)) < 1e-12
    assert _ulps(exact.exp(exact.log(np.array([2.5, 1e-5, 7e11]))), [2.5, 1e-5, 7e11]) <= 8.0


def test_linear_algebra_agrees_with_numpy():
    A, B = RNG.normal(size=(2, 7, 3, 3))
    v = RNG.normal(size=(7, 3))
    P = RNG.normal(size=(7, 50, 3))
    assert np.allclose(exact.matmul3(A, B), A @ B, rtol=0, atol=1e-14)
    assert np.allclose(exact.matvec3(A, v), np.einsum("bij,bj->bi", A, v), rtol=0, atol=1e-14)
    assert np.allclose(exact.points_times_matrix(P, A), P @ A, rtol=0, atol=1e-14)
    c, rows = RNG.normal(size=(4, 30)), RNG.normal(size=(30, 99))
    assert np.allclose(exact.lincomb(c, rows), c @ rows, rtol=0, atol=1e-13)
    assert exact.lincomb(c.astype(np.float32), rows.astype(np.float32)).dtype == np.float32


def test_cholesky_matches_numpy_and_refuses_indefinite():
    M = RNG.normal(size=(3, 12, 12))
    S = M @ np.swapaxes(M, 1, 2) + 1e-3 * np.eye(12)
    assert np.allclose(exact.cholesky(S), np.linalg.cholesky(S), rtol=0, atol=1e-10)
    with pytest.raises(np.linalg.LinAlgError):
        exact.cholesky(np.array([[1.0, 2.0], [2.0, 1.0]]))


def test_erfc_and_normal_cdf_match_scipy_far_into_the_tails():
    from scipy.special import erfc, ndtr

    x = np.concatenate([np.linspace(-6.0, 26.0, 20001), [0.0, -0.0, 1.5, 1.5 - 1e-16]])
    want = erfc(x)
    ok = want > 0
    assert np.max(np.abs(exact.erfc(x)[ok] - want[ok]) / want[ok]) < 1e-13
    y = np.linspace(-37.0, 8.0, 20001)
    w = ndtr(y)
    assert np.max(np.abs(exact.ndtr(y) - w) / w) < 1e-13
