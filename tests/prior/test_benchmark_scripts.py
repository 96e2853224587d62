"""The prior's benchmark scripts still run (smoke tests; the figures live in docs/prior.md)."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_gpu_script_dry_run_on_cpu(tmp_path):
    r = subprocess.run(["bash", str(ROOT / "benchmarks" / "prior_gpu.sh"), "--dry"], capture_output=True, text=True,
                       env={**os.environ, "OUT": str(tmp_path)}, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads((tmp_path / "prior_gpu.json").read_text())
    assert res["preset"] == "small" and res["flops_per_step"] > 0 and res["eager_rays_per_s"] > 0
    assert res["max_abs_rgb"] == 0.0  # CPU against itself
    assert "| eager bf16 |" in r.stdout
    fit = json.loads((tmp_path / "prior_gpu_fit.json").read_text())  # the fitting part, same script
    assert fit["preset"] == "small" and fit["finetune_fp32_s_per_step"] > 0 and fit["finetune_bf16_s_per_step"] > 0
    full = fit["render"][0]
    assert full["samples"] == [32, 32, 32] and not full["bf16"] and full["max_abs_rgb"] == 0.0  # itself
    assert all(r["psnr_vs_full"] > 20 for r in fit["render"])
    assert "| samples per level |" in r.stdout


@pytest.mark.slow
def test_gpu_stream_script_dry_run_on_cpu(tmp_path):
    """benchmarks/prior_gpu_stream.sh --dry: both runs train (in memory and streaming) and the table prints."""
    r = subprocess.run(["bash", str(ROOT / "benchmarks" / "prior_gpu_stream.sh"), "--dry"], capture_output=True,
                       text=True, env={**os.environ, "OUT": str(tmp_path / "out"), "WORK": str(tmp_path / "w")},
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    rates = json.loads((tmp_path / "out" / "prior_gpu_stream.json").read_text())
    assert rates["0"] > 0 and rates["2"] > 0
    for buf in (0, 2):
        recs = [json.loads(line) for line in (tmp_path / "out" / f"stream_buf{buf}.jsonl").read_text().splitlines()]
        assert [rec["step"] for rec in recs] == [2, 4]
    assert "| streaming, buffer 2 |" in r.stdout and "streaming / in memory:" in r.stdout


def test_claim_test_plan_has_fixed_cameras(tmp_path):
    """benchmarks/prior_claim.py's test plan: every expression's views at TEST_VIEWS around its
    target at TEST_RADIUS_M, everything else the source plan's."""
    import importlib.util

    import numpy as np

    from synth.conventions import orbit_camera_to_world
    from synth.plan import io
    from tests.prior.test_cli import synth

    spec = importlib.util.spec_from_file_location("prior_claim", ROOT / "benchmarks" / "prior_claim.py")
    pc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pc)
    r = synth("plan", "-n", 2, "--start", 3, "--seed", 1, "--out", tmp_path / "p0",
              "--set", f"dataset.views_per_expression={len(pc.TEST_VIEWS)}", "--set", "camera.min_separation_deg=0",
              "--set", "dataset.expressions_per_identity=1")
    assert r.returncode == 0, r.stderr
    pc.fixed_camera_plan(tmp_path / "p0", tmp_path / "p1")
    a, b = io.load_plan(tmp_path / "p0"), io.load_plan(tmp_path / "p1")
    assert a.shard_ids() == b.shard_ids()
    for sid in a.shard_ids():
        for ia, ib in zip(a.shard(sid)["identities"], b.shard(sid)["identities"]):
            assert ia["identity_index"] == ib["identity_index"] and ia["target"] == ib["target"]
            for fr, (az, el) in zip(ib["expressions"][0]["frames"], pc.TEST_VIEWS):
                want = orbit_camera_to_world(az, el, pc.TEST_RADIUS_M, np.asarray(ib["target"]))
                np.testing.assert_allclose(fr["camera"]["camera_to_world"], want, atol=1e-6)
                assert fr["camera"]["azimuth_deg"] == az
    assert pc.scaled_sets(["finetune.steps=10", "finetune.lr_init=0.5"], 2.0) == ["finetune.steps=20",
                                                                                   "finetune.lr_init=0.5"]


