"""How a run reports progress: a live bar on a terminal, plain lines in a farm log, JSON lines
for monitoring.

- On a terminal, a progress bar (frames, frames/s, elapsed, ETA).
- When stdout is not a terminal (a pipe, a batch system's log file), one plain line every
  ``every`` seconds, flushed at once, so the log is never empty for hours::

      synth render: 1200/585000 frames (0.2%), 0.54 frames/s, ETA 12d 07h, 0 failures, 2 workers

- ``json_log``: every worker event that matters to monitoring (start, frame, skip, commit,
  error, batch end with its retry flag, waiting for shards held elsewhere, the summary) as one
  JSON object per line with a ``time`` field (ISO 8601, UTC), appended and flushed per line.

Time here is wall-clock time for people and monitors; it never enters the dataset.
"""

from __future__ import annotations

import datetime as _dt
import json
import sys
import time
from pathlib import Path
from typing import IO

from renderer_jobs.events import BatchEnd, Commit, Error, Event, Frame, Skip, Start, encode

#: Events copied to the JSON log (heartbeats and memory reports are left out).
_LOGGED = (Start, Frame, Skip, Commit, Error, BatchEnd)


def eta_text(seconds: float) -> str:
    if seconds != seconds or seconds == float("inf"):
        return "?"
    s = int(round(seconds))
    d, s = divmod(s, 86400)
    h, s = divmod(s, 3600)
    m, s = divmod(s, 60)
    if d:
        return f"{d}d {h:02d}h"
    if h:
        return f"{h}h {m:02d}m"
    return f"{m}m {s:02d}s"


class Progress:
    """Progress of one ``synth render``: ``mode`` is "bar", "lines" or "none" (see the module
    docstring); :func:`auto_mode` picks bar or lines from the output stream."""

    def __init__(self, total: int, done: int, mode: str = "lines", every: float = 30.0,
                 json_log: Path | None = None, out: IO[str] | None = None, workers: int | None = None):
        self.total, self.done, self.mode, self.every, self.workers = total, done, mode, every, workers
        self.out = sys.stdout if out is None else out
        self.rendered = 0
        self.failures = 0
        self._t0 = time.monotonic()
        self._last_line = self._t0
        self._bar = self._task = None
        self._json: IO[str] | None = None
        if json_log is not None:
            json_log.parent.mkdir(parents=True, exist_ok=True)
            self._json = open(json_log, "a", encoding="utf-8")

    # -- lifecycle -----------------------------------------------------------------------------
    def __enter__(self) -> Progress:
        if self.mode == "bar":
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress as Bar, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)

            self._bar = Bar(TextColumn("[bold]rendering"), BarColumn(), MofNCompleteColumn(),
                            TextColumn("{task.fields[fps]:.2f} frames/s"), TimeElapsedColumn(), TextColumn("ETA"),
                            TimeRemainingColumn(), transient=False)
            self._task = self._bar.add_task("frames", total=self.total, completed=self.done, fps=0.0)
            self._bar.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)
            self._bar = None
        elif self.mode == "lines" and self.rendered:
            self._line()
        if self._json is not None:
            self._json.close()
            self._json = None

    # -- input ----------------------------------------------------------------------------------
    def event(self, ev: Event) -> None:
        if isinstance(ev, Frame):
            self.rendered += 1
            self.done += 1
            if self._bar is not None:
                self._bar.update(self._task, advance=1, fps=self.fps())
        elif isinstance(ev, BatchEnd) and ev.returncode != 0 and not ev.retry:
            self.failures += 1
        if isinstance(ev, _LOGGED):
            self.record(json.loads(encode(ev)))
        self.tick()

    def record(self, obj: dict) -> None:
        """One JSON line in the log (no-op without one)."""
        if self._json is not None:
            stamp = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")
            try:
                self._json.write(json.dumps({"time": stamp, **obj}) + "\n")
                self._json.flush()
            except OSError as e:  # e.g. its disk is full: the render goes on without it
                print(f"synth render: --log-json abandoned ({e.strerror})", file=sys.stderr, flush=True)
                self._json = None

    def tick(self) -> None:
        """Print the plain line when ``every`` seconds have passed since the last one."""
        now = time.monotonic()
        if self.mode == "lines" and now - self._last_line >= self.every:
            self._line()

    def note(self, text: str) -> None:
        """A line of its own (e.g. waiting for shards held elsewhere), whatever the mode but none."""
        if self.mode == "none":
            return
        if self._bar is not None:
            self._bar.console.print(text)
        else:
            print(text, file=self.out, flush=True)

    # -- output ---------------------------------------------------------------------------------
    def fps(self) -> float:
        return self.rendered / max(time.monotonic() - self._t0, 1e-9)

    def line(self) -> str:
        fps = self.fps()
        left = self.total - self.done
        eta = eta_text(left / fps) if fps > 0 else "?"
        pct = 100.0 * self.done / max(self.total, 1)
        text = (f"synth render: {self.done}/{self.total} frames ({pct:.1f}%), {fps:.2f} frames/s, ETA {eta}, "
                f"{self.failures} failure{'s' if self.failures != 1 else ''}")
        if self.workers is not None:
            text += f", {self.workers} worker{'s' if self.workers != 1 else ''}"
        return text

    def _line(self) -> None:
        self._last_line = time.monotonic()
        print(self.line(), file=self.out, flush=True)


def auto_mode(quiet: bool, stream: IO[str] | None = None) -> str:
    """"none" when quiet, "bar" on a terminal, else "lines"."""
    if quiet:
        return "none"
    s = sys.stdout if stream is None else stream
    return "bar" if s.isatty() else "lines"
