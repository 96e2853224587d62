"""The backend interface: how a plan's pending shards get rendered somewhere.

A *batch* is a list of shard ids rendered, in order, by one fresh worker process
(``python -m blender_scripts.worker --dataset DIR --plan PLAN --shards a,b``); the process
exits after its batch, which keeps memory flat. A backend runs batches (local processes,
and later Ray tasks or Slurm array tasks) and streams the events of ``renderer_jobs.events``.

What a backend must not do is decide what is done. Completion is read from the dataset
(committed shards under ``DIR/shards/``, see :meth:`synth.dataset.shards.Dataset.pending_shards`)
by :mod:`renderer_jobs.submit` before and after a run, never from a process's memory, so a
run interrupted on one backend resumes on any other. A worker skips shards that are already
committed or claimed by another process, which makes retrying a batch always safe: a retry
keeps the frames its previous attempt staged.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from renderer_jobs.events import Event


@dataclass(frozen=True)
class Batch:
    """Shards for one worker process; ``index`` names it in events and log files."""
    index: int
    shards: tuple[str, ...]


@dataclass(frozen=True)
class Job:
    """Everything a backend needs to render a set of batches of one plan.

    - ``retries``: how many more times a batch is run whose worker failed (non-zero exit)
      without reporting an ``error`` event (a user-facing error that a retry would repeat);
    - ``log_dir``: where each attempt's worker log goes (:meth:`log_path`); ``None`` keeps
      only the last lines, in the ``batch_end`` event.
    """
    dataset: Path
    plan_dir: Path
    batches: tuple[Batch, ...]
    retries: int = 0
    log_dir: Path | None = None

    def log_path(self, batch: Batch, attempt: int) -> Path | None:
        if self.log_dir is None:
            return None
        return self.log_dir / f"batch_{batch.index:06d}.{attempt}.log"


class Run(ABC):
    """A submitted job. Iterate :meth:`events` to drive it to its end."""

    @abstractmethod
    def events(self) -> Iterator[Event]:
        """Worker events as they arrive, and one ``BatchEnd`` per worker process that ended
        (after that process's own events). Ends when every batch has ended, after its retries."""

    @abstractmethod
    def cancel(self) -> None:
        """Stop every running worker (they keep the frames already staged) and start no more.
        Returns when they have stopped."""

    def wait(self) -> list[Event]:
        """Run to the end and return all events."""
        return list(self.events())


class Backend(ABC):
    """Where workers run. Configuration (worker count, cluster address, ...) goes to the
    constructor; :meth:`submit` starts a job and returns its :class:`Run`."""

    name: str = ""

    @abstractmethod
    def submit(self, job: Job) -> Run:
        ...

    def close(self) -> None:
        """Release what the backend set up for its runs (a local Ray runtime); called once,
        after the last run."""
