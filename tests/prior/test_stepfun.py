"""prior.stepfun against brute-force loops (and a quadrature of the distortion integral)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from prior import stepfun


def random_steps(rng, rays, n, *, zero_frac=0.3, ties=False, lo=0.0, hi=1.0):
    """Sorted edges in [lo, hi] (optionally with repeated edges) and non-negative weights
    with some exact zeros."""
    t = np.sort(rng.uniform(lo, hi, size=(rays, n + 1)), axis=-1)
    t[:, 0], t[:, -1] = lo, hi
    if ties:
        t[:, 2] = t[:, 1]
        t[:, -3] = t[:, -2]
    w = rng.random((rays, n)) * (rng.random((rays, n)) > zero_frac)
    return torch.tensor(t, dtype=torch.float32), torch.tensor(w, dtype=torch.float32)


# ---------------------------------------------------------------- inverse-CDF sampling


def ref_invert_cdf(u, t, w):
    """Loop per ray: walk the bins until the running mass passes u, interpolate inside."""
    out = np.zeros(u.shape)
    for r in range(u.shape[0]):
        wr = w[r] / w[r].sum() if w[r].sum() > 0 else np.full(w.shape[1], 1.0 / w.shape[1])
        for k, uk in enumerate(u[r]):
            acc = 0.0
            for i, wi in enumerate(wr):
                if wi > 0 and (uk < acc + wi or i == len(wr) - 1):
                    out[r, k] = t[r, i] + min(max((uk - acc) / wi, 0.0), 1.0) * (t[r, i + 1] - t[r, i])
                    break
                acc += wi
            else:
                out[r, k] = t[r, -1]
    return out


def test_invert_cdf_matches_loop_reference():
    rng = np.random.default_rng(0)
    t, w = random_steps(rng, 16, 9)
    w[3] = 0.0  # an all-zero row samples uniformly over intervals
    u = torch.tensor(np.sort(rng.random((16, 40)), axis=-1), dtype=torch.float32)
    got = stepfun.invert_cdf(u, t, stepfun.normalize_weights(w)).numpy()
    want = ref_invert_cdf(u.numpy().astype(np.float64), t.numpy().astype(np.float64), w.numpy().astype(np.float64))
    np.testing.assert_allclose(got, want, atol=2e-5)


def test_deterministic_sampling_of_a_uniform_histogram_gives_even_edges():
    t = torch.tensor([[0.0, 0.25, 0.5, 0.75, 1.0]])
    edges = stepfun.sample_intervals(t, torch.ones(1, 4), 8)
    np.testing.assert_allclose(edges[0].numpy(), np.linspace(0, 1, 9), atol=1e-6)


def test_deterministic_samples_follow_the_histogram_mass():
    t = torch.tensor([[0.0, 0.1, 0.5, 0.6, 1.0]])
    w = torch.tensor([[0.5, 0.0, 0.25, 0.25]])
    pts = stepfun.invert_cdf(stepfun.quantiles(1, 1000), t, w)[0].numpy()
    counts = np.histogram(pts, bins=t[0].numpy())[0]
    np.testing.assert_array_equal(counts, [500, 0, 250, 250])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1), n=st.integers(1, 12), num=st.integers(2, 40),
       randomized=st.booleans(), lo=st.floats(-2, 2), width=st.floats(0.0, 5.0),
       single=st.booleans())
def test_sample_intervals_are_sorted_and_inside_the_domain(seed, n, num, randomized, lo, width, single):
    rng = np.random.default_rng(seed)
    hi = lo + width
    t, w = random_steps(rng, 4, n, zero_frac=0.5, ties=n > 4, lo=lo, hi=hi)
    w[0] = 0.0
    gen = torch.Generator().manual_seed(seed)
    jitter = torch.rand((4, 1 if single else num), generator=gen) if randomized else None
    edges = stepfun.sample_intervals(t, w, num, jitter, (lo, hi))
    assert edges.shape == (4, num + 1)
    assert torch.isfinite(edges).all()
    assert (edges[:, 1:] >= edges[:, :-1]).all()
    tol = 1e-6 * max(1.0, abs(lo), abs(hi))
    assert (edges >= lo - tol).all() and (edges <= hi + tol).all()


def test_stratified_quantiles_stay_in_their_bins():
    jitter = torch.tensor([[0.0, 0.5, 0.999999], [0.25, 0.25, 0.25]])
    u = stepfun.quantiles(2, 3, jitter)
    np.testing.assert_allclose(u.numpy(), [[0.0, 0.5, 0.99999967], [1 / 12, 5 / 12, 9 / 12]], atol=1e-7)
    shared = stepfun.quantiles(2, 4, torch.tensor([[0.2], [0.9]]))
    np.testing.assert_allclose(shared.numpy(), [[0.05, 0.3, 0.55, 0.8], [0.225, 0.475, 0.725, 0.975]], atol=1e-7)
    assert (stepfun.quantiles(1, 5, torch.ones(1, 5)) < 1).all()


# ---------------------------------------------------------------- dilation


def test_range_max_matches_brute_force():
    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 7, 8, 9, 33):
        v = torch.tensor(rng.random((5, n)), dtype=torch.float32)
        lo = torch.tensor(rng.integers(-1, n + 1, size=(5, 50)))
        hi = torch.tensor(rng.integers(-1, n + 1, size=(5, 50)))
        got = stepfun.range_max(v, lo, hi)
        for r in range(5):
            for q in range(50):
                a, b = max(int(lo[r, q]), 0), min(int(hi[r, q]), n - 1)
                want = float(v[r, a:b + 1].max()) if int(lo[r, q]) <= int(hi[r, q]) and a <= b else 0.0
                assert got[r, q].item() == want


def ref_dilated_value(t, w, d, x):
    """max w_i over the intervals [t_i - d, t_{i+1} + d) covering x (0 if none)."""
    cover = [w[i] for i in range(len(w)) if t[i] <= x + d and t[i + 1] > x - d]
    return max(cover) if cover else 0.0


@pytest.mark.parametrize("dilation", [0.0, 0.003, 0.05, 0.4])
def test_max_dilate_matches_pointwise_brute_force(dilation):
    rng = np.random.default_rng(5)
    t, w = random_steps(rng, 6, 10, ties=True)
    t_new, w_new = stepfun.max_dilate(t, w, dilation, (0.0, 1.0))
    assert t_new.shape == (6, 3 * 11) and w_new.shape == (6, 3 * 11 - 1)
    assert (t_new[:, 1:] >= t_new[:, :-1]).all() and t_new.min() >= 0 and t_new.max() <= 1
    td, wd = t.numpy().astype(np.float64), w.numpy()
    for r in range(6):
        xs = rng.random(300)
        idx = np.searchsorted(t_new[r].numpy(), xs, side="right") - 1
        for x, i in zip(xs, idx):
            assert w_new[r, i].item() == ref_dilated_value(td[r], wd[r], dilation, x)


def test_max_dilate_weights_bounds_the_original_density():
    rng = np.random.default_rng(6)
    t, w = random_steps(rng, 5, 12)
    t_new, w_new = stepfun.max_dilate_weights(t, w, 0.02, (0.0, 1.0))
    pdf = w / (t[:, 1:] - t[:, :-1])
    pdf_new = w_new / (t_new[:, 1:] - t_new[:, :-1]).clamp_min(1e-12)
    for r in range(5):
        xs = torch.tensor(rng.random(200), dtype=torch.float32)
        i = torch.searchsorted(t[r], xs, right=True) - 1
        j = torch.searchsorted(t_new[r], xs, right=True) - 1
        assert (pdf_new[r, j] >= pdf[r, i] * (1 - 1e-5)).all()
    assert (w_new.sum(-1) >= w.sum(-1) * (1 - 1e-5)).all()


def test_anneal_exponent_schedule():
    assert stepfun.anneal_exponent(0.0, 10.0) == 0.0
    assert stepfun.anneal_exponent(1.0, 10.0) == pytest.approx(1.0)
    assert stepfun.anneal_exponent(2.0, 10.0) == pytest.approx(1.0)  # clipped
    assert stepfun.anneal_exponent(0.3, 1.0) == pytest.approx(0.3)  # slope 1: identity
    assert stepfun.anneal_exponent(0.1, 10.0) == pytest.approx(10 * 0.1 / (9 * 0.1 + 1))
    assert stepfun.anneal_exponent(0.0, 0.0) == 1.0  # off
    xs = np.linspace(0, 1, 50)
    vals = [stepfun.anneal_exponent(x, 10.0) for x in xs]
    assert np.all(np.diff(vals) > 0)
    as_tensor = stepfun.anneal_exponent(torch.tensor(xs, dtype=torch.float32), 10.0)
    np.testing.assert_allclose(as_tensor.numpy(), vals, rtol=1e-5)


# ---------------------------------------------------------------- envelope and proposal penalty


def ref_outer(t, t_env, w_env):
    return np.array([sum(w_env[j] for j in range(len(w_env)) if t_env[j] < t[i + 1] and t_env[j + 1] > t[i])
                     for i in range(len(t) - 1)])


def envelope_cases():
    rng = np.random.default_rng(7)
    t, _ = random_steps(rng, 4, 9, ties=True)
    t_env, w_env = random_steps(rng, 4, 6, ties=True)
    yield t, t_env, w_env
    same = torch.linspace(0, 1, 9).expand(2, 9).contiguous()
    yield same, same, torch.tensor(rng.random((2, 8)), dtype=torch.float32)  # identical grids
    fine = torch.linspace(0, 1, 33).expand(2, 33).contiguous()
    yield fine, same, torch.tensor(rng.random((2, 8)), dtype=torch.float32)  # nested
    yield same, fine, torch.tensor(rng.random((2, 32)), dtype=torch.float32)


def test_outer_envelope_matches_brute_force():
    for t, t_env, w_env in envelope_cases():
        got = stepfun.outer_envelope(t, t_env, w_env).numpy()
        for r in range(t.shape[0]):
            want = ref_outer(t[r].numpy(), t_env[r].numpy(), w_env[r].numpy().astype(np.float64))
            np.testing.assert_allclose(got[r], want, rtol=1e-5, atol=1e-6)


def test_outer_envelope_of_identical_grids_is_the_histogram_itself():
    t = torch.linspace(0, 1, 9).expand(3, 9).contiguous()
    w = torch.rand(3, 8, generator=torch.Generator().manual_seed(0))
    np.testing.assert_allclose(stepfun.outer_envelope(t, t, w).numpy(), w.numpy(), rtol=1e-6)
    assert stepfun.proposal_penalty(t, w, t, w).abs().max() < 1e-12


# ---------------------------------------------------------------- distortion


def ref_distortion_pairwise(t, w):
    m = (t[1:] + t[:-1]) / 2
    n = len(w)
    inter = sum(w[i] * w[j] * abs(m[i] - m[j]) for i in range(n) for j in range(n))
    return inter + sum(w[i] ** 2 * (t[i + 1] - t[i]) for i in range(n)) / 3


def ref_distortion_quadrature(t, w, cells=1500):
    """The definition: the double integral of p(u) p(v) |u - v| of the step density
    p = w_i / (t_{i+1} - t_i), by the midpoint rule on a fine grid."""
    u = (np.arange(cells) + 0.5) / cells * (t[-1] - t[0]) + t[0]
    du = (t[-1] - t[0]) / cells
    i = np.clip(np.searchsorted(t, u, side="right") - 1, 0, len(w) - 1)
    p = w[i] / (t[i + 1] - t[i])
    return float((p[:, None] * p[None, :] * np.abs(u[:, None] - u[None, :])).sum() * du * du)


def test_distortion_matches_pairwise_sum_and_the_double_integral():
    rng = np.random.default_rng(8)
    t, w = random_steps(rng, 6, 7)
    got = stepfun.distortion(t, w).numpy()
    for r in range(6):
        td, wd = t[r].numpy().astype(np.float64), w[r].numpy().astype(np.float64)
        assert got[r] == pytest.approx(ref_distortion_pairwise(td, wd), rel=1e-5, abs=1e-7)
        assert got[r] == pytest.approx(ref_distortion_quadrature(td, wd), rel=1e-2, abs=1e-4)


def test_distortion_hard_cases():
    # all mass in one interval of width L: L / 3; zero weights: 0; a zero-width interval: no intra term
    t = torch.tensor([[0.0, 0.2, 0.5, 1.0], [0.0, 0.2, 0.5, 1.0], [0.0, 0.5, 0.5, 1.0]])
    w = torch.tensor([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(stepfun.distortion(t, w).numpy(), [0.3 / 3, 0.0, 0.0], atol=1e-7)
    # two point masses at distance D: 2 * w1 * w2 * D
    t2 = torch.tensor([[0.0, 1e-6, 0.7, 0.7 + 1e-6]])
    w2 = torch.tensor([[0.5, 0.0, 0.5]])
    assert stepfun.distortion(t2, w2).item() == pytest.approx(2 * 0.25 * 0.7, rel=1e-4)
