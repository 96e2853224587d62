"""Plan or resume, then render what is missing with a backend, until the dataset is complete.

``DIR/plan/`` holds the plan. :func:`prepare_plan` plans into it (atomically: several runs
started at once adopt the first one's identical plan), or, when it exists, recomputes the plan
hash in memory and refuses arguments that give another. :func:`render_plan` reports a
finished dataset without writing anything; otherwise it checks the whole plan (shard spec
hashes, model, HDR maps) before any worker starts, opens (or resumes) the dataset and loops, reading from its files each
time: the shards not committed yet that no live process holds are grouped into batches of
``shards_per_worker`` (one fresh worker process each) and run on a backend while its events
are tallied; shards that another live process holds (another ``synth render``, a worker of
a killed controller still exiting, another host) are waited for, or reported with
``wait=False``. It returns only when every shard is committed, and otherwise raises the
error whose exit code says why (docs/farm.md, "Exit codes").
"""

from __future__ import annotations

import os
import time
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from renderer_jobs.backend import Backend, Batch, Job, Run
from renderer_jobs.events import EXIT_DISK_FULL, EXIT_INPUT, BatchEnd, Error, Event, Frame, Rss
from renderer_jobs.failures import Failure, group, report_lines
from renderer_jobs.progress import Progress
from synth.errors import DiskFull, Incomplete, SynthError, WorkerFailed

#: How many times one invocation hands the same pending shard to a backend before it gives up
#: (a worker that ends without error but without committing it, e.g. it found it busy).
MAX_ROUNDS = 3


def prepare_plan(out: Path, identities: int, config: Path | None, sets: list[str], seed: int | None,
                 model: Path | None, start: int = 0) -> Path:
    """Plan into ``out/plan``, or verify that the plan there is the one these arguments give.

    Everything is checked before anything is written (the configuration, the counts, the
    referenced files, ``out`` itself), and a refused or failed plan leaves the file system as
    it was. An existing plan is verified without writing (the plan hash is recomputed in
    memory), so a finished dataset on read-only media still resumes to "complete". When
    several ``synth render`` start at once on one ``out``, each plans into a temporary
    directory and the first rename wins; the others adopt its plan when it is identical
    (:func:`synth.plan.io.write_plan`)."""
    from synth.config import load_config
    from synth.dataset.shards import PLAN_DIR, check_out_dir
    from synth.plan.io import check_hdri_files, load_plan
    from synth.plan.planner import run_plan

    cfg = load_config(config, sets)
    check_hdri_files({"environment": cfg.lighting.environment, "hdri_files": cfg.lighting.hdri_files})
    info = check_out_dir(out)
    target = out / PLAN_DIR
    if os.path.lexists(target) or info is not None:  # a plan or a dataset is there: the same one?
        there = load_plan(target).plan_hash if os.path.lexists(target) else info["plan_hash"]
        header, _ = run_plan(cfg, identities, None, seed=seed, first_identity=start, model_path=model)
        if header["plan_hash"] != there:
            raise SynthError(f"{out} already holds a render of a different plan (hash {there[:16]}, "
                             f"these arguments give {header['plan_hash'][:16]})", str(target),
                             "rerun with the original arguments to resume, or use a new --out")
        if os.path.lexists(target):
            return target
    run_plan(cfg, identities, target, seed=seed, first_identity=start, model_path=model)  # (re)write the plan
    return target


def existing_plan(plan_dir: Path) -> Path:
    """An existing plan directory to render (``--plan``), checked and made absolute."""
    from synth.plan.io import load_plan

    load_plan(plan_dir)  # clear error if it is not a plan
    return plan_dir.resolve()


