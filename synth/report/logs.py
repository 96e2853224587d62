"""Render times, failures and retries, from ``synth render``'s logs (``DIR/logs/<run>/``).

Each worker (or farm task) attempt writes ``batch_NNNNNN.ATTEMPT.log``: bpy's output and the
worker protocol's events (:mod:`renderer_jobs.events`), one per line: ``frame`` events carry
the time inside Cycles, ``error`` events a user-facing failure, and the remote backends add
the ``batch_end`` of each attempt (its exit status and whether it is retried). A batch with a
later attempt in the same run was retried, so its earlier attempts failed.
"""

from __future__ import annotations

import os
import re
from collections import defaultdict
from pathlib import Path

ATTEMPT_LOG = re.compile(r"^batch_(\d{6})\.(\d+)\.log$")
#: Error messages kept in the report (the last ones).
MAX_ERRORS = 20


def render_log_stats(log_dir: Path, committed: dict[str, str] | None = None) -> dict:
    """``{"runs", "attempts", "retried_batches", "failed_attempts", "errors": [{"log", "message"}],
    "unreadable_events", "frame_seconds": {key: s}, "shard_seconds": {shard: s}}``. Frame times
    are the last recorded for each key; with ``committed`` (key -> shard) only committed frames
    count, and shard totals add them up."""
    from renderer_jobs.events import BatchEnd, Error, EventError, Frame, parse_line

    out = {"runs": 0, "attempts": 0, "retried_batches": 0, "failed_attempts": 0, "errors": [],
           "unreadable_events": 0, "frame_seconds": {}, "shard_seconds": {}}
    if not Path(log_dir).is_dir():
        return out
    seconds: dict[str, float] = {}
    for run in sorted(os.listdir(log_dir)):
        rd = Path(log_dir) / run
        if not rd.is_dir():
            continue
        logs = sorted((int(m[1]), int(m[2]), rd / n) for n in os.listdir(rd) if (m := ATTEMPT_LOG.match(n)))
        if not logs:
            continue
        out["runs"] += 1
        last_attempt: dict[int, int] = defaultdict(int)
        for batch, attempt, _ in logs:
            last_attempt[batch] = max(last_attempt[batch], attempt)
        out["retried_batches"] += sum(1 for a in last_attempt.values() if a > 0)
        for batch, attempt, path in logs:
            out["attempts"] += 1
            failed = attempt < last_attempt[batch]
            with open(path, encoding="utf-8", errors="replace") as f:
                for line in f:
                    if '"event"' not in line:  # bpy's output (an event may follow text bpy left unended)
                        continue
                    try:
                        ev = parse_line(line)
                    except EventError:
                        out["unreadable_events"] += 1
                        continue
                    if isinstance(ev, Frame):
                        seconds[ev.key] = ev.render_seconds
                    elif isinstance(ev, Error):
                        failed = True
                        out["errors"].append({"log": f"{run}/{path.name}", "message": ev.message})
                    elif isinstance(ev, BatchEnd) and ev.returncode != 0:
                        failed = True
            out["failed_attempts"] += int(failed)
    out["errors"] = out["errors"][-MAX_ERRORS:]
    if committed is not None:
        seconds = {k: s for k, s in seconds.items() if k in committed}
        totals: dict[str, float] = defaultdict(float)
        for k, s in seconds.items():
            totals[committed[k]] += s
        out["shard_seconds"] = dict(sorted(totals.items()))
    out["frame_seconds"] = dict(sorted(seconds.items()))
    return out
