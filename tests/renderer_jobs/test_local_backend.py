"""The local backend (renderer_jobs.local) with a bpy-free fake worker (tests/fake_worker.py):
events in order, one batch per process, retries, per-attempt logs, cancel (SIGTERM to the
whole process group, SIGKILL after the grace time)."""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path

import pytest

from renderer_jobs import local
from renderer_jobs.backend import Job
from renderer_jobs.events import BatchEnd, Commit, Error, Frame, Start
from renderer_jobs.submit import RunStats, make_batches

FAKE = Path(__file__).resolve().parents[1] / "support" / "fake_worker.py"


def fake_cmd(dataset: Path, plan_dir: Path, shards) -> list[str]:
    return [sys.executable, str(FAKE), "--dataset", str(dataset), "--plan", str(plan_dir), "--shards", ",".join(shards)]


def submit(tmp_path, shards, behaviour=None, workers=1, per_worker=2, **job):
    (tmp_path / "behaviour.json").write_text(json.dumps(behaviour or {}))
    backend = local.LocalBackend(workers=workers, cmd=fake_cmd)
    return backend.submit(Job(dataset=tmp_path, plan_dir=tmp_path / "plan", batches=make_batches(shards, per_worker),
                              **job))


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text().split("State:")[1].split()[0]
    except (FileNotFoundError, IndexError):
        return False
    return state not in ("Z", "X")


def test_events_of_each_batch_end_with_its_batch_end(tmp_path):
    shards = [f"s{i}" for i in range(5)]
    events = submit(tmp_path, shards, workers=2, per_worker=2).wait()
    ends = [e for e in events if isinstance(e, BatchEnd)]
    assert sorted((e.batch, e.shards) for e in ends) == [(0, ("s0", "s1")), (1, ("s2", "s3")), (2, ("s4",))]
    assert all(e.returncode == 0 and e.attempt == 0 and not e.retry for e in ends)
    assert sorted(e.shard for e in events if isinstance(e, Commit)) == shards
    assert sorted(e.key for e in events if isinstance(e, Frame)) == sorted(f"{s}_v{v}" for s in shards for v in (0, 1))
    starts = [e for e in events if isinstance(e, Start)]
    assert sorted(e.shards for e in starts) == [("s0", "s1"), ("s2", "s3"), ("s4",)]
    assert len({e.pid for e in starts}) == 3, "one fresh process per batch"
    for end in ends:  # a process's own events all come before its batch_end
        i_end = events.index(end)
        mine = [i for i, e in enumerate(events) if isinstance(e, (Frame, Commit)) and e.shard in end.shards]
        assert mine and max(mine) < i_end
        assert "worker: " in end.log_tail  # stderr tail
    stats = RunStats()
    for e in events:
        stats.add(e)
    assert (stats.frames_rendered, stats.worker_starts, stats.failures) == (10, 3, [])
    assert stats.render_seconds == pytest.approx(5.0)


def test_nothing_to_do_starts_nothing(tmp_path):
    assert submit(tmp_path, []).wait() == []


def test_a_crash_is_retried_and_each_attempt_has_its_log(tmp_path):
    events = submit(tmp_path, ["a", "b"], {"b": "crash_once"}, retries=2, log_dir=tmp_path / "logs").wait()
    ends = [e for e in events if isinstance(e, BatchEnd)]
    assert [(e.attempt, e.returncode, e.retry) for e in ends] == [(0, 1, True), (1, 0, False)]
    assert "boom in b" in ends[0].log_tail
    stats = RunStats()
    for e in events:
        stats.add(e)
    assert stats.failures == [] and stats.worker_starts == 2
    assert sorted(e.shard for e in events if isinstance(e, Commit)) == ["a", "a", "b"]  # the worker re-did "a";
    # the real worker skips a committed shard (it reads the dataset), the fake does not
    first = (tmp_path / "logs" / "batch_000000.0.log").read_text()
    second = (tmp_path / "logs" / "batch_000000.1.log").read_text()
    assert "boom in b" in first and "boom" not in second
    assert "Fra:1 Mem" in second and '"event": "commit"' in second


def test_without_retries_a_crash_is_a_failure_with_the_stderr_tail(tmp_path):
    events = submit(tmp_path, ["a", "b", "c"], {"b": "crash"}, per_worker=1, retries=0).wait()
    stats = RunStats()
    for e in events:
        stats.add(e)
    assert len(stats.failures) == 1
    assert stats.failures[0].startswith("worker for b exited with code 1:\n")
    assert "Traceback: boom in b" in stats.failures[0]
    assert sorted(e.shard for e in events if isinstance(e, Commit)) == ["a", "c"]  # the others go on


def test_a_reported_error_is_not_retried(tmp_path):
    events = submit(tmp_path, ["a"], {"a": "error"}, retries=3).wait()
    ends = [e for e in events if isinstance(e, BatchEnd)]
    assert [(e.returncode, e.retry) for e in ends] == [(2, False)]
    stats = RunStats()
    for e in events:
        stats.add(e)
    assert stats.failures[0] == "a: bad input for a"
    assert stats.failures[1].startswith("worker for a exited with code 2")


def test_an_event_of_another_version_is_reported(tmp_path):
    events = submit(tmp_path, ["a"], {"a": "bad_event"}).wait()
    errs = [e for e in events if isinstance(e, Error)]
    assert len(errs) == 1 and "protocol version 99" in errs[0].message
    assert [e.shard for e in events if isinstance(e, Commit)] == ["a"]


def _wait_for(pred, what: str, limit: float = 30.0) -> None:
    deadline = time.monotonic() + limit
    while not pred():
        assert time.monotonic() < deadline, what
        time.sleep(0.02)


@pytest.mark.parametrize("behaviour, rc", [("hang", -signal.SIGTERM), ("stubborn", -signal.SIGKILL)])
def test_cancel_stops_every_worker_and_its_children(tmp_path, monkeypatch, behaviour, rc):
    monkeypatch.setattr(local, "TERM_GRACE_S", 0.5)
    run = submit(tmp_path, ["a", "b", "c"], {"a": behaviour, "b": behaviour, "c": "ok"}, workers=2, per_worker=1)
    it = run.events()
    started = set()
    for ev in it:
        if isinstance(ev, Start):
            started |= set(ev.shards)
        if started == {"a", "b"}:
            break
    _wait_for(lambda: all((tmp_path / f"{s}.child").exists() for s in "ab"), "children not started")
    children = [int((tmp_path / f"{s}.child").read_text()) for s in "ab"]
    try:
        run.cancel()
        rest = list(run.events())
        ends = [e for e in rest if isinstance(e, BatchEnd)]
        assert sorted((e.shards, e.returncode, e.retry) for e in ends) == [(("a",), rc, False), (("b",), rc, False)]
        assert not any(isinstance(e, Start) for e in rest), "no batch starts after cancel"
        _wait_for(lambda: not any(alive(p) for p in children), "a worker's child survived the cancel", 10.0)
    finally:  # leave nothing running if the test fails
        for p in children:
            try:
                os.kill(p, signal.SIGKILL)
            except ProcessLookupError:
                pass


def test_workers_get_the_environment_given(tmp_path):
    backend = local.LocalBackend(workers=1, env={"PATH": os.environ.get("PATH", ""), "FOO": "1"})
    assert backend.env["FOO"] == "1" and backend.env["PYTHONUNBUFFERED"] == "1"
    assert "blender_scripts.worker" in local.worker_command(tmp_path, tmp_path / "plan", ["a", "b"])
    assert local.worker_command(tmp_path, tmp_path / "plan", ["a", "b"])[-1] == "a,b"
