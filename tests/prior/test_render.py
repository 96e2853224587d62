"""prior.render: compositing against closed forms and a product-form loop; resampling."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from prior import render
from prior.config import SamplingConfig


def ref_weights(density, t):
    """w_i = prod_{j<i} (1 - a_j) * a_i with a_i = 1 - exp(-sigma_i delta_i), looped."""
    out = np.zeros(density.shape)
    for r in range(density.shape[0]):
        trans = 1.0
        for i in range(density.shape[1]):
            a = 1.0 - math.exp(-density[r, i] * (t[r, i + 1] - t[r, i]))
            out[r, i] = trans * a
            trans *= 1.0 - a
    return out


def test_alpha_weights_match_the_product_form():
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(0.5, 2.0, size=(5, 17)), axis=-1)
    density = rng.exponential(3.0, size=(5, 16)) * (rng.random((5, 16)) > 0.3)
    got = render.alpha_weights(torch.tensor(density, dtype=torch.float32), torch.tensor(t, dtype=torch.float32))
    np.testing.assert_allclose(got.numpy(), ref_weights(density, t), atol=1e-6)


def slab(density_value, a, b, near=0.0, far=2.0, n=4000):
    """A ray through a slab of constant density on [a, b] (edges aligned to the slab)."""
    t = torch.linspace(near, far, n + 1)[None]
    mid = (t[:, 1:] + t[:, :-1]) / 2
    density = torch.where((mid > a) & (mid < b), torch.tensor(density_value), torch.tensor(0.0))
    w = render.alpha_weights(density, t)
    acc = w.sum(-1)
    return t, w, acc, render.expected_depth(w, t, acc)


def test_opaque_slab_gives_its_depth_and_full_opacity():
    t, w, acc, depth = slab(1e6, 0.8, 1.2)
    assert acc.item() == pytest.approx(1.0, abs=1e-6)
    assert depth.item() == pytest.approx(0.8, abs=2 * 2.0 / 4000)


def test_half_transparent_slab_gives_the_analytic_opacity_and_depth():
    sigma, a, b = 2.0, 0.5, 1.0  # grid step 5e-4 puts edges exactly on 0.5 and 1.0
    t, w, acc, depth = slab(sigma, a, b)
    length = b - a
    assert acc.item() == pytest.approx(1 - math.exp(-sigma * length), rel=1e-4)
    # E[t | hit] for an exponential hit time truncated to the slab
    want = a + 1 / sigma - length * math.exp(-sigma * length) / (1 - math.exp(-sigma * length))
    assert depth.item() == pytest.approx(want, abs=1e-3)


def test_zero_huge_and_infinite_densities_stay_finite():
    t = torch.tensor([[0.0, 0.5, 1.0, 1.5], [0.0, 0.5, 1.0, 1.5], [1.0, 1.0, 1.0, 1.0]])
    density = torch.tensor([[0.0, 0.0, 0.0], [1e30, float("inf"), 1e38], [float("inf"), 1e30, 5.0]])
    density.requires_grad_(True)
    w = render.alpha_weights(density, t)
    acc = w.sum(-1)
    depth = render.expected_depth(w, t, acc)
    assert torch.isfinite(w).all() and torch.isfinite(depth).all()
    np.testing.assert_allclose(acc.detach().numpy(), [0.0, 1.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(w[1].detach().numpy(), [1.0, 0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(depth.detach().numpy(), [1.5, 0.25, 1.0], atol=1e-6)
    (w.sum() + depth.sum()).backward()
    assert torch.isfinite(density.grad).all()


def test_composite_with_background():
    w = torch.tensor([[0.25, 0.25, 0.0]])
    values = torch.tensor([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [9.0, 9.0, 9.0]]])
    rgb = render.composite(w, values) + (1 - w.sum(-1))[:, None] * torch.tensor([[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(rgb.numpy(), [[0.25, 0.25, 0.5]])


def test_planar_depth_uses_the_camera_z_component():
    assert render.planar_depth(torch.tensor(2.0), torch.tensor(0.5)).item() == 1.0


def test_analytic_normals_of_a_radial_density_point_outwards():
    centre = torch.tensor([0.1, -0.2, 0.3])
    x = torch.randn(4, 5, 3, generator=torch.Generator().manual_seed(0)).requires_grad_(True)
    raw = -((x - centre) ** 2).sum(-1)  # density grows towards the centre
    n = render.analytic_normals(raw, x, create_graph=False)
    want = (x - centre) / (x - centre).norm(dim=-1, keepdim=True)
    np.testing.assert_allclose(n.detach().numpy(), want.detach().numpy(), atol=1e-6)


def test_ray_bounds_sanitise_missing_rays():
    near, far = render.ray_bounds(torch.tensor([0.5, 2.0, -1.0]), torch.tensor([1.5, 1.0, 0.5]))
    np.testing.assert_allclose(near.numpy(), [0.5, 2.0, 0.0])
    np.testing.assert_allclose(far.numpy(), [1.5, 2.0, 0.5])


def test_dilation_for_level_follows_the_sample_counts():
    cfg = SamplingConfig(proposal_samples=(64, 32), nerf_samples=16)
    assert render.dilation_for_level(1, cfg) == pytest.approx(0.0025 + 0.5 / 64)
    assert render.dilation_for_level(2, cfg) == pytest.approx(0.0025 + 0.5 / (64 * 32))


@pytest.mark.parametrize("train_frac", [0.0, 0.3, 1.0])
def test_resample_concentrates_samples_where_the_weights_are(train_frac):
    cfg = SamplingConfig(proposal_samples=(64,), nerf_samples=64)
    s = torch.linspace(0, 1, 65)[None]
    w = torch.zeros(1, 64)
    w[0, 40] = 1.0  # all mass in [0.625, 0.640625)
    jitter = render.draw_jitter(1, cfg, torch.Generator().manual_seed(0), None)[1]
    edges = render.resample(1, s, w, cfg, train_frac=train_frac, jitter=jitter)
    assert (edges[:, 1:] >= edges[:, :-1]).all() and edges.min() >= 0 and edges.max() <= 1
    mid = (edges[0, 1:] + edges[0, :-1]) / 2
    dil = render.dilation_for_level(1, cfg)
    inside = ((mid >= 0.625 - dil) & (mid <= 0.640625 + dil)).float().mean().item()
    if train_frac == 0.0:  # exponent 0: every (dilated) interval is equally likely
        assert inside < 0.5
    else:
        assert inside > 0.9
