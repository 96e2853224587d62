"""``synth report DIR``: the dataset at a glance (an HTML page with plots, or JSON)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer


def report_cmd(
    directory: Path = typer.Argument(..., help="Dataset directory (the --out of `synth render`), complete or not."),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="HTML file to write "
                                          "(default: DIR/report.html)."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON (no HTML unless -o is given)."),
    max_shards: Optional[int] = typer.Option(None, "--max-shards", min=1, help="Read only the first N committed "
                                             "shards (a sample of a large dataset; progress counts all)."),
) -> None:
    """Identity and expression codes, viewpoints and their separation, asset and style
    frequencies, skin ITA, render time per frame and shard, failures and retries, and a
    contact sheet, for the committed shards. One self-contained HTML file (plots embedded)."""
    from synth.report.html import write_report

    out = output if output is not None or as_json else directory / "report.html"
    summary = write_report(directory, out, max_shards=max_shards)
    if as_json:
        typer.echo(json.dumps(summary, indent=1))
        return
    p = summary["progress"]
    typer.echo(f"{out}: {p['shards_committed']}/{p['shards_planned']} shards, {p['frames_committed']}/"
               f"{p['frames_planned']} frames committed")


def register(app: typer.Typer) -> None:
    app.command("report")(report_cmd)
