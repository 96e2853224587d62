"""Start one render worker process and follow it: the part every backend shares.

:class:`WorkerProcess` starts ``python -m blender_scripts.worker`` in its own process group,
with ``SYNTH_PARENT_PID`` set so the worker dies with whoever started it
(:mod:`renderer_jobs.guard`), parses its stdout into events, writes every line of stdout and
stderr to its log file, keeps the last stderr lines, and notes when it last said anything
(the watchdog's clock). The local backend runs several at once on this machine; a Ray task or
a Slurm array task runs one batch with :func:`run_batch`, which also writes the batch's
``batch_end`` event into the log, where the controller reads it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO

from renderer_jobs.events import BatchEnd, Error, Event, EventError, encode, parse_line, should_retry
from renderer_jobs.guard import PARENT_ENV

#: Lines of a worker's stderr kept for the ``batch_end`` event.
TAIL_LINES = 15
#: Seconds between SIGTERM and SIGKILL when a worker is stopped.
TERM_GRACE_S = 10.0
#: Default watchdog: a worker silent for this long (it sends a heartbeat every <= 10 s, also
#: mid-render) has stopped answering and is killed; its batch is retried.
STALL_TIMEOUT_S = 300.0

WorkerCommand = Callable[[Path, Path, Sequence[str]], list[str]]


def worker_command(dataset: Path, plan_dir: Path, shards: Sequence[str]) -> list[str]:
    """The command line of one render worker."""
    return [sys.executable, "-m", "blender_scripts.worker", "--dataset", str(dataset), "--plan", str(plan_dir),
            "--shards", ",".join(shards)]


def worker_env(base: dict | None = None, **extra: str) -> dict:
    """The environment of a worker started by this process: unbuffered output, this
    process's PID as the parent to die with, this checkout on the import path."""
    env = dict(os.environ if base is None else base)
    root = str(Path(__file__).resolve().parents[1])
    paths = [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in paths if p != root])
    env["PYTHONUNBUFFERED"] = "1"
    env[PARENT_ENV] = str(os.getpid())
    env.update(extra)
    return env


class WorkerProcess:
    """One running worker and the threads reading its output."""

    def __init__(self, cmd: list[str], env: dict, shards: Sequence[str], log_path: Path | None = None,
                 on_event: Callable[[Event], None] | None = None):
        self.shards = tuple(shards)
        self.tail: deque[str] = deque(maxlen=40)
        self.reported_error = False
        self.stalled = False
        self.last_activity = time.monotonic()
        self._on_event = on_event
        self._log: IO[str] | None = None
        self._log_lock = threading.Lock()
        if log_path is not None:
            log_path.parent.mkdir(parents=True, exist_ok=True)
            self._log = open(log_path, "a", encoding="utf-8")
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     errors="replace", env=env, start_new_session=True)
        self._threads = [threading.Thread(target=self._read_stdout, daemon=True),
                         threading.Thread(target=self._read_stderr, daemon=True)]
        for t in self._threads:
            t.start()

    def logline(self, line: str) -> None:
        """Append to the log; a log that cannot be written (disk full) is given up, never the
        worker's events."""
        with self._log_lock:
            if self._log is None:
                return
            try:
                self._log.write(line if line.endswith("\n") else line + "\n")
                self._log.flush()
            except OSError as e:
                self.tail.append(f"(worker log abandoned: {e.strerror})")
                try:
                    self._log.close()
                except OSError:
                    pass
                self._log = None

    def _read_stdout(self) -> None:
        for line in self.proc.stdout:  # type: ignore[union-attr]
            self.last_activity = time.monotonic()
            self.logline(line)
            try:
                ev = parse_line(line)
            except EventError as e:
                ev = Error(shard=",".join(self.shards), message=f"unreadable worker event: {e}")
            if ev is None:
                continue
            if isinstance(ev, Error):
                self.reported_error = True
            if self._on_event is not None:
                self._on_event(ev)

    def _read_stderr(self) -> None:
        for line in self.proc.stderr:  # type: ignore[union-attr]
            self.last_activity = time.monotonic()
            self.logline(line)
            self.tail.append(line.rstrip())

    def silent_for(self) -> float:
        return time.monotonic() - self.last_activity

    def signal_group(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            pass

    def stop(self, grace: float = TERM_GRACE_S) -> int:
        """SIGTERM the worker's group, SIGKILL after ``grace`` seconds; returns its status."""
        self.signal_group(signal.SIGTERM)
        try:
            return self.proc.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            self.signal_group(signal.SIGKILL)
            return self.proc.wait()

    def stop_stalled(self, timeout: float) -> bool:
        """The watchdog: stop the worker if it said nothing for ``timeout`` seconds."""
        if self.proc.poll() is not None or self.silent_for() <= timeout:
            return False
        self.stalled = True
        self.tail.append(f"watchdog: no output from the worker for {timeout:.0f} s; stopped it")
        self.logline(self.tail[-1])
        self.stop()
        return True

    def finish(self) -> None:
        """After the process ended: let the readers reach the end of its output."""
        for t in self._threads:
            t.join(timeout=5.0)
        with self._log_lock:
            if self._log is not None:
                try:
                    self._log.close()
                except OSError:
                    pass
                self._log = None

    def batch_end(self, batch: int, attempt: int, retries: int, cancelled: bool = False) -> BatchEnd:
        """The ``batch_end`` event of this (ended) process: retried when it crashed or stalled,
        attempts remain and the run was not cancelled."""
        rc = self.proc.returncode
        retry = ((self.stalled or should_retry(rc, self.reported_error)) and not cancelled and attempt < retries)
        return BatchEnd(batch=batch, shards=self.shards, attempt=attempt, returncode=rc,
                        log_tail="\n".join(list(self.tail)[-TAIL_LINES:]), retry=retry)


def attempt_log(log_dir: Path, batch: int) -> tuple[int, Path]:
    """The next attempt number of ``batch`` and its new, empty log file (created exclusively,
    so two attempts never share one, also on shared storage)."""
    log_dir.mkdir(parents=True, exist_ok=True)
    n = 0
    while True:
        p = log_dir / f"batch_{batch:06d}.{n}.log"
        try:
            with open(p, "x", encoding="utf-8"):
                return n, p
        except FileExistsError:
            n += 1


def run_batch(dataset: Path, plan_dir: Path, shards: Sequence[str], batch: int, log_dir: Path, retries: int,
              env: dict | None = None, stall_timeout: float = STALL_TIMEOUT_S,
              cmd: WorkerCommand = worker_command) -> BatchEnd:
    """Run one attempt of a batch to its end (the body of a Ray or Slurm task): its log goes
    to ``log_dir/batch_NNNNNN.ATTEMPT.log`` and ends with the ``batch_end`` event."""
    attempt, log_path = attempt_log(log_dir, batch)
    w = WorkerProcess(cmd(dataset, plan_dir, shards), worker_env(env), shards, log_path)
    try:
        while w.proc.poll() is None:
            time.sleep(0.5)
            w.stop_stalled(stall_timeout)
    except BaseException:  # the task itself is being stopped: take the worker down with it
        w.stop()
        raise
    finally:
        w.proc.wait()
        w.finish()
    end = w.batch_end(batch, attempt, retries)
    with open(log_path, "a", encoding="utf-8") as f:
        f.write(encode(end) + "\n")
    return end
