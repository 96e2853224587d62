"""The local backend: W worker processes on this machine, one fresh process per batch.

Each worker is ``python -m blender_scripts.worker`` in its own process group; its stdout is
parsed into events (:mod:`renderer_jobs.events`) and the last lines of its stderr are kept
for the ``batch_end`` event (all of its output goes to ``Job.log_dir`` when one is given).
:meth:`LocalRun.cancel` (Ctrl-C) sends SIGTERM to every worker's group, waits up to 10 s,
then SIGKILLs; frames already staged survive and the next run resumes.
"""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import IO

from renderer_jobs.backend import Backend, Batch, Job, Run
from renderer_jobs.events import BatchEnd, Error, Event, EventError, parse_line

#: Lines of a worker's stderr kept for the ``batch_end`` event.
TAIL_LINES = 15
#: Seconds between SIGTERM and SIGKILL on cancel.
TERM_GRACE_S = 10.0

WorkerCommand = Callable[[Path, Path, Sequence[str]], list[str]]


def worker_command(dataset: Path, plan_dir: Path, shards: Sequence[str]) -> list[str]:
    """The command line of one render worker."""
    return [sys.executable, "-m", "blender_scripts.worker", "--dataset", str(dataset), "--plan", str(plan_dir),
            "--shards", ",".join(shards)]


class _Worker:
    """One running worker process and the threads reading its output."""

    def __init__(self, batch: Batch, attempt: int, cmd: list[str], env: dict, log_path: Path | None,
                 out: queue.Queue):
        self.batch, self.attempt = batch, attempt
        self.tail: deque[str] = deque(maxlen=40)
        self.reported_error = False
        self._log: IO[str] | None = None
        self._log_lock = threading.Lock()
        if log_path is not None:
            log_path.parent.mkdir(parents=True, exist_ok=True)
            self._log = open(log_path, "w", encoding="utf-8")
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     errors="replace", env=env, start_new_session=True)
        self._threads = [threading.Thread(target=self._read_stdout, args=(out,), daemon=True),
                         threading.Thread(target=self._read_stderr, daemon=True)]
        for t in self._threads:
            t.start()

    def _logline(self, line: str) -> None:
        if self._log is not None:
            with self._log_lock:
                self._log.write(line if line.endswith("\n") else line + "\n")

    def _read_stdout(self, out: queue.Queue) -> None:
        for line in self.proc.stdout:  # type: ignore[union-attr]
            self._logline(line)
            try:
                ev = parse_line(line)
            except EventError as e:
                ev = Error(shard=",".join(self.batch.shards), message=f"unreadable worker event: {e}")
            if ev is None:
                continue
            if isinstance(ev, Error):
                self.reported_error = True
            out.put(ev)

    def _read_stderr(self) -> None:
        for line in self.proc.stderr:  # type: ignore[union-attr]
            self._logline(line)
            self.tail.append(line.rstrip())

    def finish(self) -> None:
        """After the process ended: let the readers reach the end of its output."""
        for t in self._threads:
            t.join(timeout=5.0)
        if self._log is not None:
            with self._log_lock:
                self._log.close()

    def signal_group(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            pass


class LocalRun(Run):
    def __init__(self, job: Job, workers: int, env: dict, cmd: WorkerCommand):
        self.job, self.workers, self.env, self.cmd = job, max(1, workers), env, cmd
        self._todo: deque[tuple[Batch, int]] = deque((b, 0) for b in job.batches)
        self._running: list[_Worker] = []
        self._events: queue.Queue = queue.Queue()
        self._cancelled = False

    def _start(self, batch: Batch, attempt: int) -> None:
        cmd = self.cmd(self.job.dataset, self.job.plan_dir, batch.shards)
        self._running.append(_Worker(batch, attempt, cmd, self.env, self.job.log_path(batch, attempt),
                                     self._events))

    def _reap(self) -> None:
        for w in list(self._running):
            rc = w.proc.poll()
            if rc is None:
                continue
            self._running.remove(w)
            w.finish()
            retry = (rc != 0 and not w.reported_error and not self._cancelled and w.attempt < self.job.retries)
            self._events.put(BatchEnd(batch=w.batch.index, shards=w.batch.shards, attempt=w.attempt,
                                      returncode=rc, log_tail="\n".join(list(w.tail)[-TAIL_LINES:]),
                                      retry=retry))
            if retry:
                self._todo.append((w.batch, w.attempt + 1))

    def events(self) -> Iterator[Event]:
        while self._todo or self._running or not self._events.empty():
            while self._todo and len(self._running) < self.workers and not self._cancelled:
                self._start(*self._todo.popleft())
            try:
                yield self._events.get(timeout=0.05)
            except queue.Empty:
                pass
            self._reap()

    def cancel(self) -> None:
        self._cancelled = True
        self._todo.clear()
        for w in self._running:
            w.signal_group(signal.SIGTERM)
        deadline = time.monotonic() + TERM_GRACE_S
        for w in self._running:
            try:
                w.proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                w.signal_group(signal.SIGKILL)
                w.proc.wait()
        self._reap()


class LocalBackend(Backend):
    """``workers`` processes at a time; ``env`` for the workers (default: this process's)."""

    name = "local"

    def __init__(self, workers: int = 1, env: dict | None = None, cmd: WorkerCommand = worker_command):
        self.workers, self.cmd = workers, cmd
        self.env = dict(os.environ if env is None else env)
        self.env.setdefault("PYTHONUNBUFFERED", "1")

    def submit(self, job: Job) -> LocalRun:
        return LocalRun(job, self.workers, self.env, self.cmd)
