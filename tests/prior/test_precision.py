"""bf16 ``auto`` (prior.precision): on where the device computes bf16 natively, off elsewhere;
the setting is read as true, false or "auto", and the run's log says which was chosen."""

from __future__ import annotations

import json

import pytest
import torch

from prior.fit import config as fit_config
from prior.precision import cpu_flags, native_bf16, resolve_bf16
from prior.train import config as run_config
from synth.errors import SynthError

XEON = "processor\t: 0\nflags\t\t: fpu sse avx512f avx512bw avx512_bf16 amx_tile\n\nprocessor\t: 1\n"
EPYC = "processor\t: 0\nflags\t\t: fpu sse avx2 avx512f avx512bw avx512_vnni\n"  # Zen 3/Genoa-less: no bf16
ARM = "processor\t: 0\nFeatures\t: fp asimd sve bf16 i8mm\n"


@pytest.mark.parametrize("text, native", [(XEON, True), (EPYC, False), (ARM, True), ("", False)])
def test_cpu_native_bf16_from_flags(tmp_path, text, native):
    p = tmp_path / "cpuinfo"
    p.write_text(text)
    on, why = native_bf16(torch.device("cpu"), p)
    assert on is native
    assert ("avx512_bf16" in why or "bf16" in why) if native else why.startswith("CPU has none of")


def test_unreadable_cpuinfo_means_off(tmp_path):
    assert cpu_flags(tmp_path / "missing") == set()
    assert native_bf16(torch.device("cpu"), tmp_path / "missing")[0] is False


def test_resolve_explicit_and_auto(monkeypatch):
    assert resolve_bf16(True, torch.device("cpu"), "train.bf16") == (True, "train.bf16 = true: bf16 autocast on")
    assert resolve_bf16(False, torch.device("cpu"), "finetune.bf16")[0] is False
    monkeypatch.setattr("prior.precision.native_bf16", lambda dev: (False, "CPU has none of avx512_bf16"))
    on, line = resolve_bf16("auto", torch.device("cpu"), "train.bf16")
    assert on is False and line == "train.bf16 = auto: bf16 autocast off (CPU has none of avx512_bf16)"


def test_auto_is_the_default_and_presets_use_it():
    for name in ("small", "paper"):
        assert run_config.preset(name).train.bf16 == "auto"
        assert fit_config.load(name).finetune.bf16 == "auto"
    assert run_config.load("small", sets=["train.bf16=true"]).train.bf16 is True
    assert run_config.load("small", sets=["train.bf16=false"]).train.bf16 is False
    assert fit_config.load("small", sets=["finetune.bf16=auto"]).finetune.bf16 == "auto"
    with pytest.raises(SynthError, match="choose one of false, true, auto"):
        fit_config.load("small", sets=["finetune.bf16=2"])
    import tomllib

    cfg = run_config.preset("small")
    assert run_config.from_dict(tomllib.loads(run_config.to_toml(cfg)), "toml") == cfg  # "auto" round-trips


def test_training_log_and_run_json_say_which_was_chosen(tmp_path, capsys, monkeypatch):
    pytest.importorskip("OpenEXR")
    from prior.train.loop import Trainer
    from prior.train.run import prepare
    from tests.prior import scene

    ds = scene.make_dataset(tmp_path / "d", identities=2, expressions=1, views=4, size=16)
    for native in (True, False):
        monkeypatch.setattr("prior.precision.native_bf16", lambda dev, n=native: (n, "stub CPU"))
        run = tmp_path / f"r{native}"
        s = prepare(ds, run, sets=list(scene.TINY), steps=1)
        assert Trainer(s, torch.device("cpu"), tty=False, tensorboard=False).run() == 0
        out = capsys.readouterr().out
        assert f"train.bf16 = auto: bf16 autocast {'on' if native else 'off'} (stub CPU)" in out
        assert json.loads((run / "run.json").read_text())["bf16"] is native
