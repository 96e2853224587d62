"""Command-line parameters that several commands share, declared once (typer ``Annotated`` types),
so the same option has the same spelling and help everywhere."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

#: ``--set section.key=value``, repeatable; applied after the preset and the TOML file
Overrides = Annotated[list[str], typer.Option("--set", help="Override one key: section.key=value (repeatable).")]
#: the prior's compute device
Device = Annotated[str, typer.Option("--device", help="cpu or cuda.")]
#: the prior's size presets
PriorPreset = Annotated[Optional[str], typer.Option("--preset", "-p", help="small (CPU, default) or paper.")]
