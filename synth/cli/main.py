"""The ``synth`` command line. Each command group lives in its own module and is added here.

User errors (:class:`synth.errors.SynthError`) print one line to stderr and exit with code 2.
"""

from __future__ import annotations

import sys

import typer

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
    from synth.cli import model_cmd

    app.add_typer(model_cmd.app, name="model")
    # Optional command groups: present once their modules exist.
    import importlib

    for mod, attr in (("synth.cli.config_cmd", "register"), ("synth.cli.plan_cmd", "register"),
                      ("synth.cli.render_cmd", "register"), ("synth.cli.dataset_cmd", "register"),
                      ("synth.cli.assets_cmd", "register"), ("synth.cli.export_cmd", "register"),
                      ("synth.cli.report_cmd", "register"), ("prior.cli", "register")):
        try:
            m = importlib.import_module(mod)
        except ModuleNotFoundError as e:
            if e.name == mod:
                continue
            raise
        getattr(m, attr)(app)


_register()


def main(argv: list[str] | None = None) -> int:
    from synth.errors import SynthError

    try:
        rc = app(args=argv, standalone_mode=False)
    except SynthError as e:
        print(f"synth: error: {e}", file=sys.stderr)
        return e.exit_code
    except typer.Exit as e:
        return e.exit_code
    except typer.Abort:
        print("synth: aborted", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("synth: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # usage errors (typer bundles its own click)
        try:
            from typer._click.exceptions import ClickException
        except ImportError:  # older typer: plain click
            from click import ClickException
        if isinstance(e, ClickException):
            e.show()
            return 2
        raise
    return rc if isinstance(rc, int) else 0


if __name__ == "__main__":
    sys.exit(main())
