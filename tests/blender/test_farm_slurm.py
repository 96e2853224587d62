"""The Slurm backend on a real single-node Slurm (Debian's slurm-wlm and munge, set up for
localhost by scripts/slurm_local.sh): the render as a job array, one array task cancelled
with scancel mid-render, the rerun finishing the job with the same bytes as the local
backend. Skipped, saying why, where a local Slurm cannot be installed or started."""

from __future__ import annotations

import os
import signal
import subprocess

import pytest
from tests.support.farm_helpers import (ROOT, SMALL, compare, env, frame_keys, lease_holder, leave_nothing_running,
                                        staged, start_synth, synth, wait_for)

pytest.importorskip("bpy")
pytest.importorskip("submitit")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

SCRIPT = ROOT / "scripts" / "slurm_local.sh"


@pytest.fixture(scope="module")
def slurm(tmp_path_factory):
    """A running local Slurm: {"SLURM_CONF": ...}; its jobs cancelled and daemons stopped after."""
    if os.geteuid() != 0:
        pytest.skip("a local Slurm needs root here (scripts/slurm_local.sh runs the daemons as root)")
    state = tmp_path_factory.mktemp("slurm")
    p = subprocess.run(["bash", str(SCRIPT), "start", str(state)], capture_output=True, text=True, timeout=1200)
    if p.returncode == 3:
        pytest.skip(p.stderr.strip().splitlines()[-1])
    try:
        assert p.returncode == 0, p.stdout + p.stderr
        yield {"SLURM_CONF": str(state / "slurm.conf")}
    finally:
        subprocess.run(["bash", str(SCRIPT), "stop", str(state)], capture_output=True, text=True, timeout=300)


def squeue(conf: dict) -> dict[str, str]:
    p = subprocess.run(["squeue", "-h", "-r", "-o", "%i|%T"], capture_output=True, text=True, env=env(**conf))
    return dict(line.split("|", 1) for line in p.stdout.split() if "|" in line)


def test_slurm_array_with_a_cancelled_task_then_rerun_equals_local(slurm, farm_reference, tmp_path):
    out = tmp_path / "ds"
    args = ["render", *SMALL, "--out", out, "--backend", "slurm", "--shards-per-worker", "1",
            "--array-parallelism", "1", "--progress-every", "5"]
    ctl = start_synth(*args, extra_env=slurm)
    try:
        # one task at a time: cancel the first while its worker renders (a frame staged, not
        # committed). The worker is stopped (SIGSTOP) as soon as it has staged a frame, so the
        # cancel cannot come after its shard's last frame: one frame is 0.4 s of Cycles on an idle
        # machine at this preset, less than finding the task with squeue and scancel's delivery
        # take, and the run then ended with every shard committed (exit 0). scancel sends the job
        # SIGCONT and SIGTERM: the worker goes on only to stop at once (renderer_jobs/guard.py).
        def stopped_mid_shard():
            for p in staged(out):
                h = lease_holder(out, p.parent.name)
                if h is None:
                    continue
                os.kill(h["pid"], signal.SIGSTOP)
                if (out / "shards" / p.parent.name / "manifest.json").exists():  # committed meanwhile
                    os.kill(h["pid"], signal.SIGCONT)
                    continue
                return p.parent.name
            return None

        shard = wait_for(stopped_mid_shard, "a worker with a staged frame", 600)
        running = [t for t, s in squeue(slurm).items() if s == "RUNNING"]
        assert len(running) == 1, running  # --array-parallelism 1: the stopped worker's task
        subprocess.run(["scancel", running[0]], check=True, env=env(**slurm))
        stdout, err = ctl.communicate(timeout=900)
    finally:
        leave_nothing_running(ctl, out)
    assert ctl.returncode == 3, stdout + err
    assert "synth: error: 1 shard(s) failed after their retries" in err
    assert len(list(out.glob("shards/*/manifest.json"))) == 2  # the other tasks ran on
    assert not (out / "shards" / shard / "manifest.json").exists()  # the cancelled one did not
    assert list(out.glob("logs/slurm-*/submitit/*")), "submitit's per-task logs live under the dataset"
    p = synth(*args, extra_env=slurm)
    assert "6/6 frames in 3/3 shards committed" in p.stdout
    synth("validate", out)
    assert frame_keys(out) == frame_keys(farm_reference)
    rc, text = compare(farm_reference, out)
    assert rc == 0, text
