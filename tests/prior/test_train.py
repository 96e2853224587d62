"""prior.train: exact resume, the collapse check, non-finite losses, DDP (gloo), the schedule."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.prior import scene
from prior.train import checkpoint as ckpt
from prior.train import loop
from prior.train.config import TrainConfig
from prior.train.loop import Trainer
from prior.train.optim import learning_rate
from prior.train.run import prepare
from synth.errors import SynthError

pytest.importorskip("OpenEXR")
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def ds(tmp_path_factory):
    return scene.make_dataset(tmp_path_factory.mktemp("prior") / "d", identities=2, expressions=2, views=4, size=16)


def _train(ds, run, sets=(), steps=6, resume=False, stop_at=None):
    s = prepare(ds, run, sets=[] if resume else [*scene.TINY, *sets], steps=steps, resume=resume)
    return Trainer(s, torch.device("cpu"), tty=False, tensorboard=False).run(stop_at=stop_at)


def _state(run):
    return ckpt.load(ckpt.latest(run))


@pytest.mark.parametrize("sets", [[], ["train.grad_accum=2", "train.foreground_fraction=0.5"],
                                  # streaming: a buffer of 1 of the 2 identities, swapped every 2 steps
                                  ["data.buffer_identities=1", "data.views_per_load=0.5", "data.read_ahead=1"]])
def test_resume_is_exact(ds, tmp_path, sets):
    assert _train(ds, tmp_path / "a", sets, steps=6) == 0
    assert _train(ds, tmp_path / "b", sets, steps=6, stop_at=3) == 0
    assert _state(tmp_path / "b").step == 3
    assert _train(ds, tmp_path / "b", steps=None, resume=True) == 0
    a, b = _state(tmp_path / "a"), _state(tmp_path / "b")
    assert a.step == b.step == 6 and a.model_state.keys() == b.model_state.keys()
    for k in a.model_state:
        assert torch.equal(a.model_state[k], b.model_state[k]), k
    oa, ob = ckpt.load_optimizer_state(a), ckpt.load_optimizer_state(b)
    for pa, pb in zip(oa["optimizer"]["state"].values(), ob["optimizer"]["state"].values()):
        assert torch.equal(pa["exp_avg"], pb["exp_avg"]) and torch.equal(pa["exp_avg_sq"], pb["exp_avg_sq"])
    # and training changed the model (the comparison is not between two initial states)
    first = ckpt.load(ckpt.checkpoint_path(tmp_path / "a", 0))
    assert not all(torch.equal(first.model_state[k], a.model_state[k]) for k in a.model_state)


def test_collapse_check_fires_on_zero_density(ds, tmp_path):
    sets = ["model.density_bias=-1000.0", "train.background_steps=0", "train.collapse_patience=2"]
    with pytest.raises(SynthError, match="collapsed.*step 2"):
        _train(ds, tmp_path / "r", sets, steps=10)
    assert [s for s, _ in ckpt.list_checkpoints(tmp_path / "r")] == [0]
    # a healthy model does not trip it
    assert _train(ds, tmp_path / "ok", ["train.background_steps=0", "train.collapse_patience=1",
                                        "train.collapse_acc=1e-9"], steps=3) == 0


def test_non_finite_loss_stops_and_keeps_last_good_checkpoint(ds, tmp_path, monkeypatch):
    real = loop.losses.l1_loss
    calls = {"n": 0}

    def poisoned(pred, target, weights=None):
        calls["n"] += 1
        return real(pred, target, weights) * (float("nan") if calls["n"] > 3 else 1.0)

    monkeypatch.setattr(loop.losses, "l1_loss", poisoned)
    with pytest.raises(SynthError, match=r"not finite at step 3.*step 2\) is kept"):
        _train(ds, tmp_path / "r", steps=10)
    assert [s for s, _ in ckpt.list_checkpoints(tmp_path / "r")] == [0, 2]
    good = _state(tmp_path / "r")
    assert all(torch.isfinite(v).all() for v in good.model_state.values())


def test_learning_rate_schedule():
    t = TrainConfig(steps=1000, lr_init=2e-3, lr_final=2e-5, warmup_steps=100, warmup_start=0.01)
    assert learning_rate(0, t) == pytest.approx(2e-5)
    assert learning_rate(100, t) == pytest.approx(2e-3 * (2e-5 / 2e-3) ** 0.1)
    assert learning_rate(1000, t) == pytest.approx(2e-5)
    lrs = [learning_rate(s, t) for s in range(100, 1001)]
    assert all(b < a for a, b in zip(lrs, lrs[1:]))  # decays after the warm-up
    assert learning_rate(50, t) == pytest.approx(learning_rate(50, TrainConfig(steps=1000, warmup_steps=0)) * 0.505)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_ddp_gloo_world_1_equals_plain_and_world_2_runs(ds, tmp_path):
    sets = [a for s in scene.TINY for a in ("--set", s)]
    base = [sys.executable, "-m", "prior.cli", "train", str(ds), "--steps", "3", *sets]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MASTER_ADDR": "127.0.0.1"}

    def ddp(run, world):
        port = str(_free_port())
        procs = [subprocess.Popen([*base, "--out", str(run)], env={**env, "RANK": str(r), "LOCAL_RANK": str(r),
                                                                  "WORLD_SIZE": str(world), "MASTER_PORT": port},
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for r in range(world)]
        outs = [p.communicate(timeout=300)[0] for p in procs]
        assert [p.returncode for p in procs] == [0] * world, outs

    ddp(tmp_path / "ddp1", 1)
    assert _train(ds, tmp_path / "plain", steps=3) == 0
    a, b = _state(tmp_path / "ddp1"), _state(tmp_path / "plain")
    assert all(torch.equal(a.model_state[k], b.model_state[k]) for k in a.model_state)
    ddp(tmp_path / "ddp2", 2)
    c = _state(tmp_path / "ddp2")
    assert c.step == 3 and all(torch.isfinite(v).all() for v in c.model_state.values())
    import json

    assert json.loads((tmp_path / "ddp2" / "run.json").read_text())["ranks"] == 2
    assert not all(torch.equal(c.model_state[k], b.model_state[k]) for k in b.model_state)
    assert np.isfinite(c.losses["loss"])


@pytest.mark.slow
def test_ddp_gloo_two_ranks_stream_disjoint_identities_in_sync(tmp_path):
    """2 ranks through torchrun on localhost (gloo), a tar dataset of 4 identities, a buffer of 1."""
    import json

    ds = scene.make_dataset(tmp_path / "d", identities=4, expressions=2, views=4, size=16, shard_format="tar")
    sets = [a for s in [*scene.TINY, "data.buffer_identities=1", "data.views_per_load=0.5", "train.log_every=2"]
            for a in ("--set", s)]
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc-per-node", "2", "--master-addr", "127.0.0.1",
           "--master-port", str(_free_port()), "-m", "prior.cli", "train", str(ds), "--out", str(tmp_path / "run"),
           "--steps", "8", *sets]
    p = subprocess.run(cmd, env={**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"},
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    c = _state(tmp_path / "run")
    state = ckpt.load_optimizer_state(c)["trainer"]["loader"]
    assert [s["rank"] for s in state] == [0, 1]
    seen = [set(s["order"]) | set(s["held"]) for s in state]
    assert seen == [{0, 2}, {1, 3}]  # latent ids m % 2 == rank: disjoint identities (and shards)
    assert all(s["epoch"] >= 1 for s in state)  # the buffer of 1 swapped through each rank's identities
    metrics = [json.loads(x) for x in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert len(metrics) == 4 and all(m["param_spread"] == 0.0 for m in metrics)  # parameters in sync


def test_bf16_autocast_on_cpu_trains(ds, tmp_path):
    assert _train(ds, tmp_path / "r", ["train.bf16=true"], steps=2) == 0
    st = _state(tmp_path / "r")
    assert all(torch.isfinite(v).all() and v.dtype == torch.float32 for v in st.model_state.values())
    assert np.isfinite(st.losses["loss"])


def test_tensorboard_scalars_and_previews(ds, tmp_path):
    s = prepare(ds, tmp_path / "r", sets=[*scene.TINY, "train.preview_every=2", "train.preview_size=8"], steps=2)
    assert Trainer(s, torch.device("cpu"), tty=False, tensorboard=True).run() == 0
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    ev = EventAccumulator(str(tmp_path / "r" / "tb"), size_guidance={"images": 0})
    ev.Reload()
    tags = ev.Tags()
    assert {"train/loss", "train/psnr", "train/acc_fg", "train/rays_per_s"} <= set(tags["scalars"])
    assert [e.step for e in ev.Scalars("train/loss")] == [1, 2]
    assert sorted(tags["images"]) == ["preview/identity_0", "preview/identity_1"]
    img = ev.Images("preview/identity_0")[0]
    assert (img.width, img.height) == (16, 8)  # prediction | ground truth
    import json

    lines = (tmp_path / "r" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(x)["step"] for x in lines] == [1, 2]


@pytest.mark.slow
def test_compiled_training_matches_eager_closely(ds, tmp_path):
    assert _train(ds, tmp_path / "c", ["train.compile=true"], steps=3) == 0
    assert _train(ds, tmp_path / "e", [], steps=3) == 0
    c, e = _state(tmp_path / "c"), _state(tmp_path / "e")
    for k in e.model_state:
        torch.testing.assert_close(c.model_state[k], e.model_state[k], rtol=1e-3, atol=1e-4)
