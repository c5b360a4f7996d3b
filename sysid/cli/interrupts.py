"""What a command has kept when the user interrupts it (Ctrl-C): one line for the error path.

A command that writes outputs says what an interruption leaves behind with
`on_interrupt("...")`; the default is that nothing was written, which holds for every
command whose outputs are staged and moved into place only when complete.
"""
from __future__ import annotations

from typing import Callable

_DEFAULT = "nothing was written (outputs are moved into place only when complete)"
_note = _DEFAULT


def on_interrupt(note: str | Callable[[], str]) -> None:
    """Set the line shown if the running command is interrupted (or a function giving it)."""
    global _note
    _note = note


def interrupt_note() -> str:
    """The line to show for an interruption now."""
    return _note() if callable(_note) else _note
