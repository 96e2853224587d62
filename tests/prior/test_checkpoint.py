"""prior.train.checkpoint: round trip; truncated, foreign and mismatched files are refused."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from tests.prior import scene
from prior.train import checkpoint as ckpt
from prior.train.loop import Trainer
from prior.train.run import prepare
from synth.errors import SynthError

pytest.importorskip("OpenEXR")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("ck")
    ds = scene.make_dataset(root / "d", identities=2, expressions=2, views=3, size=12)
    s = prepare(ds, root / "run", sets=scene.TINY, steps=2)
    tr = Trainer(s, torch.device("cpu"), tty=False, tensorboard=False)
    assert tr.run() == 0
    return root / "run", tr


def test_round_trip(run):
    path, tr = run
    ck = ckpt.load(ckpt.latest(path))
    assert ck.step == 2 and ck.config == tr.cfg and ck.layout == tr.s.table.layout
    state = tr.model.state_dict()
    assert ck.model_state.keys() == state.keys()
    assert all(torch.equal(ck.model_state[k], state[k]) for k in state)
    for k, v in tr.s.table.info.arrays().items():
        np.testing.assert_array_equal(getattr(ck.identities, k), v)
        assert getattr(ck.identities, k).dtype == v.dtype
    opt = ckpt.load_optimizer_state(ck)
    assert opt["step"] == 2 and opt["trainer"]["collapse_count"] == 0
    assert opt["trainer"]["loader"] == [tr.loader.state_dict()]  # the buffer's state, for an exact resume
    assert ck.losses["step"] == 2 and np.isfinite(ck.losses["loss"])
    # the scene sphere was fitted to the data and saved with the config
    assert ck.config.model.scene_radius == pytest.approx(
        float((np.linalg.norm(ck.identities.centre - np.array(ck.config.model.scene_center), axis=1)
               + ck.identities.radius).max()))


def test_truncated_foreign_and_mismatched_refused(run, tmp_path):
    path, _ = run
    good = ckpt.latest(path)
    data = good.read_bytes()
    for name, blob in [("half", data[: len(data) // 2]), ("head", data[:100]), ("empty", b""),
                       ("noise", bytes(range(256)) * 10)]:
        p = tmp_path / f"{name}.safetensors"
        p.write_bytes(blob)
        with pytest.raises(SynthError, match="truncated or foreign"):
            ckpt.load(p)
    from safetensors.torch import save_file

    foreign = tmp_path / "foreign.safetensors"
    save_file({"w": torch.zeros(3)}, str(foreign), metadata={"format": "pt"})
    with pytest.raises(SynthError, match="not a prior checkpoint"):
        ckpt.load(foreign)
    # a model file whose optimizer file is damaged or from another step
    d = tmp_path / "pair" / "checkpoints"
    d.mkdir(parents=True)
    (d / good.name).write_bytes(data)
    opt = good.with_name(good.name.replace(".safetensors", ".optim.pt")).read_bytes()
    (d / good.name.replace(".safetensors", ".optim.pt")).write_bytes(opt[:-10])
    with pytest.raises(SynthError, match="does not match"):
        ckpt.load_optimizer_state(ckpt.load(d / good.name))
    meta = json.loads(data[8:8 + int.from_bytes(data[:8], "little")])["__metadata__"]
    assert meta["format"] == ckpt.FORMAT and json.loads(meta["layout"])["size"] == scene.ID_SIZE + scene.EXPR_SIZE + 9


def test_keep_prunes_oldest(run):
    path, _ = run
    assert [s for s, _ in ckpt.list_checkpoints(path)] == [0, 2]
    assert not [p for p in (path / "checkpoints").iterdir() if p.name.startswith(".")]  # no temp files left
