"""``synth plan``: decide every random choice of a dataset and write it as JSON specs."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Optional

import typer

from synth.seeds import MAX_SEED


def plan_cmd(
    identities: int = typer.Option(..., "--identities", "-n", help="Number of identities to plan."),
    out: Path = typer.Option(..., "--out", "-o", help="Plan directory to create (must be new or empty)."),
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="TOML configuration file."),
    seed: Optional[int] = typer.Option(None, "--seed", "-s", min=0, max=MAX_SEED,
                                       help="Run seed (overrides dataset.seed)."),
    set_: list[str] = typer.Option([], "--set", help="Override one key: section.key=value (repeatable)."),
    model: Optional[Path] = typer.Option(None, "--model", "-m", help="Head model .npz (default: embedded)."),
    environments: Optional[int] = typer.Option(None, "--environments", min=1, max=100,
                                               help="Lighting environments per expression (default: config, 1); "
                                                    "each expression's views are rendered in every one."),
    start: int = typer.Option(0, "--start", help="First identity index (a multiple of identities_per_shard)."),
    jobs: Optional[int] = typer.Option(None, "--jobs", "-j", help="Processes (default: up to 4 cores); "
                                       "never changes the output."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print only the plan hash."),
    as_json: bool = typer.Option(False, "--json", help="Print the plan's hash, counts and summary as JSON."),
) -> None:
    """Write the sampling plan: identity and expression codes, joint rotations, assets, cameras
    (K, world_to_camera) and per-frame seeds, one JSON spec per shard, plus a summary."""
    from synth.config import load_config
    from synth.plan.planner import run_plan

    t0 = time.perf_counter()
    sets = [*set_, *([f"dataset.environments_per_expression={environments}"] if environments is not None else [])]
    cfg = load_config(config, sets)
    header, summ = run_plan(cfg, identities, out, seed=seed, first_identity=start, model_path=model, jobs=jobs)
    dt = time.perf_counter() - t0
    if quiet:
        typer.echo(header["plan_hash"])
        return
    if as_json:
        import json

        model = {k: header["model"][k] for k in ("name", "sha256", "path", "identity_dims", "expression_dims")}
        typer.echo(json.dumps({"out": str(out), "plan_hash": header["plan_hash"], "run_seed": header["run_seed"],
                               "first_identity": header["first_identity"], "num_identities": header["num_identities"],
                               "num_frames": header["num_frames"], "num_shards": len(header["shards"]),
                               "bytes": sum(s["bytes"] for s in header["shards"]), "model": model,
                               "summary": summ, "seconds": round(dt, 3)}, indent=1))
        return
    from rich.console import Console
    from rich.table import Table

    cams = summ["cameras"]
    size = sum(s["bytes"] for s in header["shards"])
    t = Table(title=f"plan {out}", show_header=False)
    for k, v in (
        ("identities", f"{header['num_identities']} (from {header['first_identity']})"),
        ("frames", f"{header['num_frames']} in {len(header['shards'])} shards ({size / 1e6:.1f} MB)"),
        ("run seed", str(header["run_seed"])),
        ("model", f"{header['model']['name']} ({header['model']['sha256'][:12]})"),
        ("expressions", ", ".join(f"{k} {v}" for k, v in summ["expression_kinds"].items())),
        ("views", f"{cams['views_per_expression']} per expression, >= {cams['min_separation_deg']} deg apart "
                  f"(smallest {cams['smallest_pairwise_angle_deg']:.3f}; packing bound {cams['packing_bound']})"),
        ("camera acceptance", f"{cams['acceptance_rate']:.3f} ({cams['restarts']} restarts)"),
        ("plan hash", header["plan_hash"]),
        ("time", f"{dt:.2f} s"),
    ):
        t.add_row(k, v)
    Console().print(t)


def register(app: typer.Typer) -> None:
    app.command("plan")(plan_cmd)