def _bench(name: str):
    import importlib.util
    import sys

    sys.path.insert(0, str(ROOT / "benchmarks"))  # prior_sizes imports prior_claim
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_sizes_one_hot_plan_and_rows(tmp_path):
    """benchmarks/prior_sizes.py: identity k of the test plan gets the one-hot code on dimension k
    and the look-at target of that head; everything else is the source plan's. Its fit rows: 3
    views before 1, no pre-training from the largest rung's configuration."""
    import numpy as np

    from synth.model.default import load_default_model
    from synth.plan import io
    from synth.plan.identities import look_at_targets
    from tests.prior.test_cli import synth

    ps = _bench("prior_sizes")
    r = synth("plan", "-n", 2, "--start", 3, "--seed", 1, "--out", tmp_path / "p0",
              "--set", "dataset.views_per_expression=2", "--set", "dataset.expressions_per_identity=1")
    assert r.returncode == 0, r.stderr
    ps.one_hot_plan(tmp_path / "p0", tmp_path / "p1")
    a, b = io.load_plan(tmp_path / "p0"), io.load_plan(tmp_path / "p1")
    model = load_default_model()
    for k, sid in enumerate(b.shard_ids()):
        ia, ib = a.shard(sid)["identities"][0], b.shard(sid)["identities"][0]
        assert ib["identity_index"] == 3 + k and ib["expressions"] == ia["expressions"]
        code = np.asarray(ib["identity_code"])
        assert code[k] == 1.0 and np.count_nonzero(code) == 1 and len(code) == len(ia["identity_code"])
        np.testing.assert_allclose(ib["target"], look_at_targets(model, code, "head", [0, 0, 0])[0], atol=1e-6)
        assert ib["target"] != ia["target"]
    p = ps.PROFILES["cpu"]
    assert ps.rows(p)[:4] == [("none_views3", 60, 3), ("ids1_views3", 1, 3), ("ids15_views3", 15, 3),
                              ("ids60_views3", 60, 3)]
    assert ps.rows(p, [0, 15]) == [("none_views3", 60, 3), ("ids15_views3", 15, 3), ("none_views1", 60, 1),
                                   ("ids15_views1", 15, 1)]
    assert [ps.rung_of(n) for n, _, _ in ps.rows(p)] == [0, 1, 15, 60] * 2


def test_sizes_help_parses():
    import sys

    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "prior_sizes.py"), "--help"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and "--rungs" in r.stdout, r.stderr


@pytest.mark.slow
def test_scale_script_writes_measures_and_trains_ranks(tmp_path):
    """benchmarks/prior_scale.py at toy size: write, the loader-alone measure and real training ranks' peak RSS."""
    script, ds = str(ROOT / "benchmarks" / "prior_scale.py"), str(tmp_path / "ds")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}

    def run(*args):
        r = subprocess.run([os.sys.executable, script, *args], capture_output=True, text=True, env=env, timeout=600)
        assert r.returncode == 0, r.stderr[-2000:]
        return r.stdout

    assert "wrote 3 identities, 78 frames" in run("write", "--identities", "3", "--views", "2", "--out", ds)
    out = run("measure", ds, "--buffer", "2", "--steps", "5", "--ranks", "1")
    assert "| prepare | 78 frames |" in out and "| 1 rank(s), rank 0 |" in out
    rows = [x for x in run("train-rss", ds, "--buffer", "2", "--steps", "2", "--ranks", "1", "2").splitlines()
            if x.startswith("|")]
    assert len(rows) == 2 and all(x.endswith("| ok |") for x in rows)
    assert len(rows[1].split("peak RSS ")[1].split(" MB")[0].split(" / ")) == 2  # one figure per rank
