"""A plan renders on any node: planned under numpy 2.x (.venv-np2: what a plain
`pip install synth-faces` gets, made by scripts/setup.sh) with an empty cache, rendered under this
environment's numpy 1.26 with another BLAS thread count and another empty cache, it gives the
frames of the plan made and rendered in one process. The builder reproduces the shipped default
model under numpy 2.x too."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from tests.support.farm_helpers import ROOT, SMALL, compare, env, synth

NP2 = ROOT / ".venv-np2" / "bin" / "python"
needs_np2 = pytest.mark.skipif(not NP2.is_file(), reason="no .venv-np2: run 'make setup' (scripts/setup.sh makes it)")


def np2(*args, cache: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(NP2), *map(str, args)], capture_output=True, text=True, cwd=ROOT, timeout=900,
                          env=env(SYNTH_CACHE_DIR=str(cache)))


@needs_np2
@pytest.mark.slow
def test_numpy2_is_what_the_other_environment_has(tmp_path):
    p = np2("-c", "import numpy; print(numpy.__version__)", cache=tmp_path)
    assert p.returncode == 0 and int(p.stdout.split(".")[0]) >= 2, p.stdout + p.stderr


@needs_np2
@pytest.mark.slow
@pytest.mark.blender
def test_a_plan_made_under_numpy2_renders_here_with_one_blas_thread_and_an_empty_cache(tmp_path, farm_reference):
    pytest.importorskip("bpy")
    plan = tmp_path / "plan"
    p = np2("-m", "synth.cli.main", "plan", "-n", "3", "--seed", "7", "--set", "dataset.expressions_per_identity=1",
            "--set", "dataset.views_per_expression=2", "--set", "render.preset=ci", "--set", "render.samples=64",
            "-o", plan, "-q", cache=tmp_path / "cache_np2")
    assert p.returncode == 0, p.stderr
    reference = json.loads((farm_reference / "plan" / "plan.json").read_text())
    assert json.loads((plan / "plan.json").read_text())["plan_hash"] == reference["plan_hash"]
    assert not (tmp_path / "cache_np2" / "models").exists()  # the default model is package data
    out = tmp_path / "ds"
    synth("render", "--plan", plan, "--out", out, "-q",
          extra_env={"OPENBLAS_NUM_THREADS": "1", "SYNTH_CACHE_DIR": str(tmp_path / "cache_render")})
    rc, text = compare(out, farm_reference)
    assert rc == 0, text


@needs_np2
@pytest.mark.slow
def test_the_builder_reproduces_the_shipped_model_under_numpy2(tmp_path):
    p = np2(ROOT / "scripts" / "build_default_model.py", "--check", cache=tmp_path)
    assert p.returncode == 0 and "the build reproduces the shipped model" in p.stdout, p.stdout + p.stderr


def _rewrite(plan: Path, header: dict) -> None:
    """plan.json with another model sha256, as a plan made with that model has it."""
    from synth.plan.io import header_hash

    header["plan_hash"] = header_hash(header)
    (plan / "plan.json").write_text(json.dumps(header))


def test_a_changed_default_model_is_refused_in_one_line_naming_both_hashes(tmp_path, monkeypatch):
    """A node whose installed default model is not the plan's (another synth-faces version)."""
    from synth.errors import SynthError
    from synth.plan import io

    plan = tmp_path / "plan"
    synth("plan", "-n", "1", "--set", "render.preset=ci", "-o", plan, "-q")
    header = json.loads((plan / "plan.json").read_text())
    other = "0" * 64
    header["model"]["sha256"] = other
    _rewrite(plan, header)
    monkeypatch.setenv("SYNTH_CACHE_DIR", str(tmp_path / "cache"))
    with pytest.raises(SynthError) as e:
        io.load_plan(plan).checked_model_path()
    msg = str(e.value)
    assert "\n" not in msg and os.uname().nodename in msg and other[:16] in msg
    assert "fcab7c3b35ba672e" in msg and "synth-faces version" in msg


def test_an_old_plan_of_the_default_model_finds_its_build_in_the_cache(tmp_path, monkeypatch):
    """Plans made when the default model was built into the user cache keep rendering there."""
    import shutil

    from synth.io import sha256_file
    from synth.model.default import packaged_model_path
    from synth.plan import io

    plan = tmp_path / "plan"
    synth("plan", "-n", "1", "--set", "render.preset=ci", "-o", plan, "-q")
    cached = tmp_path / "cache" / "models" / "makehuman-head-0123456789abcdef.npz"
    cached.parent.mkdir(parents=True)
    shutil.copy(packaged_model_path(), cached)
    with open(cached, "ab") as f:
        f.write(b"\0")  # other bytes: an older build
    header = json.loads((plan / "plan.json").read_text())
    header["model"]["sha256"] = sha256_file(cached)
    _rewrite(plan, header)
    monkeypatch.setenv("SYNTH_CACHE_DIR", str(tmp_path / "cache"))
    assert io.load_plan(plan).checked_model_path() == cached
