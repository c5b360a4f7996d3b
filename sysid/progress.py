"""Progress of long loops that reads well wherever it goes: a redrawn bar on a terminal, and
in a file or a pipe a plain time-stamped line at the start, every few seconds, and at the end
(no carriage-return redraws filling a log); nothing with ``-q`` (`sysid.logs`)."""
from __future__ import annotations

import sys
import time
from typing import Iterable, Iterator, Sized, TextIO

from sysid import logs


def on_terminal(stream: TextIO | None = None) -> bool:
    """Whether progress goes to an interactive terminal (stderr by default)."""
    return logs.on_terminal(stream or sys.stderr)


class LineProgress:
    """tqdm's small interface (`update`, `close`, iteration) writing whole lines."""

    def __init__(self, iterable: Iterable | None = None, total: int | None = None, desc: str = "",
                 unit: str = "it", every_s: float = 5.0, stream: TextIO | None = None):
        self.iterable = iterable
        self.total = total if total is not None else (len(iterable) if isinstance(iterable, Sized) else None)
        self.desc, self.unit, self.every_s = desc, unit, every_s
        self.stream = stream or sys.stderr
        self.n = 0
        self.started = self.last = time.monotonic()
        self.closed = False
        self._line(f"{self.n}/{self.total} {unit}" if self.total is not None else "started")

    def _line(self, text: str) -> None:
        print(logs.stamp(f"{self.desc}: {text}", self.stream), file=self.stream, flush=True)

    def update(self, n: int = 1) -> None:
        self.n += n
        now = time.monotonic()
        if now - self.last >= self.every_s and (self.total is None or self.n < self.total):
            self.last = now
            share = f" ({100 * self.n / self.total:.0f} %)" if self.total else ""
            self._line(f"{self.n}/{self.total if self.total is not None else '?'} {self.unit}{share}")

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._line(f"{self.n} {self.unit} in {time.monotonic() - self.started:.1f} s")

    def __iter__(self) -> Iterator:
        for item in self.iterable:
            yield item
            self.update()
        self.close()


def progress(iterable: Iterable | None = None, *, total: int | None = None, desc: str = "", unit: str = "it",
             quiet: bool = False):
    """A tqdm bar on a terminal, `LineProgress` otherwise; nothing at all when `quiet` (or
    the command runs with ``-q``)."""
    quiet = quiet or logs.is_quiet()
    if on_terminal() or quiet:
        from tqdm import tqdm
        return tqdm(iterable, total=total, desc=desc, unit=unit, disable=quiet, leave=False)
    return LineProgress(iterable, total=total, desc=desc, unit=unit)
