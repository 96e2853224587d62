"""Helpers of the render-farm tests (test_farm_*.py): run `synth` in subprocesses, find the
worker processes of a dataset, wait for files, compare two datasets bit for bit."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SYNTH = [sys.executable, "-m", "synth.cli.main"]
#: The farm tests' render: 3 identities (3 shards), 1 expression, 2 views, at `ci`, slowed
#: down enough (64 spp) that a worker can be caught mid-shard.
SMALL = ["--identities", "3", "--expressions", "1", "--views", "2", "--preset", "ci", "--seed", "7",
         "--set", "render.samples=64"]


def env(**extra) -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in e.get("PYTHONPATH", "").split(os.pathsep) if p])
    e.update(extra)
    return e


def synth(*args, check: bool = True, timeout: float = 900,
          extra_env: dict | None = None) -> subprocess.CompletedProcess:
    p = subprocess.run([*SYNTH, *map(str, args)], capture_output=True, text=True, timeout=timeout,
                       env=env(**(extra_env or {})), cwd=ROOT)
    if check and p.returncode != 0:
        raise AssertionError(f"synth {' '.join(map(str, args))} -> {p.returncode}\n{p.stdout}\n{p.stderr}")
    return p


def start_synth(*args, extra_env: dict | None = None) -> subprocess.Popen:
    """`synth ...` in the background, in its own session (so a test can kill its group)."""
    return subprocess.Popen([*SYNTH, *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env(**(extra_env or {})), cwd=ROOT, start_new_session=True)


def wait_for(pred, what: str, limit: float = 120.0, every: float = 0.05):
    deadline = time.monotonic() + limit
    while True:
        got = pred()
        if got:
            return got
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {limit:.0f} s waiting for {what}")
        time.sleep(every)


def worker_pids(dataset: Path) -> list[int]:
    """Render workers (any backend) writing into ``dataset``, from /proc."""
    out = []
    needle = f"--dataset\0{dataset}\0"
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().decode(errors="replace")
        except OSError:
            continue
        if "blender_scripts.worker" in cmd and needle in cmd:
            out.append(int(d.name))
    return out


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text().split("State:")[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def kill(pids) -> None:
    for p in pids:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass


def leave_nothing_running(ctl: subprocess.Popen, out: Path) -> None:
    """After a test (passed or not): kill the workers of ``out`` and the controller's group."""
    kill(worker_pids(out))
    if ctl.poll() is None:
        os.killpg(ctl.pid, signal.SIGKILL)
        ctl.wait()


def staged(out: Path) -> list[Path]:
    d = out / ".staging"
    return sorted(d.glob("*/id*.json")) if d.is_dir() else []


def lease_holder(out: Path, shard: str) -> dict | None:
    try:
        return json.loads((out / ".staging" / f"{shard}.lease").read_text())
    except (OSError, ValueError):
        return None


def compare(a: Path, b: Path) -> tuple[int, str]:
    """scripts/compare_datasets.py: frame JSON (timing and host fields ignored) and EXR pixels."""
    p = subprocess.run([sys.executable, str(ROOT / "scripts" / "compare_datasets.py"), str(a), str(b)],
                       capture_output=True, text=True, env=env(), timeout=600)
    return p.returncode, p.stdout + p.stderr


def frame_keys(out: Path) -> list[str]:
    return sorted(p.stem for p in out.glob("shards/*/*.json") if p.name != "manifest.json")
