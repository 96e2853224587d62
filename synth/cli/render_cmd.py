"""``synth render``: plan (or reuse the plan) and render it into a sharded dataset.

    synth render --identities N [--expressions E] [--views V] [--config F] [--preset P]
                 [--workers W] [--seed S] --out DIR

``DIR/plan/`` holds the plan. A rerun of the same command re-plans into a temporary
directory, finds the same plan hash, and resumes: committed shards are skipped and frames
already staged by an interrupted run are kept. A different plan (other counts, seed,
config or model) for the same ``DIR`` is refused. ``--plan PLAN_DIR`` renders an existing
plan instead of planning.
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path
from typing import Optional

import typer

from synth.errors import SynthError

PLAN_SUBDIR = "plan"


def _overrides(expressions, views, preset, workers_device, set_):
    sets = list(set_)
    if expressions is not None:
        sets.append(f"dataset.expressions_per_identity={expressions}")
    if views is not None:
        sets.append(f"dataset.views_per_expression={views}")
    if preset is not None:
        sets.append(f'render.preset="{preset}"')
    if workers_device is not None:
        sets.append(f'render.device="{workers_device}"')
    return sets


def prepare_plan(out: Path, identities: int, config: Optional[Path], sets: list[str], seed: Optional[int],
                 model: Optional[Path], start: int = 0) -> Path:
    """Plan into ``out/plan`` or verify that the plan there is the one these arguments give."""
    from synth.config import load_config
    from synth.plan.io import load_plan
    from synth.plan.planner import run_plan

    cfg = load_config(config, sets)
    target = out / PLAN_SUBDIR
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


def render_plan(out: Path, plan_dir: Path, workers: int, shards_per_worker: int, quiet: bool = False) -> dict:
    """Open (or resume) the dataset for ``plan_dir`` in ``out`` and render what is missing."""
    from synth.plan.io import load_plan
    from synth.render.runner import raise_on_failures, run_workers
    from synth.dataset.shards import open_dataset

    plan = load_plan(plan_dir)
    ds = open_dataset(out, plan.plan_hash, plan.expected(),
                      meta={"plan_dir": os.path.relpath(plan_dir, out), "run_seed": plan.seed,
                            "render": plan.render_settings(), "model": plan.header["model"]})
    pending = ds.pending_shards()
    total = sum(len(v) for v in ds.expected.values())
    committed = total - sum(len(ds.expected[s]) for s in pending)
    staged = 0
    for s in pending:
        d = ds.staging_dir(s)
        if d.is_dir():
            staged += sum(1 for n in os.listdir(d) if n.endswith(".json") and n.startswith("id"))
    t0 = time.perf_counter()
    stats = run_workers(out, plan_dir, pending, total, committed + staged, workers=workers,
                        shards_per_worker=shards_per_worker, show_progress=not quiet)
    wall = time.perf_counter() - t0
    raise_on_failures(stats)
    summary = ds.summary()
    return {"wall_seconds": wall, "render_seconds": stats.render_seconds, "frames_rendered": stats.frames_rendered,
            "frames_before": committed + staged, "shards_committed": stats.shards_committed,
            "worker_starts": stats.worker_starts, "peak_worker_rss_mb": stats.peak_rss_mb, **summary}


def render_cmd(
    identities: Optional[int] = typer.Option(None, "--identities", "-n", min=1, help="Number of identities."),
    out: Path = typer.Option(..., "--out", "-o", help="Dataset directory (created, or resumed)."),
    expressions: Optional[int] = typer.Option(None, "--expressions", "-e", min=1,
                                              help="Expressions per identity (default: config)."),
    views: Optional[int] = typer.Option(None, "--views", "-v", min=1, help="Views per expression (default: config)."),
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="TOML configuration file."),
    preset: Optional[str] = typer.Option(None, "--preset", "-p", help="Render preset: ci, preview or production."),
    workers: int = typer.Option(1, "--workers", "-w", min=1, max=256, help="Worker processes (one bpy scene each)."),
    shards_per_worker: int = typer.Option(2, "--shards-per-worker", min=1,
                                          help="Recycle a worker process after this many shards."),
    seed: Optional[int] = typer.Option(None, "--seed", "-s", help="Run seed (overrides dataset.seed)."),
    device: Optional[str] = typer.Option(None, "--device", help="auto (OptiX, CUDA, else CPU), gpu or cpu."),
    set_: list[str] = typer.Option([], "--set", help="Override one config key: section.key=value (repeatable)."),
    model: Optional[Path] = typer.Option(None, "--model", "-m", help="Head model .npz (default: embedded)."),
    plan_dir: Optional[Path] = typer.Option(None, "--plan", help="Render this existing plan directory instead "
                                            "of planning (no other planning options allowed)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar; print one summary line."),
) -> None:
    """Render a dataset: plan (or reuse the plan in DIR/plan), then render the missing shards
    with W worker processes. Rerun the same command to resume after an interruption."""
    if plan_dir is not None:
        if any(x is not None for x in (identities, expressions, views, config, preset, seed, model, device)) or set_:
            raise SynthError("--plan renders an existing plan; planning options were given too", "--plan",
                             "drop --identities/--expressions/--views/--config/--preset/--seed/--set/--model")
        from synth.plan.io import load_plan

        load_plan(plan_dir)  # clear error if it is not a plan
        pdir = plan_dir.resolve()
    else:
        if identities is None:
            raise SynthError("missing --identities", "synth render", "pass --identities N (or --plan PLAN_DIR)")
        pdir = prepare_plan(out, identities, config, _overrides(expressions, views, preset, device, set_), seed, model)
    try:
        res = render_plan(out, pdir, workers, shards_per_worker, quiet=quiet)
    except KeyboardInterrupt:
        typer.echo("interrupted: frames rendered so far are kept; rerun the same command to resume", err=True)
        raise typer.Exit(130) from None
    fps = res["frames_rendered"] / max(res["wall_seconds"], 1e-9)
    typer.echo(f"{out}: {res['frames_committed']}/{res['frames']} frames in {res['shards_committed']}/"
               f"{res['shards']} shards committed; rendered {res['frames_rendered']} now in "
               f"{res['wall_seconds']:.1f} s ({fps:.2f} frames/s, Cycles {res['render_seconds']:.1f} s, "
               f"{res['worker_starts']} worker process(es), peak worker RSS {res['peak_worker_rss_mb']:.0f} MB)")


def register(app: typer.Typer) -> None:
    app.command("render")(render_cmd)
