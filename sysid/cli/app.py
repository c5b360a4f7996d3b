"""The `sysid` typer application; each ``*_commands`` module registers its commands on it.

Options of the application itself (``sysid --version``, ``-v``, ``-q``) are accepted before
or after the command's name: `sysid.cli.common_options_first` moves them in front."""
from __future__ import annotations

import typer

app = typer.Typer(add_completion=False, no_args_is_help=True, rich_markup_mode=None,
                  pretty_exceptions_enable=False,
                  help="Ship maneuvering system identification: MMG, hybrid MMG+FNN, reports.")

EPILOG = ("Every command also takes -v/--verbose (more detail, e.g. every epoch), -q/--quiet (warnings "
          "and errors only) and --traceback.")


def _print_version(value: bool) -> None:
    if value:
        import platform

        from sysid import __version__
        typer.echo(f"sysid {__version__} (Python {platform.python_version()})")
        raise typer.Exit()


@app.callback(epilog=EPILOG)
def common_options(
    version: bool = typer.Option(False, "--version", is_eager=True, callback=_print_version,
                                 help="Print sysid's version and exit."),
    verbose: int = typer.Option(0, "-v", "--verbose", count=True, show_default=False,
                                help="More detail (every training epoch); any command, before or after its name."),
    quiet: bool = typer.Option(False, "-q", "--quiet",
                               help="Warnings and errors only, no progress; any command, before or after its name."),
) -> None:
    """Ship maneuvering system identification: MMG, hybrid MMG+FNN, reports.

    Stage lines go to stdout, time-stamped when stdout is a file or a pipe; warnings and
    errors to stderr."""
    from sysid import logs
    logs.configure(-1 if quiet else verbose)
