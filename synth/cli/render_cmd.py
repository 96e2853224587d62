"""``synth render``: plan (or reuse the plan) and render it into a sharded dataset.

    synth render --identities N [--expressions E] [--views V] [--environments N] [--config F] [--preset P]
                 [--workers W] [--seed S] [--backend local|ray|slurm] --out DIR

``DIR/plan/`` holds the plan. A rerun of the same command re-plans into a temporary
directory, finds the same plan hash, and resumes: committed shards are skipped and frames
already staged by an interrupted run are kept. A different plan (other counts, seed,
config or model) for the same ``DIR`` is refused. ``--plan PLAN_DIR`` renders an existing
plan instead of planning.

This module parses arguments and prints; planning, resuming and running the workers live
in ``renderer_jobs`` (``submit``: plan-or-resume and the render loop; ``backends``: local
processes, Ray tasks or a Slurm job array; docs/farm.md). Before anything is planned or
written, the extras the run needs are checked (:mod:`synth.extras`): ``bpy`` where workers
run from this Python (local, or a Ray runtime started here; a Slurm job or a Ray cluster runs
them on its nodes), ``ray`` or ``submitit`` for those backends.
"""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Optional

import typer

from synth.errors import SynthError
from synth.extras import require
from synth.seeds import MAX_SEED


def _overrides(expressions, views, preset, workers_device, set_, environments=None):
    sets = list(set_)
    if environments is not None:
        sets.append(f"dataset.environments_per_expression={environments}")
    if expressions is not None:
        sets.append(f"dataset.expressions_per_identity={expressions}")
    if views is not None:
        sets.append(f"dataset.views_per_expression={views}")
    if preset is not None:
        sets.append(f'render.preset="{preset}"')
    if workers_device is not None:
        sets.append(f'render.device="{workers_device}"')
    return sets


def _interrupt(signum, frame):
    """SIGTERM (kill, systemd, a scheduler) stops a render as Ctrl-C does: workers stopped,
    staged frames kept, exit 130."""
    raise KeyboardInterrupt