def run_log_dir(out: Path, backend: str) -> Path:
    """``DIR/logs/<backend>-<UTC time>-<pid>/``: this invocation's worker (or task) logs."""
    from synth.dataset.layout import LOGS_DIR

    return Path(out) / LOGS_DIR / f"{backend}-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}-{os.getpid()}"


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
    failed_shards: set[str] = field(default_factory=set)
    input_errors: list[str] = field(default_factory=list)  # error events of batches that exited EXIT_INPUT
    disk_full: list[str] = field(default_factory=list)  # error events of batches that ran out of space
    peak_rss_mb: float = 0.0
    _errors: dict[str, str] = field(default_factory=dict)  # shards (joined) -> the error they reported
    _failed: list[tuple[tuple[str, ...], int, str]] = field(default_factory=list)  # shards, exit status, log tail

    def add(self, ev: Event) -> None:
        if isinstance(ev, Frame):
            self.frames_rendered += 1
            self.render_seconds += ev.render_seconds
        elif isinstance(ev, Rss):
            self.peak_rss_mb = max(self.peak_rss_mb, ev.rss_mb)
        elif isinstance(ev, Error):
            self.failures.append(f"{ev.shard}: {ev.message}")
            self._errors[ev.shard] = ev.message
        elif isinstance(ev, BatchEnd):
            self.worker_starts += 1
            if ev.returncode != 0 and not ev.retry:
                self.failures.append(f"worker for {','.join(ev.shards)} exited with code {ev.returncode}:\n"
                                     f"{ev.log_tail}")
                self.failed_shards.update(ev.shards)
                self._failed.append((tuple(ev.shards), ev.returncode, ev.log_tail))
                msg = self._errors.get(",".join(ev.shards))
                if ev.returncode == EXIT_DISK_FULL:
                    self.disk_full.append(msg or f"out of disk space (worker for {','.join(ev.shards)})")
                elif ev.returncode == EXIT_INPUT and msg:
                    self.input_errors.append(msg)


    def failure_records(self) -> list[Failure]:
        """Each failed batch with the error its worker reported (else its exit status and the
        last line of its log), then the errors of workers that otherwise ended well."""
        out, used = [], set()
        for shards, rc, tail in self._failed:
            key = ",".join(shards)
            msg = self._errors.get(key)
            if msg is None:
                last = next((t.strip() for t in reversed(tail.splitlines()) if t.strip()), "")
                msg = f"worker exited with code {rc}" + (f": {last}" if last else "")
            used.add(key)
            out.append(Failure(shards, msg, rc, tuple(tail.splitlines())))
        out += [Failure(tuple(k.split(",")), m) for k, m in self._errors.items() if k not in used]
        return out


def tally(run: Run, stats: RunStats, progress: Progress) -> None:
    """Drive ``run`` to its end, adding up its events and reporting progress. On Ctrl-C the run
    is cancelled (workers stopped, staged frames kept) and KeyboardInterrupt re-raised."""
    try:
        for ev in run.events():
            stats.add(ev)
            progress.event(ev)
    except KeyboardInterrupt:
        run.cancel()
        raise


def raise_on_failures(stats: RunStats, quiet: bool = False) -> None:
    """Raise the one-line error of the gravest kind: out of disk space (exit 4), a user-facing
    input error (2), a worker or task failure (3); before it, print each distinct failure once
    to stderr, and without ``quiet`` the ends of the failed workers' logs, no line twice
    (:mod:`renderer_jobs.failures`)."""
    if not stats.failures:
        return
    import sys

    if stats.disk_full:
        err: SynthError = DiskFull(stats.disk_full[0])
    elif stats.input_errors:
        err = SynthError(stats.input_errors[0])
    else:
        if stats.failed_shards:
            first = next(f for f in stats.failures if f.startswith("worker for "))
            what = f"{len(stats.failed_shards)} shard(s) failed after their retries; first: {first.splitlines()[0]}"
        else:  # e.g. an event of another protocol version from a worker that otherwise finished
            what = f"a worker reported an error: {stats.failures[0].splitlines()[0]}"
        err = WorkerFailed(what.rstrip(":"), "render",
                           "see the worker log above and in DIR/logs; rerun the same command to resume")
    for line in report_lines(group(stats.failure_records()), str(err), quiet):
        print(line, file=sys.stderr)
    raise err from None


def staged_frames(ds, shard_ids: Iterable[str]) -> int:
    """Frames an interrupted run left staged (JSON written) in the given shards."""
    n = 0
    for s in shard_ids:
        d = ds.staging_dir(s)
        if d.is_dir():
            n += sum(1 for name in os.listdir(d) if name.endswith(".json") and name.startswith("id"))
    return n


def _held_text(held: dict) -> str:
    items = sorted(held.items())
    text = ", ".join(f"{s} ({h.describe()})" for s, h in items[:3])
    return text + (f" and {len(items) - 3} more" if len(items) > 3 else "")


def finished(out: Path, plan) -> dict | None:
    """The dataset's summary when ``out`` holds this plan's dataset with every shard committed
    (read without writing anything), else ``None``."""
    from synth.dataset.layout import DATASET_FILE
    from synth.dataset.shards import load_dataset

    if not (Path(out) / DATASET_FILE).is_file():
        return None
    ds = load_dataset(out)
    if ds.plan_hash != plan.plan_hash:
        return None  # open_dataset refuses it with the full message
    summary = ds.summary()
    return summary if summary["shards_committed"] == summary["shards"] else None


