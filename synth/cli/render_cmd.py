"""``synth render``: plan (or reuse the plan) and render it into a sharded dataset.

    synth render --identities N [--expressions E] [--views V] [--config F] [--preset P]
                 [--workers W] [--seed S] --out DIR

``DIR/plan/`` holds the plan. A rerun of the same command re-plans into a temporary
directory, finds the same plan hash, and resumes: committed shards are skipped and frames
already staged by an interrupted run are kept. A different plan (other counts, seed,
config or model) for the same ``DIR`` is refused. ``--plan PLAN_DIR`` renders an existing
plan instead of planning.

This module parses arguments and prints; planning, resuming and running the workers live
in ``renderer_jobs`` (``submit``: plan-or-resume; ``local``: the worker processes).
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from synth.errors import SynthError


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
    from renderer_jobs.local import LocalBackend
    from renderer_jobs.submit import existing_plan, prepare_plan, render_plan

    if plan_dir is not None:
        if any(x is not None for x in (identities, expressions, views, config, preset, seed, model, device)) or set_:
            raise SynthError("--plan renders an existing plan; planning options were given too", "--plan",
                             "drop --identities/--expressions/--views/--config/--preset/--seed/--set/--model")
        pdir = existing_plan(plan_dir)
    else:
        if identities is None:
            raise SynthError("missing --identities", "synth render", "pass --identities N (or --plan PLAN_DIR)")
        pdir = prepare_plan(out, identities, config, _overrides(expressions, views, preset, device, set_), seed, model)
    try:
        res = render_plan(out, pdir, LocalBackend(workers), shards_per_worker, quiet=quiet)
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
