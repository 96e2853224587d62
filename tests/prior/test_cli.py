"""synth prior train / render / info as a user runs them: end to end, bad input (one line, exit 2,
nothing written), Ctrl-C (checkpoint, exit 130, exact resume)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.prior import scene

pytest.importorskip("OpenEXR")
ROOT = Path(__file__).resolve().parents[2]
SETS = [a for s in scene.TINY for a in ("--set", s)]


def synth(*args, timeout=600, path_first=None):
    """``synth ARGS`` in a subprocess; ``path_first``: a folder searched before the checkout (a stand-in module)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(str(p) for p in (path_first, ROOT) if p is not None)}
    return subprocess.run([sys.executable, "-m", "synth.cli.main", *map(str, args)], capture_output=True, text=True,
                          env=env, timeout=timeout)


def one_line_error(r) -> str:
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("synth: error: "), r.stderr
    return lines[0]


def snapshot(d: Path) -> dict:
    return {str(p.relative_to(d)): (p.stat().st_size, p.stat().st_mtime_ns) for p in d.rglob("*")} if d.exists() \
        else {}


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli")
    ds = scene.make_dataset(root / "d", identities=2, expressions=2, views=3, size=12)
    r = synth("prior", "train", ds, "--out", root / "run", "--steps", 3, *SETS)
    assert r.returncode == 0, r.stderr
    assert "step 3/3" in r.stdout  # plain progress lines when not on a terminal
    return root, ds, root / "run"


def test_train_info_render(trained):
    root, ds, run = trained
    r = synth("prior", "info", run)
    assert r.returncode == 0 and "step 3 of 3" in r.stdout and "identities  2: 0, 1" in r.stdout, r.stderr
    assert "beta 4 + expression 3 + joints jaw, eye_l, eye_r (3 each) = 16" in r.stdout
    out = root / "views"
    r = synth("prior", "render", run, "--identity", 1, "--expression", 1, "--orbit", 2, "--size", 10, "-o", out)
    assert r.returncode == 0, r.stderr
    from PIL import Image
    import OpenEXR

    for k in range(2):
        key = f"id000001_ex01_orbit{k:03d}"
        for kind in ("colour", "opacity", "normals"):
            assert Image.open(out / f"{key}_{kind}.png").size == (10, 10)
        z = OpenEXR.File(str(out / f"{key}_depth.exr")).channels()["Z"].pixels
        assert z.shape == (10, 10) and np.isfinite(z).all() and (z >= 0).all()
    assert (out / "cameras.json").is_file()


@pytest.mark.parametrize("case", ["no_shards", "missing_dataset", "bad_set", "resume_nothing", "fresh_over_run",
                                  "resume_other_dims", "resume_with_preset"])
def test_train_errors(trained, tmp_path, case):
    root, ds, run = trained
    out = tmp_path / "run"
    if case == "no_shards":
        (tmp_path / "empty" / "shards").mkdir(parents=True)
        args = [tmp_path / "empty", "--out", out]
    elif case == "missing_dataset":
        args = [tmp_path / "nope", "--out", out]
    elif case == "bad_set":
        args = [ds, "--out", out, "--set", "train.stepz=3"]
    elif case == "resume_nothing":
        args = [ds, "--out", out, "--resume"]
    elif case == "fresh_over_run":
        out = run
        args = [ds, "--out", run, *SETS]
    elif case == "resume_other_dims":
        other = scene.make_dataset(tmp_path / "other", identities=2, expressions=2, views=3, size=12, id_size=6)
        out = run
        args = [other, "--out", run, "--resume", "--steps", 5]
    else:
        out = run
        args = [ds, "--out", run, "--resume", "--preset", "paper"]
    before = snapshot(out)
    msg = one_line_error(synth("prior", "train", *args))
    assert snapshot(out) == before, msg  # nothing written (or changed)
    expect = {"no_shards": "no committed frames", "missing_dataset": "not a dataset", "bad_set": "train.steps",
              "resume_nothing": "nothing to resume", "fresh_over_run": "already has checkpoints",
              "resume_other_dims": "differ from the checkpoint", "resume_with_preset": "cannot change"}[case]
    assert expect in msg


def test_render_and_info_errors(trained, tmp_path):
    root, ds, run = trained
    out = tmp_path / "views"
    assert "identity 7 is not in this run" in one_line_error(
        synth("prior", "render", run, "--identity", 7, "--expression", 0, "-o", out))
    assert "expression 9" in one_line_error(synth("prior", "render", run, "--identity", 0, "--expression", 9, "-o", out))
    assert not out.exists()
    bad = tmp_path / "bad"
    (bad / "checkpoints").mkdir(parents=True)
    good = sorted((run / "checkpoints").glob("*.safetensors"))[-1].read_bytes()
    (bad / "checkpoints" / "step_00000009.safetensors").write_bytes(good[: len(good) // 3])
    assert "truncated or foreign" in one_line_error(synth("prior", "info", bad))
    assert "truncated or foreign" in one_line_error(
        synth("prior", "render", bad, "--identity", 0, "--expression", 0, "-o", out))
    assert not out.exists()
    assert "no checkpoint" in one_line_error(synth("prior", "info", tmp_path))


@pytest.mark.slow
def test_ctrl_c_checkpoints_and_resume_continues(trained, tmp_path):
    root, ds, _ = trained
    run = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.Popen([sys.executable, "-m", "synth.cli.main", "prior", "train", str(ds), "--out", str(run),
                          "--steps", "100000", *SETS, "--set", "train.checkpoint_every=100000"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    for line in p.stdout:
        if line.startswith("step 2/"):
            break
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    assert "interrupted: checkpoint of step" in out
    from prior.train import checkpoint as ckpt

    step = ckpt.load(ckpt.latest(run)).step
    assert step >= 2
    r = synth("prior", "train", ds, "--out", run, "--resume", "--steps", step + 2)
    assert r.returncode == 0, r.stderr
    assert ckpt.load(ckpt.latest(run)).step == step + 2
