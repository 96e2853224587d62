"""The ``synth`` command line. Each command group lives in its own module and is added here;
:func:`main` runs it inside the error boundary of :mod:`synth.cli.boundary`."""

from __future__ import annotations

import sys

import typer

from synth.cli.boundary import run

app = typer.Typer(
    name="synth",
    help="Procedural synthetic face data with Blender (Cafca-style), and tools around it.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _print_version(value: bool) -> None:
    if value:
        from synth import __version__

        typer.echo(f"synth {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                       help="Print the version and exit.")) -> None:
    """Procedural synthetic face data with Blender (Cafca-style), and tools around it."""


def _register() -> None:
    import prior.cli
    from synth.cli import (assets_cmd, config_cmd, dataset_cmd, export_cmd, model_cmd, plan_cmd, render_cmd,
                           report_cmd)

    app.add_typer(model_cmd.app, name="model")
    for m in (config_cmd, plan_cmd, render_cmd, dataset_cmd, assets_cmd, export_cmd, report_cmd, prior.cli):
        m.register(app)


_register()


def main(argv: list[str] | None = None) -> int:
    return run(app, argv)


if __name__ == "__main__":
    sys.exit(main())
