"""What the Ray and Slurm backends share: batches run as tasks somewhere else, each attempt
writing its log under ``Job.log_dir`` (:func:`renderer_jobs.spawn.run_batch`), and the
controller following those logs for events.

A remote task cannot hand its worker's stdout to the controller, but both see the dataset
directory, so the log doubles as the event stream: :class:`LogFollower` reads the new whole
lines of every ``batch_NNNNNN.ATTEMPT.log``, and :class:`RemoteRun` turns them into the
events of :class:`renderer_jobs.backend.Run`, ending a batch on its final ``batch_end``. A
task that ended without writing one (its process was killed, it was cancelled before it
started) gets a ``batch_end`` made up by the controller once the scheduler says it ended
and a grace time for shared storage to show the log's last lines has passed.
"""

from __future__ import annotations

import re
import time
from abc import abstractmethod
from collections.abc import Iterator
from pathlib import Path

from renderer_jobs.backend import Job, Run
from renderer_jobs.events import BatchEnd, Error, Event, EventError, parse_line

_LOG_RE = re.compile(r"^batch_(\d{6})\.(\d+)\.log$")
#: Seconds to wait, after the scheduler says a task ended, for its log's last lines.
END_GRACE_S = 15.0


class LogFollower:
    """New events in the attempt logs of a directory, in the order of their lines."""

    def __init__(self, log_dir: Path):
        self.dir = log_dir
        self._pos: dict[Path, int] = {}
        self.attempts: dict[int, int] = {}  # batch -> highest attempt seen
        self.ended: dict[tuple[int, int], BatchEnd] = {}  # (batch, attempt) -> its batch_end
        self.tails: dict[tuple[int, int], list[str]] = {}

    def poll(self) -> list[tuple[int, int, Event]]:
        """(batch, attempt, event) for every event written since the last call."""
        out: list[tuple[int, int, Event]] = []
        try:
            names = sorted(p.name for p in self.dir.iterdir())
        except FileNotFoundError:
            return out
        for name in names:
            m = _LOG_RE.match(name)
            if not m:
                continue
            batch, attempt = int(m[1]), int(m[2])
            self.attempts[batch] = max(self.attempts.get(batch, -1), attempt)
            path = self.dir / name
            pos = self._pos.get(path, 0)
            try:
                with open(path, "rb") as f:
                    f.seek(pos)
                    data = f.read()
            except FileNotFoundError:
                continue
            end = data.rfind(b"\n")
            if end < 0:
                continue
            self._pos[path] = pos + end + 1
            for raw in data[:end].decode("utf-8", "replace").split("\n"):
                tail = self.tails.setdefault((batch, attempt), [])
                tail.append(raw)
                del tail[:-40]
                try:
                    ev = parse_line(raw)
                except EventError as e:
                    ev = Error(shard=f"batch {batch}", message=f"unreadable worker event: {e}")
                if ev is None:
                    continue
                if isinstance(ev, BatchEnd):
                    self.ended[(batch, attempt)] = ev
                out.append((batch, attempt, ev))
        return out


class RemoteRun(Run):
    """A run whose batches are tasks of a scheduler. Subclasses say which tasks ended
    (:meth:`_ended_tasks`) and how to cancel them (:meth:`_cancel_tasks`)."""

    poll_s = 0.5

    def __init__(self, job: Job):
        if job.log_dir is None:
            raise ValueError("a remote backend needs Job.log_dir (its tasks' logs carry the events)")
        self.job = job
        self.follow = LogFollower(job.log_dir)
        self._done: set[int] = set()
        self._task_end: dict[int, tuple[float, str]] = {}  # batch -> (when seen ended, why)
        self._shards = {b.index: b.shards for b in job.batches}
        self.cancelled = False

    @abstractmethod
    def _ended_tasks(self) -> dict[int, str]:
        """Batches whose task ended since the last call -> a word on how (for a made-up batch_end)."""

    @abstractmethod
    def _cancel_tasks(self) -> None:
        ...

    def _made_up_end(self, batch: int, attempt: int, why: str, retry: bool) -> BatchEnd:
        tail = "\n".join(self.follow.tails.get((batch, attempt), [])[-12:])
        return BatchEnd(batch=batch, shards=self._shards[batch], attempt=max(attempt, 0), returncode=-1,
                        log_tail=f"{why}\n{tail}".strip(), retry=retry)

    def events(self) -> Iterator[Event]:
        while len(self._done) < len(self.job.batches):
            got = self.follow.poll()
            for batch, attempt, ev in got:
                for older in range(attempt):  # a retry started: an attempt that died silently ended
                    if (batch, older) not in self.follow.ended:
                        end = self._made_up_end(batch, older, "the task's process died", retry=True)
                        self.follow.ended[(batch, older)] = end
                        yield end
                if isinstance(ev, BatchEnd) and not ev.retry:
                    self._done.add(batch)
                yield ev
            now = time.monotonic()
            for batch, why in self._ended_tasks().items():
                self._task_end.setdefault(batch, (now, why))
            for batch, (t, why) in list(self._task_end.items()):
                if batch in self._done or now - t < (0.0 if self.cancelled else END_GRACE_S):
                    continue  # (the log's last lines may still be on their way)
                attempt = self.follow.attempts.get(batch, 0)
                self._done.add(batch)
                yield self._made_up_end(batch, attempt, f"task ended ({why}) without reporting its end", False)
            if not got:
                time.sleep(self.poll_s)

    def cancel(self) -> None:
        self.cancelled = True
        self._cancel_tasks()
