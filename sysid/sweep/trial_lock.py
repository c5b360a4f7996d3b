"""One process at a time per trial: an exclusive advisory lock (``flock``) held while a
trial is checked, trained and written.

Optuna may propose the same configuration twice while the first is still training, and a
retried trial may start beside the attempt it replaces. The second process waits at the
lock and then finds the run complete (reused) or resumes it from its checkpoint. The
kernel releases the lock when its holder dies, so a killed trial never blocks a resume.
Locks live in ``{out}/.locks/`` so that no reader of the trial directories sees them; the
trial runner removes them once every trial is over (`remove_locks`).
"""
from __future__ import annotations

import os
import shutil
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

try:
    import fcntl
except ImportError:  # not POSIX: trials are not locked
    fcntl = None

LOCK_DIR = ".locks"


def lock_path(out: str | os.PathLike, trial_path: str) -> Path:
    """The lock file of the trial at `trial_path` (relative to the sweep's output `out`)."""
    return Path(out) / LOCK_DIR / (trial_path.replace("/", "__") + ".lock")


@contextmanager
def trial_lock(out: str | os.PathLike, trial_path: str) -> Iterator[None]:
    """Hold the trial's exclusive lock (blocking until another holder is done)."""
    if fcntl is None:
        yield
        return
    path = lock_path(out, trial_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing the descriptor releases the lock


def remove_locks(out: str | os.PathLike) -> None:
    """Remove ``{out}/.locks/``: call only when no trial of `out` can still be running."""
    shutil.rmtree(Path(out) / LOCK_DIR, ignore_errors=True)
