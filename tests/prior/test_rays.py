"""prior.rays.RayBundle (selection, chunks, latents, devices) and prior.train.stats (the named
statistics of a training step)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from prior.rays import RayBundle
from prior.train.stats import LoggedStats, StepStats
from tests.prior.test_model import random_rays, tiny_model


def _fields(b: RayBundle) -> dict:
    return {f.name: getattr(b, f.name) for f in dataclasses.fields(b)}


def test_selection_applies_to_every_field_and_keeps_absent_ones_absent():
    rays = dataclasses.replace(random_rays(10), radii=torch.arange(10.0))
    for index in (slice(2, 7), np.array([9, 0, 4]), torch.tensor([1, 1, 3]), rays.radii > 5.5):
        sub = rays[index]
        assert sub.latents is None
        for name, v in _fields(sub).items():
            if v is not None:
                want = getattr(rays, name)[torch.as_tensor(index) if isinstance(index, np.ndarray) else index]
                assert torch.equal(v, want), name
    assert len(rays[np.array([9, 0, 4])]) == 3
    assert torch.equal(rays[rays.radii > 5.5].radii, torch.tensor([6.0, 7, 8, 9]))


def test_chunks_cover_the_rays_in_order_and_render_as_the_whole():
    rays = random_rays(23)
    parts = list(rays.chunks(7))
    assert [len(p) for p in parts] == [7, 7, 7, 2]
    for name, v in _fields(rays).items():
        if v is not None:
            assert torch.equal(torch.cat([getattr(p, name) for p in parts]), v), name
    assert list(random_rays(0).chunks(4)) == []
    model = tiny_model()
    with torch.no_grad():
        whole = model(rays)
        chunked = [model(p) for p in parts]
    for key in ("rgb", "acc", "depth"):
        torch.testing.assert_close(torch.cat([c[key] for c in chunked]), whole[key], rtol=1e-5, atol=1e-6)


def test_with_latent_broadcasts_one_vector_and_passes_its_gradient():
    rays = random_rays(6)
    w = torch.full((64,), 0.3, requires_grad=True)
    lat = rays.with_latent(w)
    assert lat.latent_ids is None and lat.latents.shape == (6, 64) and torch.equal(lat.codes, rays.codes)
    tiny_model()(lat)["rgb"].sum().backward()
    assert w.grad is not None and torch.isfinite(w.grad).all() and w.grad.abs().sum() > 0
    assert rays.with_latent(torch.zeros(1, 64)).latents.shape == (6, 64)


def test_from_numpy_dtypes_valid_and_frozen():
    n = 4
    rays = RayBundle.from_numpy(np.zeros((n, 3)), np.ones((n, 3)), np.array([0.5, 1.0, 0.2, 0.0]),
                                np.array([1.0, 1.0, 0.1, 0.3]), np.zeros((n, 2)), latent_ids=np.arange(n))
    assert rays.origins.dtype == rays.near.dtype == rays.codes.dtype == torch.float32
    assert rays.latent_ids.dtype == torch.int64 and rays.radii is None and rays.latents is None
    assert torch.equal(rays.valid, torch.tensor([1.0, 0.0, 0.0, 1.0]))
    assert rays.to("cpu").origins.device.type == "cpu"
    with pytest.raises(dataclasses.FrozenInstanceError):
        rays.near = rays.far


def test_step_stats_round_trip_and_rank_means():
    names = StepStats.names()
    assert names == ("loss", "l1", "proposal", "sq_err", "fg_acc", "fg_rays", "valid_rays")
    assert set(StepStats.MEANS) <= set(names)
    s = StepStats.from_tensor(torch.arange(1.0, 8.0))
    assert float(s.proposal) == 3.0 and float(s.valid_rays) == 7.0
    assert torch.equal(s.to_tensor(), torch.arange(1.0, 8.0))
    acc = StepStats.accumulator("cpu")
    acc += s.to_tensor()
    acc += s.to_tensor()
    assert StepStats.from_tensor(acc).values()["fg_rays"] == 12.0
    logged = LoggedStats.of(s, 5)
    assert LoggedStats.names() == (*names, "skipped_shards")
    halved = LoggedStats.from_tensor(logged.to_tensor() * 2).mean_over_ranks(2).values()
    assert halved == {"loss": 1.0, "l1": 2.0, "proposal": 3.0, "sq_err": 8.0, "fg_acc": 10.0, "fg_rays": 12.0,
                      "valid_rays": 14.0, "skipped_shards": 10.0}
