"""``--json`` on plan, validate and report: one JSON document on stdout, matching the files."""

from __future__ import annotations

import json
import subprocess
import sys

from synth.dataset.shards import open_dataset
from tests.support import fake_frames

SYNTH = [sys.executable, "-m", "synth.cli.main"]


def run(*args, check=True):
    return subprocess.run([*SYNTH, *map(str, args)], capture_output=True, text=True, check=check)


def test_plan_json(tmp_path):
    out = tmp_path / "plan"
    s = json.loads(run("plan", "-n", 2, "-o", out, "--set", "dataset.expressions_per_identity=2",
                       "--set", "dataset.views_per_expression=3", "--json").stdout)
    header = json.loads((out / "plan.json").read_text())
    assert s["plan_hash"] == header["plan_hash"] and s["num_frames"] == 12 == header["num_frames"]
    assert s["num_shards"] == len(header["shards"]) and s["summary"]["frames"] == 12
    assert s["model"]["name"] == header["model"]["name"]


def test_validate_json(tmp_path):
    ds = open_dataset(tmp_path / "ds", "a" * 64, fake_frames.plan(2, 1, 2))
    fake_frames.render_dataset(ds, shards=["shard_000000"])
    p = run("validate", tmp_path / "ds", "--json", check=False)
    rep = json.loads(p.stdout)
    assert p.returncode == 1 and rep["ok"] is False and rep["shards_checked"] == 1
    assert [d["kind"] for d in rep["defects"]] == ["missing-shard"]
    p = run("validate", tmp_path / "ds", "--json", "--partial")
    assert json.loads(p.stdout)["ok"] is True


def test_report_json(tmp_path):
    ds = open_dataset(tmp_path / "ds", "a" * 64, fake_frames.plan(2, 1, 2))
    fake_frames.render_dataset(ds, shards=["shard_000001"])
    s = json.loads(run("report", tmp_path / "ds", "--json").stdout)
    assert s["progress"]["shards_committed"] == 1 and s["identities"]["count"] == 1
