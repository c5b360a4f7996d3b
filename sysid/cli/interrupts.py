"""What a command has kept when the user interrupts it (Ctrl-C): one line for the error path.

A command that writes outputs says what an interruption leaves behind with
`on_interrupt("...")`; the default is that nothing was written, which holds for every
command whose outputs are staged and moved into place only when complete.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Callable, Iterator

_DEFAULT = "nothing was written (outputs are moved into place only when complete)"
_note: str | Callable[[], str] = _DEFAULT


def on_interrupt(note: str | Callable[[], str]) -> None:
    """Set the line shown if the running command is interrupted (or a function giving it)."""
    global _note
    _note = note


def interrupt_note() -> str:
    """The line to show for an interruption now."""
    return _note() if callable(_note) else _note


@contextmanager
def interruptible() -> Iterator[None]:
    """Ctrl-C (SIGINT) interrupts the command even when sysid was started with SIGINT
    ignored (a background job of a non-interactive shell inherits that, and Python keeps
    it): a SIGINT that reaches sysid always ends it (exit 130). Put back afterwards. To
    keep a long job out of a terminal's Ctrl-C, start it in its own session (``setsid``)."""
    ignored = (threading.current_thread() is threading.main_thread()
               and signal.getsignal(signal.SIGINT) is signal.SIG_IGN)
    if ignored:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        if ignored:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
