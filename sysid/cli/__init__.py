"""The ``sysid`` command. Thin: each subcommand module parses options and calls the library.

Subcommand modules register themselves on `app` when imported below.
"""
from __future__ import annotations

import sys

import typer
import typer.main

from sysid.errors import SysidError
from sysid.cli.interrupts import interrupt_note, interruptible
from sysid.cli.outputs import release

from sysid.cli.app import app  # noqa: E402

# subcommands (each module adds its commands to `app`)
from sysid.cli import forces_commands  # noqa: E402,F401
from sysid.cli import simulate_commands  # noqa: E402,F401
from sysid.cli import evaluate_commands  # noqa: E402,F401
from sysid.cli import report_commands  # noqa: E402,F401
from sysid.cli import preprocess_commands  # noqa: E402,F401
from sysid.cli import train_commands  # noqa: E402,F401
from sysid.cli import ship_commands  # noqa: E402,F401
from sysid.cli import init_commands  # noqa: E402,F401
from sysid.cli import export_commands  # noqa: E402,F401
from sysid.cli import sweep_commands  # noqa: E402,F401
from sysid.cli import maneuver_commands  # noqa: E402,F401
from sysid.cli import compare_commands  # noqa: E402,F401
from sysid.cli import logs_commands  # noqa: E402,F401


MULTI_VALUE_OPTIONS = ("--data", "--turning", "--zigzag", "--recorded")


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


COMMON_OPTIONS = ("-v", "-vv", "-vvv", "--verbose", "-q", "--quiet")


def common_options_first(argv: list[str]) -> list[str]:
    """``sysid train CFG -v`` to ``sysid -v train CFG``: the options every command takes
    (`sysid.cli.app.common_options`) belong to the application, wherever they are written
    (up to a ``--``)."""
    end = argv.index("--") if "--" in argv else len(argv)
    common = [a for a in argv[:end] if a in COMMON_OPTIONS]
    return common + [a for a in argv[:end] if a not in COMMON_OPTIONS] + argv[end:]


def _with_epilog(command) -> None:
    """Every command's help ends by naming the options every command takes."""
    from sysid.cli.app import EPILOG
    for sub in getattr(command, "commands", {}).values():
        sub.epilog = sub.epilog or EPILOG
        _with_epilog(sub)


INTERRUPTED = 130  # the shell's code for a job stopped by Ctrl-C (128 + SIGINT)


def run(argv: list[str]) -> None:
    """Run a subcommand; `SysidError` and `KeyboardInterrupt` propagate (for tests and
    embedding)."""
    command = typer.main.get_command(app)
    _with_epilog(command)
    failed = True
    try:
        code = command(args=common_options_first(expand_multi_value(list(argv))), prog_name="sysid",
                       standalone_mode=False)
        failed = isinstance(code, int) and code != 0
    finally:
        release(failed)  # the output locks the command took; a failed command's new empty folders
    # typer >= 0.29 turns Ctrl-C into Exit(130) and, outside standalone mode, returns the code
    if code == INTERRUPTED:
        raise KeyboardInterrupt
    if isinstance(code, int) and code:
        raise SystemExit(code)


TRACEBACK_FLAG = "--traceback"


def _is_usage_error(exc: BaseException) -> bool:
    """click's ClickException family (vendored by typer >= 0.29, the `click` package before)."""
    return callable(getattr(exc, "show", None)) and isinstance(getattr(exc, "exit_code", None), int)


def _is_abort(exc: BaseException) -> bool:
    return type(exc).__name__ == "Abort"


def main(argv: list[str] | None = None) -> None:
    """Console entry point: one clear line on bad input, no traceback.

    Exit codes: 0 success; 2 usage error, bad input (file and field named) or a refused
    output (`OutputError`: an input, a sealed or foreign directory, a link, an unwritable
    path, another sysid writing it); 1 a failure while writing (`OSError`) or an unexpected
    error; 130 interrupted (Ctrl-C). ``--traceback`` shows the Python traceback of an
    unexpected error.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    show_traceback = TRACEBACK_FLAG in args
    args = [a for a in args if a != TRACEBACK_FLAG]
    try:
        with interruptible():
            run(args)
    except SysidError as exc:
        typer.secho(f"error: {exc}", fg=typer.colors.RED, err=True)
        sys.exit(2)
    except (typer.Exit, SystemExit) as exc:
        code = getattr(exc, "exit_code", getattr(exc, "code", 0))
        sys.exit(code or 0)
    except KeyboardInterrupt:
        typer.secho(f"interrupted: {interrupt_note()}", fg=typer.colors.YELLOW, err=True)
        sys.exit(INTERRUPTED)
    except Exception as exc:
        if _is_usage_error(exc):
            exc.show()  # type: ignore[attr-defined]
            sys.exit(exc.exit_code)  # type: ignore[attr-defined]
        if _is_abort(exc):  # click turns Ctrl-C into Abort
            typer.secho(f"interrupted: {interrupt_note()}", fg=typer.colors.YELLOW, err=True)
            sys.exit(INTERRUPTED)
        if isinstance(exc, OSError):  # output or input file problems: not our bug
            where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            typer.secho(f"error: {where}{exc.strerror or exc}", fg=typer.colors.RED, err=True)
            sys.exit(1)
        if show_traceback:
            raise
        typer.secho(f"internal error: {type(exc).__name__}: {exc} "
                    f"(run again with {TRACEBACK_FLAG} to see where)", fg=typer.colors.RED, err=True)
        sys.exit(1)
