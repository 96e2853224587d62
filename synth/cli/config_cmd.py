"""``synth config show``: print the resolved configuration (TOML) or the documented key table."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

config_app = typer.Typer(help="Inspect the dataset configuration.", no_args_is_help=True)


@config_app.command("show")
def show_cmd(
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="TOML configuration file."),
    set_: list[str] = typer.Option([], "--set", help="Override one key: section.key=value (repeatable)."),
    explain: bool = typer.Option(False, "--explain", help="Print every key with its type, default and meaning."),
) -> None:
    """Print the resolved configuration: defaults <- --config <- --set (render preset applied)."""
    from synth.config import explain as explain_rows
    from synth.config import load_config, to_toml

    if explain:
        from rich.console import Console
        from rich.table import Table

        t = Table("key", "type", "default", "meaning", show_lines=False)
        for row in explain_rows():
            t.add_row(*row)
        Console(width=200).print(t)
        return
    cfg = load_config(config, set_)
    typer.echo(to_toml(cfg.resolved()), nl=False)


def register(app: typer.Typer) -> None:
    app.add_typer(config_app, name="config")
