"""``synth export nerfstudio|cafca|usd``: a rendered dataset in the formats other tools read (docs/export.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

export_app = typer.Typer(help="Write a dataset in other tools' formats (docs/export.md).", no_args_is_help=True)


@export_app.command("nerfstudio")
def nerfstudio_cmd(
    directory: Path = typer.Argument(..., help="Dataset directory (its committed shards) or one shard directory."),
    out: Path = typer.Option(..., "--out", "-o", help="nerfstudio data folder to create (new or empty)."),
    identity: Optional[int] = typer.Option(None, "--identity", "-i", min=0, help="Only this identity index."),
    expression: Optional[int] = typer.Option(None, "--expression", "-e", min=0, help="Only this expression index."),
    environment: int = typer.Option(0, "--environment", min=0, help="The lighting environment to export (datasets "
                                    "planned with dataset.environments_per_expression > 1)."),
    val_views: int = typer.Option(1, "--val-views", min=0, help="Views per scene held out as validation and test "
                                  "images (the highest view indices, as the prior holds out); 0: no split."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
) -> None:
    """transforms.json (OpenGL cameras, fl_x fl_y cx cy w h, the train/val/test split), 8-bit sRGB
    PNGs with straight alpha, masks, and 16-bit depth PNGs in millimetres. nerfstudio trains one
    static scene: pick one identity and expression (`ns-train nerfacto --data OUT`)."""
    from synth.export.nerfstudio import export_nerfstudio

    s = export_nerfstudio(directory, out, identity=identity, expression=expression, environment=environment,
                          val_views=val_views)
    if as_json:
        typer.echo(json.dumps(s, indent=1))
        return
    typer.echo(f"{s['out']}: {s['frames']} frames ({len(s['val'])} held out for val/test) of {len(s['scenes'])} "
               f"scene(s) (identity, expression) "
               f"{', '.join(f'({i}, {e})' for i, e in s['scenes'][:6])}{' ...' if len(s['scenes']) > 6 else ''}")
    if len(s["scenes"]) > 1:
        typer.echo("note: nerfstudio trains one static scene; select one with --identity and --expression", err=True)


@export_app.command("cafca")
def cafca_cmd(
    directory: Path = typer.Argument(..., help="Dataset directory (its committed shards) or one shard directory."),
    out: Path = typer.Option(..., "--out", "-o", help="Folder to create (new or empty)."),
    identity: Optional[int] = typer.Option(None, "--identity", "-i", min=0, help="Only this identity index."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
) -> None:
    """The Cafca release's layout: SUBJECT/EXP_ENV/{cameras_json,color_image,foreground_mask,
    segmentation}/Cvv.{json,png} (OpenCV cameras with K, world2cam, cam2world, P, position,
    orientation; 16-bit segmentation; environment.json), so code written for it reads ours."""
    from synth.export.cafca import export_cafca

    s = export_cafca(directory, out, identity=identity)
    if as_json:
        typer.echo(json.dumps(s, indent=1))
        return
    typer.echo(f"{s['out']}: {s['frames']} frames in {len(s['scenes'])} scene folder(s) (SUBJECT/EXP_ENV)")


@export_app.command("usd")
def usd_cmd(
    directory: Path = typer.Argument(..., help="Dataset directory (the --out of `synth render`)."),
    out: Path = typer.Option(..., "--out", "-o", help="Stage to write: .usdc (binary), .usda (text) or .usd."),
    shard: Optional[str] = typer.Option(None, "--shard", "-s", help="Shard id (default: the first committed)."),
    model: Optional[Path] = typer.Option(None, "--model", "-m", help="Head model .npz the dataset was rendered "
                                         "with (default: the dataset's plan's, else the embedded default)."),
    no_assets: bool = typer.Option(False, "--no-assets", help="Only the head, landmarks and cameras."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
) -> None:
    """A USD stage of one shard: the head mesh per expression as time samples (time code =
    expression index) with segmentation subsets, the built shell assets' meshes, a camera per
    view; metres, Z up. Needs usd-core (the `export` extra)."""
    from synth.export.usd import export_usd

    s = export_usd(directory, out, shard=shard, model=model, assets=not no_assets)
    if as_json:
        typer.echo(json.dumps(s, indent=1))
        return
    for r in s["identities"]:
        skipped = f"; not exported: {', '.join(sorted(r['skipped']))}" if r["skipped"] else ""
        typer.echo(f"identity {r['identity']}: {len(r['expressions'])} expression(s), {len(r['views'])} camera(s), "
                   f"assets: {', '.join(r['assets']) or 'none'}{skipped}")
    typer.echo(f"{s['out']}: shard {s['shard']}, {s['frames']} frames")


def register(app: typer.Typer) -> None:
    app.add_typer(export_app, name="export")