def render_plan(out: Path, plan_dir: Path, backend: Backend, shards_per_worker: int, quiet: bool = False,
                retries: int = 0, log_dir: Path | None = None, wait: bool = True, progress: Progress | None = None,
                poll_s: float = 2.0) -> dict:
    """Open (or resume) the dataset for ``plan_dir`` in ``out`` and render until every shard is
    committed (see the module docstring). Raises :class:`Incomplete` (exit 1),
    :class:`WorkerFailed` (3), :class:`DiskFull` (4) or a :class:`SynthError` (2)."""
    from synth.dataset.shards import open_dataset
    from synth.plan.io import load_plan

    plan = load_plan(plan_dir)
    done = finished(out, plan)
    if done is not None:  # nothing to do: report it without writing (read-only media)
        backend.close()
        return {"wall_seconds": 0.0, "render_seconds": 0.0, "frames_rendered": 0, "frames_before": done["frames"],
                "worker_starts": 0, "peak_worker_rss_mb": 0.0, **done}
    plan.verify()  # the whole plan, before any worker starts (and before the dataset is created)
    ds = open_dataset(out, plan.plan_hash, plan.expected(), shard_format=plan.shard_format,
                      meta={"plan_dir": os.path.relpath(plan_dir, out), "run_seed": plan.seed,
                            "render": plan.render_settings(), "model": plan.header["model"]})
    pending = ds.pending_shards()
    total = sum(len(v) for v in ds.expected.values())
    before = total - sum(len(ds.expected[s]) for s in pending) + staged_frames(ds, pending)
    if progress is None:
        progress = Progress(total, before, mode="none" if quiet else "lines")
    progress.total, progress.done = total, before
    stats, rounds = RunStats(), Counter()
    t0 = time.perf_counter()
    with progress:
        try:
            _render_until_done(ds, out, plan_dir, backend, shards_per_worker, retries, log_dir, wait, progress,
                               poll_s, stats, rounds)
        finally:
            backend.close()
        wall = time.perf_counter() - t0
        summary = ds.summary()
        progress.record({"event": "summary", **summary, "frames_rendered": stats.frames_rendered,
                         "failures": len(stats.failed_shards)})
    raise_on_failures(stats, quiet=progress.mode == "none")
    if summary["shards_committed"] < summary["shards"]:
        left = ds.pending_shards()
        raise Incomplete(f"{len(left)} shard(s) not committed (first: {left[0]}) although no worker reported a failure",
                         str(out), "rerun the same command to resume; see the worker logs in DIR/logs")
    return {"wall_seconds": wall, "render_seconds": stats.render_seconds, "frames_rendered": stats.frames_rendered,
            "frames_before": before, "worker_starts": stats.worker_starts, "peak_worker_rss_mb": stats.peak_rss_mb,
            **summary}


def _render_until_done(ds, out, plan_dir, backend, shards_per_worker, retries, log_dir, wait, progress, poll_s,
                       stats: RunStats, rounds: Counter) -> None:
    """The loop of :func:`render_plan`: submit what nobody holds, wait for what others hold."""
    noted: set[str] = set()
    while True:
        pending = ds.pending_shards()
        held = ds.claims(pending)
        todo = [s for s in pending if s not in held and s not in stats.failed_shards and rounds[s] < MAX_ROUNDS]
        if todo:
            rounds.update(todo)
            job = Job(dataset=out, plan_dir=plan_dir, batches=make_batches(todo, shards_per_worker),
                      retries=retries, log_dir=log_dir)
            tally(backend.submit(job), stats, progress)
            continue
        if not held:
            return
        if not wait:
            raise Incomplete(f"{len(held)} shard(s) are being rendered by other processes: {_held_text(held)}",
                             str(out), "rerun when they are done (without --no-wait, synth render waits)")
        if set(held) != noted:
            noted = set(held)
            progress.note(f"synth render: waiting for {len(held)} shard(s) held by other processes: "
                          f"{_held_text(held)}")
            progress.record({"event": "waiting", "shards": sorted(held)})
        while set(ds.claims(held)) == set(held) and set(held) <= set(ds.pending_shards()):
            time.sleep(poll_s)
            progress.tick()
