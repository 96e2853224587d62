"""The local backend: W worker processes on this machine, one fresh process per batch.

Each worker is ``python -m blender_scripts.worker`` in its own process group
(:class:`renderer_jobs.spawn.WorkerProcess`); its stdout is parsed into events and all of its
output goes to ``Job.log_dir`` when one is given. With GPUs, there is one worker slot per GPU
by default and each worker sees only its slot's GPU (``CUDA_VISIBLE_DEVICES``,
:mod:`renderer_jobs.gpus`).

A worker dies with this process (parent-death signal, :mod:`renderer_jobs.guard`), so killing
the controller, even with SIGKILL, never leaves a worker holding a shard. A watchdog stops a
worker that said nothing (not even its heartbeat) for ``stall_timeout`` seconds and retries
its batch. :meth:`LocalRun.cancel` (Ctrl-C) sends SIGTERM to every worker's group, waits up to
10 s, then SIGKILLs; frames already staged survive and the next run resumes.
"""

from __future__ import annotations

import os
import queue
import signal
import time
from collections import deque
from collections.abc import Iterator

from renderer_jobs.backend import Backend, Batch, Job, Run
from renderer_jobs.events import Event
from renderer_jobs.gpus import visible_gpus, worker_slots
from renderer_jobs.spawn import (STALL_TIMEOUT_S, TERM_GRACE_S, WorkerCommand, WorkerProcess, worker_command,
                                 worker_env)


class LocalRun(Run):
    def __init__(self, job: Job, slots: list[str | None], env: dict, cmd: WorkerCommand, stall_timeout: float):
        self.job, self.slots, self.env, self.cmd, self.stall_timeout = job, slots, env, cmd, stall_timeout
        self._todo: deque[tuple[Batch, int]] = deque((b, 0) for b in job.batches)
        self._running: dict[int, tuple[WorkerProcess, Batch, int]] = {}
        self._events: queue.Queue = queue.Queue()
        self._cancelled = False

    def _start(self, batch: Batch, attempt: int, slot: int) -> None:
        device = self.slots[slot]
        env = worker_env(self.env, **({"CUDA_VISIBLE_DEVICES": device} if device is not None else {}))
        w = WorkerProcess(self.cmd(self.job.dataset, self.job.plan_dir, batch.shards), env, batch.shards,
                          self.job.log_path(batch, attempt), on_event=self._events.put)
        self._running[slot] = (w, batch, attempt)

    def _reap(self) -> None:
        for slot, (w, batch, attempt) in list(self._running.items()):
            if w.proc.poll() is None:
                w.stop_stalled(self.stall_timeout)
                continue
            del self._running[slot]
            w.finish()
            end = w.batch_end(batch.index, attempt, self.job.retries, cancelled=self._cancelled)
            self._events.put(end)
            if end.retry:
                self._todo.append((batch, attempt + 1))

    def events(self) -> Iterator[Event]:
        while self._todo or self._running or not self._events.empty():
            free = [s for s in range(len(self.slots)) if s not in self._running]
            while self._todo and free and not self._cancelled:
                self._start(*self._todo.popleft(), free.pop(0))
            try:
                yield self._events.get(timeout=0.05)
            except queue.Empty:
                pass
            self._reap()

    def cancel(self) -> None:
        self._cancelled = True
        self._todo.clear()
        for w, _, _ in self._running.values():
            w.signal_group(signal.SIGTERM)
        deadline = time.monotonic() + TERM_GRACE_S
        for w, _, _ in self._running.values():
            if w.proc.poll() is None:
                w.stop(grace=max(0.1, deadline - time.monotonic()))
        self._reap()


class LocalBackend(Backend):
    """Workers on this machine: ``workers`` at a time (default: one per GPU, else 1), pinned
    to the GPUs round-robin; ``env`` for the workers (default: this process's);
    ``gpus`` overrides detection (tests)."""

    name = "local"

    def __init__(self, workers: int | None = None, env: dict | None = None, cmd: WorkerCommand = worker_command,
                 stall_timeout: float = STALL_TIMEOUT_S, gpus: list[str] | None = None):
        self.env = dict(os.environ if env is None else env)
        self.cmd, self.stall_timeout = cmd, stall_timeout
        self.slots = worker_slots(workers, visible_gpus(self.env) if gpus is None else gpus)
        self.workers = len(self.slots)

    def submit(self, job: Job) -> LocalRun:
        return LocalRun(job, self.slots, self.env, self.cmd, self.stall_timeout)
