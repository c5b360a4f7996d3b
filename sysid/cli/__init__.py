"""The ``sysid`` command. Thin: each subcommand module parses options and calls the library.

Subcommand modules register themselves on `app` when imported below.
"""
from __future__ import annotations

import sys

import typer

from sysid.errors import SysidError

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Ship maneuvering system identification: MMG, hybrid MMG+FNN, reports.")

# subcommands (each module adds its commands to `app`)
from sysid.cli import mmg_commands  # noqa: E402,F401
from sysid.cli import report_commands  # noqa: E402,F401
from sysid.cli import preprocess_commands  # noqa: E402,F401
from sysid.cli import train_commands  # noqa: E402,F401
from sysid.cli import export_commands  # noqa: E402,F401


MULTI_VALUE_OPTIONS = ("--data",)


def expand_multi_value(argv: list[str]) -> list[str]:
    """``--data a b c`` to ``--data a --data b --data c`` (click takes one value per flag)."""
    out: list[str] = []
    current = None
    for arg in argv:
        if arg in MULTI_VALUE_OPTIONS:
            current = arg
            out.append(arg)
            continue
        if current and not arg.startswith("-") and out and out[-1] != current:
            out.append(current)
        elif arg.startswith("-"):
            current = None
        out.append(arg)
    return out


def run(argv: list[str]) -> None:
    """Run a subcommand; `SysidError` propagates (for tests and embedding)."""
    app(args=expand_multi_value(list(argv)), standalone_mode=False)


def main(argv: list[str] | None = None) -> None:
    """Console entry point: one clear line on bad input, no traceback."""
    try:
        run(sys.argv[1:] if argv is None else argv)
    except SysidError as exc:
        typer.secho(f"error: {exc}", fg=typer.colors.RED, err=True)
        sys.exit(2)
    except (typer.Exit, SystemExit) as exc:
        code = getattr(exc, "exit_code", getattr(exc, "code", 0))
        sys.exit(code or 0)
    except Exception as exc:  # click usage errors and friends
        import click
        if isinstance(exc, click.ClickException):
            exc.show()
            sys.exit(exc.exit_code)
        if isinstance(exc, click.exceptions.Abort):
            sys.exit(1)
        raise
