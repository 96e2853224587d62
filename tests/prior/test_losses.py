"""prior.losses against slow loop references, on random and hard cases."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from prior import losses


def rand(*shape, seed=0):
    return torch.rand(*shape, generator=torch.Generator().manual_seed(seed))


def steps(rays, n, seed, ties=False):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.random((rays, n + 1)), axis=-1)
    t[:, 0], t[:, -1] = 0.0, 1.0
    if ties:
        t[:, 3] = t[:, 2]
    w = rng.random((rays, n)) * (rng.random((rays, n)) > 0.3)
    w = w / np.maximum(w.sum(-1, keepdims=True), 1e-12) * rng.random((rays, 1))
    return torch.tensor(t, dtype=torch.float32), torch.tensor(w, dtype=torch.float32)


# ---------------------------------------------------------------- L1


def test_l1_matches_loop_reference_with_and_without_weights():
    pred, target, weights = rand(50, 3, seed=1), rand(50, 3, seed=2), rand(50, seed=3)
    p, g, m = pred.double().numpy(), target.double().numpy(), weights.double().numpy()
    plain = sum(abs(p[i, c] - g[i, c]) for i in range(50) for c in range(3)) / 150
    weighted = sum(m[i] * abs(p[i, c] - g[i, c]) / 3 for i in range(50) for c in range(3)) / m.sum()
    assert losses.l1_loss(pred, target).item() == pytest.approx(plain, rel=1e-6)
    assert losses.l1_loss(pred, target, weights).item() == pytest.approx(weighted, rel=1e-6)
    assert losses.l1_loss(pred, target, torch.zeros(50)).item() == 0.0


# ---------------------------------------------------------------- proposal


def ref_proposal(history, eps=1e-7):
    """Eq. 13 of mip-NeRF 360 by loops: bound_i = sum of the proposal weights whose
    intervals overlap NeRF interval i."""
    t, w = (x.double().numpy() for x in history[-1])
    total = 0.0
    for tp_t, wp_t in history[:-1]:
        tp, wp = tp_t.double().numpy(), wp_t.detach().double().numpy()
        level = 0.0
        for r in range(t.shape[0]):
            for i in range(w.shape[1]):
                bound = sum(wp[r, j] for j in range(wp.shape[1]) if tp[r, j] < t[r, i + 1] and tp[r, j + 1] > t[r, i])
                level += max(0.0, w[r, i] - bound) ** 2 / (w[r, i] + eps)
        total += level / t.shape[0]
    return total


def test_proposal_loss_matches_loop_reference():
    s0, w0 = steps(6, 8, 10, ties=True)
    s1, w1 = steps(6, 12, 11)
    s2, w2 = steps(6, 16, 12, ties=True)
    history = [(s0, w0), (s1, w1), (s2, w2)]
    assert losses.proposal_loss(history).item() == pytest.approx(ref_proposal(history), rel=1e-5)


def test_proposal_loss_is_zero_when_the_proposal_covers_the_nerf_weights():
    s, w = steps(4, 10, 13)
    assert losses.proposal_loss([(s, w), (s, w)]).item() == pytest.approx(0.0, abs=1e-9)
    assert losses.proposal_loss([(s, w * 2), (s, w)]).item() == pytest.approx(0.0, abs=1e-9)
    assert losses.proposal_loss([(s, torch.zeros_like(w)), (s, torch.zeros_like(w))]).item() == 0.0


def test_proposal_loss_stops_the_gradient_of_the_nerf_weights():
    s0, w0 = steps(3, 8, 14)
    s1, w1 = steps(3, 8, 15)
    w0 = (w0 * 0.1).requires_grad_(True)
    w1 = w1.clone().requires_grad_(True)
    losses.proposal_loss([(s0, w0), (s1, w1)]).backward()
    assert w1.grad is None
    assert torch.isfinite(w0.grad).all() and (w0.grad <= 0).all() and w0.grad.abs().sum() > 0


# ---------------------------------------------------------------- distortion


def test_distortion_loss_matches_pairwise_reference():
    s, w = steps(5, 9, 16, ties=True)
    want = 0.0
    for r in range(5):
        sd, wd = s[r].double().numpy(), w[r].double().numpy()
        m = (sd[1:] + sd[:-1]) / 2
        want += sum(wd[i] * wd[j] * abs(m[i] - m[j]) for i in range(9) for j in range(9))
        want += sum(wd[i] ** 2 * (sd[i + 1] - sd[i]) for i in range(9)) / 3
    assert losses.distortion_loss(s, w).item() == pytest.approx(want / 5, rel=1e-5)


def test_distortion_gradient_is_finite_on_degenerate_rays():
    s = torch.tensor([[0.0, 0.0, 0.0, 0.0], [0.0, 0.5, 0.5, 1.0]])
    w = torch.tensor([[0.0, 0.0, 0.0], [0.2, 0.0, 0.8]], requires_grad=True)
    losses.distortion_loss(s, w).backward()
    assert torch.isfinite(w.grad).all()


# ---------------------------------------------------------------- normals and view branch


def unit(x):
    return x / x.norm(dim=-1, keepdim=True)


def test_normal_consistency_matches_loop_reference():
    w = rand(4, 6, seed=20)
    n = unit(torch.randn(4, 6, 3, generator=torch.Generator().manual_seed(21)))
    n_hat = unit(torch.randn(4, 6, 3, generator=torch.Generator().manual_seed(22)))
    want = sum(float(w[r, i]) * (1 - float(n[r, i] @ n_hat[r, i])) for r in range(4) for i in range(6)) / 4
    assert losses.normal_consistency_loss(w, n, n_hat).item() == pytest.approx(want, rel=1e-5)
    assert losses.normal_consistency_loss(w, n, n).item() == pytest.approx(0.0, abs=1e-6)
    assert losses.normal_consistency_loss(w, n, -n).item() == pytest.approx(2 * float(w.sum()) / 4, rel=1e-5)


def test_normal_consistency_weight_gradient_can_be_stopped():
    w = rand(2, 3, seed=23).requires_grad_(True)
    n = unit(torch.randn(2, 3, 3, generator=torch.Generator().manual_seed(24))).requires_grad_(True)
    losses.normal_consistency_loss(w, n, unit(torch.ones(2, 3, 3)), stop_weight_grad=True).backward()
    assert w.grad is None and n.grad is not None


def test_orientation_loss_matches_loop_reference():
    w = rand(3, 5, seed=25)
    n = unit(torch.randn(3, 5, 3, generator=torch.Generator().manual_seed(26)))
    d = unit(torch.randn(3, 3, generator=torch.Generator().manual_seed(27)))
    want = sum(float(w[r, i]) * max(0.0, float(n[r, i] @ d[r])) ** 2 for r in range(3) for i in range(5)) / 3
    assert losses.orientation_loss(w, n, d).item() == pytest.approx(want, rel=1e-5)


def test_view_l2_is_the_sum_of_squares():
    a, b = torch.tensor([[1.0, -2.0]]), torch.tensor([3.0])
    assert losses.view_l2_loss([a, b]).item() == 14.0
    assert losses.view_l2_loss([]).item() == 0.0