def render_cmd(
    identities: Optional[int] = typer.Option(None, "--identities", "-n", min=1, help="Number of identities."),
    out: Path = typer.Option(..., "--out", "-o", help="Dataset directory (created, or resumed)."),
    expressions: Optional[int] = typer.Option(None, "--expressions", "-e", min=1,
                                              help="Expressions per identity (default: config)."),
    views: Optional[int] = typer.Option(None, "--views", "-v", min=1, help="Views per expression (default: config)."),
    environments: Optional[int] = typer.Option(None, "--environments", min=1, max=100,
                                               help="Lighting environments per expression (default: config, 1)."),
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="TOML configuration file."),
    preset: Optional[str] = typer.Option(None, "--preset", "-p", help="Render preset: ci, preview, production or production-max."),
    workers: Optional[int] = typer.Option(None, "--workers", "-w", min=1, max=256,
                                          help="Workers at a time (local: default one per GPU, else 1; ray without "
                                               "--ray-address: CPUs of the local runtime, default all)."),
    shards_per_worker: int = typer.Option(2, "--shards-per-worker", min=1,
                                          help="Recycle a worker process after this many shards."),
    seed: Optional[int] = typer.Option(None, "--seed", "-s", min=0, max=MAX_SEED,
                                       help="Run seed (overrides dataset.seed)."),
    device: Optional[str] = typer.Option(None, "--device", help="auto (OptiX, CUDA, else CPU), gpu or cpu."),
    set_: list[str] = typer.Option([], "--set", help="Override one config key: section.key=value (repeatable)."),
    model: Optional[Path] = typer.Option(None, "--model", "-m", help="Head model .npz (default: embedded)."),
    plan_dir: Optional[Path] = typer.Option(None, "--plan", help="Render this existing plan directory instead "
                                            "of planning (no other planning options allowed)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress output; print one summary line."),
    backend: str = typer.Option("local", "--backend", "-b", help="Where workers run: local, ray or slurm."),
    retries: int = typer.Option(2, "--retries", min=0, help="Runs again a batch whose worker crashed, this often."),
    no_wait: bool = typer.Option(False, "--no-wait", help="Exit 1 instead of waiting for shards that other live "
                                                          "processes are rendering."),
    log_json: Optional[Path] = typer.Option(None, "--log-json", help="Append JSON-line events (frame, commit, retry, "
                                                                     "failure) to this file."),
    progress_every: float = typer.Option(30.0, "--progress-every", min=0.1,
                                         help="Seconds between progress lines when stdout is not a terminal."),
    stall_timeout: float = typer.Option(300.0, "--stall-timeout", min=1.0,
                                        help="Stop and retry a worker silent this long (seconds)."),
    ray_address: Optional[str] = typer.Option(None, "--ray-address", help="Join this Ray cluster (host:port); "
                                                                          "default: start a local runtime."),
    slurm_partition: Optional[str] = typer.Option(None, "--slurm-partition", help="Slurm partition."),
    slurm_time: Optional[int] = typer.Option(None, "--slurm-time", min=1, help="Slurm time limit per task (minutes)."),
    cpus_per_task: int = typer.Option(1, "--cpus-per-task", min=1, help="CPUs per Ray or Slurm task."),
    gpus_per_task: int = typer.Option(0, "--gpus-per-task", min=0, help="GPUs per Slurm task."),
    array_parallelism: Optional[int] = typer.Option(None, "--array-parallelism", min=1,
                                                    help="Slurm array tasks running at once."),
) -> None:
    """Render a dataset: plan (or reuse the plan in DIR/plan), then render the missing shards
    on a backend until every shard is committed. Rerun the same command to resume after an
    interruption. Exit codes: 0 complete, 1 incomplete, 2 usage or input error, 3 a worker
    failed after its retries, 4 out of disk space, 130 interrupted."""
    from renderer_jobs.backends import NAMES, make_backend
    from renderer_jobs.progress import Progress, auto_mode
    from renderer_jobs.submit import existing_plan, prepare_plan, render_plan, run_log_dir

    if backend not in NAMES:
        raise SynthError(f"unknown backend {backend!r}", "--backend", f"use one of {', '.join(NAMES)}")
    if backend == "local" or (backend == "ray" and ray_address is None):  # workers run from this Python
        require("render", ("bpy",), "synth render")
    be = make_backend(backend, workers=workers, stall_timeout=stall_timeout, ray_address=ray_address,
                      partition=slurm_partition, time_min=slurm_time, cpus_per_task=cpus_per_task,
                      gpus_per_task=gpus_per_task, array_parallelism=array_parallelism)  # starts nothing
    previous = signal.getsignal(signal.SIGTERM)
    try:
        if plan_dir is not None:
            given = (identities, expressions, views, environments, config, preset, seed, model, device)
            if any(x is not None for x in given) or set_:
                raise SynthError("--plan renders an existing plan; planning options were given too", "--plan",
                                 "drop --identities/--expressions/--views/--environments/--config/--preset/--seed/"
                                 "--set/--model")
            pdir = existing_plan(plan_dir)
        else:
            if identities is None:
                raise SynthError("missing --identities", "synth render", "pass --identities N (or --plan PLAN_DIR)")
            sets = _overrides(expressions, views, preset, device, set_, environments)
            pdir = prepare_plan(out, identities, config, sets, seed, model)
        progress = Progress(0, 0, auto_mode(quiet), progress_every, log_json,
                            workers=be.workers if backend == "local" else None)
        signal.signal(signal.SIGTERM, _interrupt)  # not before: the planner's forked children keep the default
        res = render_plan(out, pdir, be, shards_per_worker, retries=retries, log_dir=run_log_dir(out, backend),
                          wait=not no_wait, progress=progress)
    except KeyboardInterrupt:
        typer.echo("interrupted: frames rendered so far are kept; rerun the same command to resume", err=True)
        raise typer.Exit(130) from None
    finally:
        signal.signal(signal.SIGTERM, previous)
    fps = res["frames_rendered"] / max(res["wall_seconds"], 1e-9)
    typer.echo(f"{out}: {res['frames_committed']}/{res['frames']} frames in {res['shards_committed']}/"
               f"{res['shards']} shards committed; rendered {res['frames_rendered']} now in "
               f"{res['wall_seconds']:.1f} s ({fps:.2f} frames/s, Cycles {res['render_seconds']:.1f} s, "
               f"{res['worker_starts']} worker process(es), peak worker RSS {res['peak_worker_rss_mb']:.0f} MB)")


def register(app: typer.Typer) -> None:
    app.command("render")(render_cmd)
