"""Issue 15 with the real worker (bpy): several ``synth render`` started at the same moment on
one ``--out`` share one plan, split the shards and each exit 0 only once every shard is
committed; an output path that is not UTF-8 renders, resumes and validates
(docs/reliability.md)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from tests.support.farm_helpers import ROOT, SYNTH, env, synth

pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

TINY = ["--expressions", "1", "--views", "1", "--preset", "ci", "--seed", "3"]


@pytest.mark.parametrize("runs", [2, 4])
def test_renders_started_together_cooperate(tmp_path, runs):
    out = tmp_path / "ds"
    args = [*SYNTH, "render", "--identities", "4", *TINY, "--out", str(out), "--progress-every", "0.5"]
    procs = [subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env(), cwd=ROOT)
             for _ in range(runs)]  # as close to the same moment as a shell's `a & b &`
    results = [(p, *p.communicate(timeout=900)) for p in procs]
    for p, o, e in results:
        assert p.returncode == 0, o + e
        assert "4/4 frames in 4/4 shards committed" in o, o  # decided from the files when it exited
        assert "Traceback" not in e
    rendered = [int(o.split("rendered ")[1].split()[0]) for _, o, _ in results]
    assert sum(rendered) == 4  # each frame rendered by exactly one of the runs (shards split by their leases)
    assert sorted(n for n in os.listdir(out) if n.startswith(".")) == [".commits", ".lock", ".staging"]
    synth("validate", out)


def test_an_output_path_that_is_not_utf8_renders_and_resumes(tmp_path):
    out = Path(os.fsdecode(os.fsencode(tmp_path) + b"/ds-\xff"))
    p = synth("render", "--identities", "1", *TINY, "--out", out)
    assert "1/1 frames in 1/1 shards committed; rendered 1 now" in p.stdout, p.stdout
    p = synth("render", "--identities", "1", *TINY, "--out", out)
    assert "1/1 frames in 1/1 shards committed; rendered 0 now" in p.stdout, p.stdout
    synth("validate", out)
