"""The log of every ``sysid`` command: one setup (`configure`), read by the CLI and by
`sysid.progress`.

Messages go to the ``sysid`` logger: stage lines (INFO) to stdout, warnings and errors to
stderr (``WARNING: ...``). On a terminal a line is printed as it is; when the stream is a
file or a pipe every line starts with the local time (``2026-11-24 06:40:01``), so a log
read later says when each stage ran. ``-q`` keeps warnings and errors only (no stage lines,
no progress); ``-v`` adds detail (every training epoch). Library code logs through
``logging.getLogger(__name__)`` or takes a ``log`` callable; it never configures handlers.
"""
from __future__ import annotations

import logging
import sys
import time
from typing import TextIO

LOGGER = logging.getLogger("sysid")
TIME_FORMAT = "%Y-%m-%d %H:%M:%S"


def on_terminal(stream: TextIO) -> bool:
    """Whether `stream` is an interactive terminal."""
    return bool(getattr(stream, "isatty", lambda: False)())


def stamp(line: str, stream: TextIO) -> str:
    """`line` with the local time in front when `stream` is not a terminal."""
    return line if on_terminal(stream) else f"{time.strftime(TIME_FORMAT)} {line}"


class _StreamHandler(logging.Handler):
    """Writes to ``sys.stdout`` or ``sys.stderr`` as they are when a record is emitted
    (so redirections made after `configure`, such as pytest's capture, are followed)."""

    def __init__(self, name: str, low: int, high: int):
        super().__init__(low)
        self.stream_name, self.high = name, high

    def emit(self, record: logging.LogRecord) -> None:
        if record.levelno >= self.high:
            return
        stream = getattr(sys, self.stream_name)
        message = record.getMessage()
        if record.levelno >= logging.WARNING and not message.startswith(("WARNING", "error")):
            message = f"{record.levelname}: {message}"
        try:
            stream.write("".join(stamp(line, stream) + "\n" for line in message.splitlines() or [""]))
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: the log is lost, the command goes on
            pass


def configure(verbosity: int = 0) -> None:
    """Set up the ``sysid`` logger for a command: `verbosity` -1 (``-q``: warnings and
    errors), 0 (stage lines) or >= 1 (``-v``: detail too). Idempotent."""
    level = logging.WARNING if verbosity < 0 else (logging.INFO if verbosity == 0 else logging.DEBUG)
    LOGGER.setLevel(level)
    LOGGER.propagate = False
    if not any(isinstance(h, _StreamHandler) for h in LOGGER.handlers):
        LOGGER.addHandler(_StreamHandler("stdout", logging.DEBUG, logging.WARNING))
        LOGGER.addHandler(_StreamHandler("stderr", logging.WARNING, logging.CRITICAL + 1))


def is_quiet() -> bool:
    """``-q`` was given: no stage lines and no progress."""
    return LOGGER.level >= logging.WARNING


def info(message: str) -> None:
    """A stage line (stdout; time-stamped in a file; hidden by ``-q``)."""
    LOGGER.info(message)


def warning(message: str) -> None:
    """A warning (stderr, ``WARNING: ...``; shown with ``-q`` too)."""
    LOGGER.warning(message)


def indented(prefix: str = "  "):
    """A ``log`` callable for library functions: stage lines with a prefix."""
    return lambda message: LOGGER.info(prefix + message)
