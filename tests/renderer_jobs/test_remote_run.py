"""What the Ray and Slurm backends share (renderer_jobs.remote, spawn.run_batch), with tasks
played by threads and the bpy-free fake worker: events read back from the attempt logs,
retries, and made-up batch ends for tasks that died without writing theirs."""

from __future__ import annotations

import json
import threading

import pytest
from tests.renderer_jobs.test_local_backend import fake_cmd

from renderer_jobs import remote
from renderer_jobs.backend import Job
from renderer_jobs.events import BatchEnd, Commit, Frame, Start, encode
from renderer_jobs.spawn import run_batch
from renderer_jobs.submit import make_batches


class ThreadRun(remote.RemoteRun):
    """Each batch is a 'task' on a thread: run_batch, retried in place like a Slurm task;
    ``die`` maps a batch to a function that plays a task dying instead."""

    poll_s = 0.02

    def __init__(self, job: Job, die=None):
        super().__init__(job)
        self.threads = {}
        for b in job.batches:
            body = (die or {}).get(b.index) or self._task
            t = threading.Thread(target=body, args=(b,), daemon=True)
            t.start()
            self.threads[b.index] = t
        self.reported: set[int] = set()

    def _task(self, b) -> None:
        while run_batch(self.job.dataset, self.job.plan_dir, b.shards, b.index, self.job.log_dir, self.job.retries,
                        cmd=fake_cmd).retry:
            pass

    def _ended_tasks(self):
        out = {i: "thread ended" for i, t in self.threads.items() if not t.is_alive() and i not in self.reported}
        self.reported |= set(out)
        return out

    def _cancel_tasks(self):
        pass


def run(tmp_path, shards, behaviour, retries=0, die=None, per_worker=1):
    (tmp_path / "behaviour.json").write_text(json.dumps(behaviour))
    job = Job(dataset=tmp_path, plan_dir=tmp_path, batches=make_batches(shards, per_worker), retries=retries,
              log_dir=tmp_path / "logs")
    return ThreadRun(job, die).wait()


def test_events_come_back_from_the_logs_with_retries(tmp_path):
    events = run(tmp_path, ["a", "b"], {"b": "crash_once"}, retries=1)
    ends = sorted((e.batch, e.attempt, e.returncode, e.retry) for e in events if isinstance(e, BatchEnd))
    assert ends == [(0, 0, 0, False), (1, 0, 1, True), (1, 1, 0, False)]
    assert sorted(e.shard for e in events if isinstance(e, Commit)) == ["a", "b"]
    assert len([e for e in events if isinstance(e, Frame)]) == 4
    assert len([e for e in events if isinstance(e, Start)]) == 3
    logs = sorted(p.name for p in (tmp_path / "logs").iterdir())
    assert logs == ["batch_000000.0.log", "batch_000001.0.log", "batch_000001.1.log"]
    first = (tmp_path / "logs" / "batch_000001.0.log").read_text()
    assert "boom in b" in first and first.rstrip().splitlines()[-1].startswith('{"v": 2, "event": "batch_end"')


def test_a_task_that_died_without_its_batch_end_gets_one_made_up(tmp_path, monkeypatch):
    monkeypatch.setattr(remote, "END_GRACE_S", 0.2)

    def dies(b):  # wrote a frame event, then its process vanished
        (tmp_path / "logs").mkdir(exist_ok=True)
        (tmp_path / "logs" / f"batch_{b.index:06d}.0.log").write_text(
            encode(Frame(shard="x", key="x_v0", render_seconds=0.1)) + "\nFra:1 Mem:10M | Sample 1/4\n")

    events = run(tmp_path, ["x"], {}, die={0: dies})
    ends = [e for e in events if isinstance(e, BatchEnd)]
    assert len(ends) == 1 and (ends[0].returncode, ends[0].retry, ends[0].shards) == (-1, False, ("x",))
    assert "task ended (thread ended) without reporting its end" in ends[0].log_tail
    assert "Sample 1/4" in ends[0].log_tail
    assert [e.key for e in events if isinstance(e, Frame)] == ["x_v0"]


def test_an_attempt_followed_by_a_newer_one_ended(tmp_path, monkeypatch):
    monkeypatch.setattr(remote, "END_GRACE_S", 0.2)

    def died_then_retried(b):  # attempt 0 killed with its process (no batch_end); attempt 1 ran
        (tmp_path / "logs").mkdir(exist_ok=True)
        (tmp_path / "logs" / f"batch_{b.index:06d}.0.log").write_text("Traceback: lost\n")
        run_batch(tmp_path, tmp_path, b.shards, b.index, tmp_path / "logs", 1, cmd=fake_cmd)

    events = run(tmp_path, ["y"], {}, retries=1, die={0: died_then_retried})
    ends = [(e.attempt, e.returncode, e.retry) for e in events if isinstance(e, BatchEnd)]
    assert ends == [(0, -1, True), (1, 0, False)]


def test_a_remote_run_needs_a_log_dir(tmp_path):
    with pytest.raises(ValueError, match="log_dir"):
        ThreadRun(Job(dataset=tmp_path, plan_dir=tmp_path, batches=()))
