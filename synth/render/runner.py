"""Local execution: W worker processes, each a fresh Python+bpy process that renders a few
shards and exits (recycling keeps memory flat), fed from a queue of uncommitted shards.

Workers report progress as JSON lines on stdout (see blender_scripts/worker.py). Ctrl-C stops
the workers; frames already written to staging survive and the next run resumes.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

from synth.errors import SynthError


@dataclass
class RunStats:
    frames_total: int
    frames_done_before: int
    frames_rendered: int = 0
    shards_committed: int = 0
    render_seconds: float = 0.0  # pure Cycles sampling time reported by workers
    worker_starts: int = 0
    failures: list[str] = field(default_factory=list)
    peak_rss_mb: float = 0.0


def _worker_cmd(dataset: Path, plan_dir: Path, shards: list[str]) -> list[str]:
    return [sys.executable, "-m", "blender_scripts.worker", "--dataset", str(dataset), "--plan", str(plan_dir),
            "--shards", ",".join(shards)]


def run_workers(dataset: Path, plan_dir: Path, shard_ids: list[str], frames_total: int, frames_done: int,
                workers: int = 1, shards_per_worker: int = 2, show_progress: bool = True,
                env: dict | None = None) -> RunStats:
    """Render ``shard_ids`` (uncommitted ones) with ``workers`` processes."""
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    stats = RunStats(frames_total=frames_total, frames_done_before=frames_done)
    queue: deque[str] = deque(shard_ids)
    running: dict[subprocess.Popen, list[str]] = {}
    lock = threading.Lock()
    t_start = time.perf_counter()
    progress = Progress(TextColumn("[bold]rendering"), BarColumn(), MofNCompleteColumn(),
                        TextColumn("{task.fields[fps]:.2f} frames/s"), TimeElapsedColumn(), TextColumn("ETA"),
                        TimeRemainingColumn(), disable=not show_progress, transient=False)
    task = progress.add_task("frames", total=frames_total, completed=frames_done, fps=0.0)
    worker_env = dict(os.environ if env is None else env)
    worker_env.setdefault("PYTHONUNBUFFERED", "1")

    def reader(proc: subprocess.Popen) -> None:
        for line in proc.stdout:  # type: ignore[union-attr]
            line = line.strip()
            if not line.startswith("{"):
                continue
            try:
                ev = json.loads(line)
            except json.JSONDecodeError:
                continue
            with lock:
                if ev.get("event") == "frame":
                    stats.frames_rendered += 1
                    stats.render_seconds += float(ev.get("render_seconds", 0.0))
                    elapsed = time.perf_counter() - t_start
                    progress.update(task, advance=1, fps=stats.frames_rendered / max(elapsed, 1e-9))
                elif ev.get("event") == "commit":
                    stats.shards_committed += 1
                elif ev.get("event") == "rss":
                    stats.peak_rss_mb = max(stats.peak_rss_mb, float(ev.get("rss_mb", 0.0)))
                elif ev.get("event") == "error":
                    stats.failures.append(f"{ev.get('shard')}: {ev.get('message')}")

    def start_one() -> None:
        batch = [queue.popleft() for _ in range(min(shards_per_worker, len(queue)))]
        proc = subprocess.Popen(_worker_cmd(dataset, plan_dir, batch), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, env=worker_env, start_new_session=True)
        threading.Thread(target=reader, args=(proc,), daemon=True).start()
        proc._stderr_tail = deque(maxlen=40)  # type: ignore[attr-defined]

        def err_reader() -> None:
            for line in proc.stderr:  # type: ignore[union-attr]
                proc._stderr_tail.append(line.rstrip())  # type: ignore[attr-defined]

        threading.Thread(target=err_reader, daemon=True).start()
        running[proc] = batch
        stats.worker_starts += 1

    interrupted = False
    with progress:
        try:
            while queue or running:
                while queue and len(running) < max(1, workers):
                    start_one()
                time.sleep(0.05)
                for proc in list(running):
                    rc = proc.poll()
                    if rc is None:
                        continue
                    batch = running.pop(proc)
                    if rc != 0:
                        time.sleep(0.1)
                        tail = "\n".join(list(proc._stderr_tail)[-15:])  # type: ignore[attr-defined]
                        stats.failures.append(f"worker for {','.join(batch)} exited with code {rc}:\n{tail}")
        except KeyboardInterrupt:
            interrupted = True
            for proc in running:
                try:
                    os.killpg(proc.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
            deadline = time.time() + 10
            for proc in running:
                try:
                    proc.wait(timeout=max(0.1, deadline - time.time()))
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
    if interrupted:
        raise KeyboardInterrupt
    return stats


def raise_on_failures(stats: RunStats) -> None:
    if stats.failures:
        import sys

        for f in stats.failures:
            print(f, file=sys.stderr)
        first = stats.failures[0]
        raise SynthError(f"{len(stats.failures)} worker(s) failed; first: {first.splitlines()[0]}",
                         "render", "see the worker log above; rerun the same command to resume") from None
