"""The prior with a head model other than the default (the ICT-FaceKit sample: 10 identity and 57
expression dimensions; skipped when absent): ``synth render`` a tiny dataset with it (Blender),
``synth prior train`` on it and ``synth prior fit --model ict.npz``; the code layout follows the
model's dimensions."""

from __future__ import annotations

import json

import numpy as np
import pytest

from synth.assets.classes import NAMES
from synth.model.format import write_model
from tests.prior.test_cli import SETS, synth
from tests.prior.test_fit_cli import FIT_SETS
from tests.support.models import ict_model

pytest.importorskip("bpy")
pytest.importorskip("OpenEXR")
pytestmark = [pytest.mark.blender, pytest.mark.slow]


def test_train_and_fit_on_an_ict_facekit_dataset(tmp_path):
    data = ict_model()
    model = write_model(data, tmp_path / "ict.npz")
    ds = tmp_path / "ds"
    bare = ",".join(f'"{c}"' for c in NAMES)  # bare heads: the prior, not the rigs, is under test
    r = synth("render", "--model", model, "-n", "2", "--expressions", "1", "--views", "3", "--preset", "ci",
              "--out", ds, "--set", f"assets.disabled_classes=[{bare}]", timeout=1200)
    assert r.returncode == 0, r.stderr
    r = synth("prior", "train", ds, "--out", tmp_path / "run", "--steps", 3, *SETS)
    assert r.returncode == 0, r.stderr
    inputs = sorted((ds / "shards").glob("*/id000000_ex00_v0*.exr"))
    assert len(inputs) == 3
    r = synth("prior", "fit", *inputs, "--prior", tmp_path / "run", "--out", tmp_path / "fit", "--model", model,
              *FIT_SETS)
    assert r.returncode == 0, r.stderr
    info = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert info["head_model"]["name"] == "ict-facekit"
    codes = np.asarray(info["codes"])
    assert codes.shape == (3, data.identity_dims + data.expression_dims + 9) == (3, 10 + 57 + 9)
    assert np.isfinite(codes).all()
