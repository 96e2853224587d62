"""`synth model info/sample` through the real CLI entry point (exit codes, outputs)."""

from __future__ import annotations

import json

from synth.cli.main import main
from synth.model.format import write_model
from tests.support.toy_model import random_model


def test_info_json_and_sample(tmp_path, capsys):
    p = write_model(random_model(), tmp_path / "m.npz")
    assert main(["model", "info", "--model", str(p), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["identity_dims"] == 6 and info["joints"][:2] == ["neck", "head"]
    assert info["landmarks"] == {"ibug68": 68} and info["license"] == "test licence"
    out = tmp_path / "sub" / "heads"  # parent does not exist yet
    assert main(["model", "sample", "--n", "3", "--seed", "1", "--model", str(p), "--out", str(out)]) == 0
    files = sorted(x.name for x in out.iterdir())
    assert files == ["codes.json", "sample_00000.obj", "sample_00001.obj", "sample_00002.obj"]
    first = (out / "sample_00000.obj").read_bytes()
    # mesh i depends only on (seed, i): a larger n reproduces it byte for byte
    out2 = tmp_path / "heads2"
    assert main(["model", "sample", "--n", "5", "--seed", "1", "--model", str(p), "--out", str(out2)]) == 0
    assert (out2 / "sample_00000.obj").read_bytes() == first


def test_errors_are_one_line_exit_2(tmp_path, capsys):
    assert main(["model", "info", "--model", str(tmp_path / "nope.npz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not found" in err[0]
    p = write_model(random_model(), tmp_path / "m.npz")
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "x").write_text("keep")
    assert main(["model", "sample", "--model", str(p), "--out", str(busy)]) == 2
    assert (busy / "x").read_text() == "keep" and len(list(busy.iterdir())) == 1
