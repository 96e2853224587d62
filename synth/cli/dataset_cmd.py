"""``synth validate DIR`` and ``synth preview DIR``: check and look at a rendered dataset."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from synth.errors import SynthError
from synth.io.process import default_jobs


def validate_cmd(
    directory: Path = typer.Argument(..., help="Dataset directory (the --out of `synth render`)."),
    quick: bool = typer.Option(False, "--quick", help="Skip sha256 hashing (sizes are still checked)."),
    partial: bool = typer.Option(False, "--partial", help="Planned shards not yet committed are warnings, "
                                                         "not defects (check a render in progress)."),
    jobs: Optional[int] = typer.Option(None, "--jobs", "-j", min=1, max=256,
                                       help="Check shards in this many processes (default: up to 4 cores)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON report instead of lines."),
    repair_index: bool = typer.Option(False, "--repair-index", help="First rebuild index.json from the shards' "
                                      "manifests (signing what they now say), print and log every change "
                                      "(DIR/logs/index-repairs.jsonl), then validate."),
) -> None:
    """Check every committed shard: checksums, EXR layers/size/NaN, JSON schema, counts vs the plan,
    and the index that signed each shard's manifest at commit.

    Exit code 0 when clean, 1 when defects were found, 2 for usage errors.
    """
    from synth.dataset.shards import load_dataset
    from synth.dataset.validate import validate_dataset
    from synth.dataset.validate_index import describe_change, repair

    load_dataset(directory)  # not a dataset: one line, exit 2
    jobs = default_jobs() if jobs is None else jobs
    if repair_index:
        changes = repair(directory)
        for c in changes:
            typer.echo(f"repaired {describe_change(c)}", err=as_json)
        typer.echo(f"index.json rebuilt from the manifests: {len(changes)} change(s)", err=as_json)
    if as_json:
        rep = validate_dataset(directory, quick=quick, partial=partial, jobs=jobs)
        typer.echo(json.dumps(rep.to_json(), indent=1))
        _finish(rep)
        return

    from rich.console import Console
    from rich.markup import escape
    from rich.progress import Progress

    err = Console(stderr=True)
    with Progress(console=err, transient=True, disable=not err.is_terminal) as prog:
        task = prog.add_task("validating", total=None)
        rep = validate_dataset(directory, quick=quick, partial=partial, jobs=jobs,
                               progress=lambda s: prog.advance(task))
    out = Console(highlight=False, soft_wrap=True)
    for d in rep.defects:
        out.print(f"[red]DEFECT[/red]  {escape(d.line())}", markup=True)
    for w in rep.warnings:
        out.print(f"[yellow]warning[/yellow] {escape(w.line())}", markup=True)
    kinds: dict[str, int] = {}
    for d in rep.defects:
        kinds[d.kind] = kinds.get(d.kind, 0) + 1
    by_kind = ", ".join(f"{k} {n}" for k, n in sorted(kinds.items()))
    status = "[green]OK[/green]" if rep.ok else f"[red]{len(rep.defects)} defect(s)[/red] ({by_kind})"
    out.print(f"{escape(rep.root)}: {rep.shards_checked}/{rep.shards_expected} shards, "
              f"{rep.frames_checked}/{rep.frames_expected} frames checked"
              f"{'' if rep.hashed else ' (no hashing: --quick)'}; {status}; {len(rep.warnings)} warning(s)"
              f"{f'; digest {rep.digest}' if rep.digest else ''}", markup=True)
    _finish(rep)


def _finish(rep) -> None:
    """Exit code 1 when defects were found (raised as an error so every entry point sees it)."""
    from synth.dataset.defects import DefectsFound

    if not rep.ok:
        raise DefectsFound(f"{len(rep.defects)} defect(s) found", rep.root, _fix(rep))


def _fix(rep) -> str:
    """What to do about the kinds of defect found."""
    kinds = {d.kind for d in rep.defects}
    fixes = []
    if kinds & {"unexpected-entry", "unexpected-shard"}:
        fixes.append("move away what does not belong to the dataset (listed above)")
    if "index" in kinds:
        fixes.append("for the index lines, --repair-index signs the manifests as they are now (only if you trust "
                     "them)")
    if kinds == {"missing-shard"}:
        fixes.append("rerun the render to commit the missing shards")
    elif kinds - {"unexpected-entry", "unexpected-shard", "index"}:
        fixes.append("re-render the affected shards (delete them from shards/ and rerun the render)")
    return "; ".join(fixes)


def preview_cmd(
    directory: Path = typer.Argument(..., help="Dataset directory."),
    shard: Optional[str] = typer.Option(None, "--shard", help="Shard id (default: the first committed shard)."),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="PNG to write (default: DIR/preview_<shard>.png)."),
    max_views: Optional[int] = typer.Option(None, "--max-views", min=1, help="Show at most this many views."),
    tile: int = typer.Option(96, "--tile", min=8, max=1024, help="Tile height in pixels."),
    overview: bool = typer.Option(False, "--overview", help="Many identities instead of one shard: per "
                                  "committed shard, its first expression at --max-views views (default 3)."),
    max_shards: Optional[int] = typer.Option(None, "--max-shards", min=1, help="With --overview: at most this "
                                             "many shards."),
    columns: int = typer.Option(2, "--columns", min=1, max=64, help="With --overview: identities per row."),
) -> None:
    """Write a contact-sheet PNG of a shard: rows expressions, columns views; colour | segmentation | depth.
    With --overview: one block per identity (colour | segmentation), to see a dataset's diversity."""
    from synth.dataset.preview import contact_sheet, overview_sheet

    if overview:
        if shard is not None:
            raise SynthError("--overview covers all shards; --shard was given too", "--shard", "drop one of them")
        p = overview_sheet(directory, output, views=max_views or 3, max_shards=max_shards, tile=tile,
                           columns=columns)
        typer.echo(str(p))
        return
    p = contact_sheet(directory, shard, output, max_views=max_views, tile=tile)
    typer.echo(str(p))


def register(app: typer.Typer) -> None:
    app.command("validate")(validate_cmd)
    app.command("preview")(preview_cmd)
