"""Plan or resume, then render what is missing with a backend.

``DIR/plan/`` holds the plan. :func:`prepare_plan` plans into it, or, when it exists,
re-plans into a temporary directory and refuses arguments that give another plan hash.
:func:`render_plan` opens (or resumes) the dataset, reads from its files which shards are
not committed yet, groups them into batches of ``shards_per_worker`` (one fresh worker
process each), runs them on a backend while tallying its events, and summarises from the
files again.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from renderer_jobs.backend import Backend, Batch, Job, Run
from renderer_jobs.events import BatchEnd, Error, Event, Frame, Rss
from synth.errors import SynthError


def prepare_plan(out: Path, identities: int, config: Path | None, sets: list[str], seed: int | None,
                 model: Path | None, start: int = 0) -> Path:
    """Plan into ``out/plan`` or verify that the plan there is the one these arguments give."""
    from synth.config import load_config
    from synth.dataset.shards import PLAN_DIR
    from synth.plan.io import load_plan
    from synth.plan.planner import run_plan

    cfg = load_config(config, sets)
    target = out / PLAN_DIR
    if out.exists() and not out.is_dir():
        raise SynthError("output path exists and is not a directory", str(out), "choose a directory for --out")
    out.mkdir(parents=True, exist_ok=True)
    if target.exists():
        existing = load_plan(target)
        tmp = out / f".plan-check-{os.getpid()}"
        shutil.rmtree(tmp, ignore_errors=True)
        try:
            header, _ = run_plan(cfg, identities, tmp, seed=seed, first_identity=start, model_path=model)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        if header["plan_hash"] != existing.plan_hash:
            raise SynthError(f"{out} already holds a render of a different plan (hash {existing.plan_hash[:16]}, "
                             f"these arguments give {header['plan_hash'][:16]})", str(target),
                             "rerun with the original arguments to resume, or use a new --out")
        return target
    run_plan(cfg, identities, target, seed=seed, first_identity=start, model_path=model)
    return target


def existing_plan(plan_dir: Path) -> Path:
    """An existing plan directory to render (``--plan``), checked and made absolute."""
    from synth.plan.io import load_plan

    load_plan(plan_dir)  # clear error if it is not a plan
    return plan_dir.resolve()


def make_batches(shard_ids: Sequence[str], shards_per_worker: int) -> tuple[Batch, ...]:
    """Consecutive groups of at most ``shards_per_worker`` shards, in the given order."""
    if shards_per_worker < 1:
        raise ValueError("shards_per_worker must be at least 1")
    ids = list(shard_ids)
    return tuple(Batch(i, tuple(ids[s:s + shards_per_worker]))
                 for i, s in enumerate(range(0, len(ids), shards_per_worker)))


@dataclass
class RunStats:
    """What the events of one run add up to (what is *done* is read from the dataset)."""
    frames_rendered: int = 0
    render_seconds: float = 0.0  # pure Cycles sampling time reported by workers
    worker_starts: int = 0  # worker processes that ran (one batch_end each)
    failures: list[str] = field(default_factory=list)
    peak_rss_mb: float = 0.0

    def add(self, ev: Event) -> None:
        if isinstance(ev, Frame):
            self.frames_rendered += 1
            self.render_seconds += ev.render_seconds
        elif isinstance(ev, Rss):
            self.peak_rss_mb = max(self.peak_rss_mb, ev.rss_mb)
        elif isinstance(ev, Error):
            self.failures.append(f"{ev.shard}: {ev.message}")
        elif isinstance(ev, BatchEnd):
            self.worker_starts += 1
            if ev.returncode != 0 and not ev.retry:
                self.failures.append(f"worker for {','.join(ev.shards)} exited with code {ev.returncode}:\n"
                                     f"{ev.log_tail}")


def tally(run: Run, frames_total: int, frames_done: int, show_progress: bool = True) -> RunStats:
    """Drive ``run`` to its end, adding up its events under a progress bar. On Ctrl-C the run
    is cancelled (workers stopped, staged frames kept) and KeyboardInterrupt re-raised."""
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    stats = RunStats()
    progress = Progress(TextColumn("[bold]rendering"), BarColumn(), MofNCompleteColumn(),
                        TextColumn("{task.fields[fps]:.2f} frames/s"), TimeElapsedColumn(), TextColumn("ETA"),
                        TimeRemainingColumn(), disable=not show_progress, transient=False)
    task = progress.add_task("frames", total=frames_total, completed=frames_done, fps=0.0)
    t_start = time.perf_counter()
    try:
        with progress:
            for ev in run.events():
                stats.add(ev)
                if isinstance(ev, Frame):
                    elapsed = time.perf_counter() - t_start
                    progress.update(task, advance=1, fps=stats.frames_rendered / max(elapsed, 1e-9))
    except KeyboardInterrupt:
        run.cancel()
        raise
    return stats


def raise_on_failures(stats: RunStats) -> None:
    """Print every failure to stderr and raise one SynthError naming the first."""
    if stats.failures:
        import sys

        for f in stats.failures:
            print(f, file=sys.stderr)
        first = stats.failures[0]
        raise SynthError(f"{len(stats.failures)} worker(s) failed; first: {first.splitlines()[0]}",
                         "render", "see the worker log above; rerun the same command to resume") from None


def staged_frames(ds, shard_ids: Iterable[str]) -> int:
    """Frames an interrupted run left staged (JSON written) in the given shards."""
    n = 0
    for s in shard_ids:
        d = ds.staging_dir(s)
        if d.is_dir():
            n += sum(1 for name in os.listdir(d) if name.endswith(".json") and name.startswith("id"))
    return n


def render_plan(out: Path, plan_dir: Path, backend: Backend, shards_per_worker: int, quiet: bool = False,
                retries: int = 0, log_dir: Path | None = None) -> dict:
    """Open (or resume) the dataset for ``plan_dir`` in ``out`` and render what is missing."""
    from synth.dataset.shards import open_dataset
    from synth.plan.io import load_plan

    plan = load_plan(plan_dir)
    ds = open_dataset(out, plan.plan_hash, plan.expected(),
                      meta={"plan_dir": os.path.relpath(plan_dir, out), "run_seed": plan.seed,
                            "render": plan.render_settings(), "model": plan.header["model"]})
    pending = ds.pending_shards()
    total = sum(len(v) for v in ds.expected.values())
    before = total - sum(len(ds.expected[s]) for s in pending) + staged_frames(ds, pending)
    job = Job(dataset=out, plan_dir=plan_dir, batches=make_batches(pending, shards_per_worker), retries=retries,
              log_dir=log_dir)
    t0 = time.perf_counter()
    stats = tally(backend.submit(job), total, before, show_progress=not quiet)
    wall = time.perf_counter() - t0
    raise_on_failures(stats)
    summary = ds.summary()
    return {"wall_seconds": wall, "render_seconds": stats.render_seconds, "frames_rendered": stats.frames_rendered,
            "frames_before": before, "worker_starts": stats.worker_starts, "peak_worker_rss_mb": stats.peak_rss_mb, **summary}
