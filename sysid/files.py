"""Atomic file output: write to a temporary file beside the target, then rename.

A crash or a bad input never leaves a half-written file behind.
"""
from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path in the target's directory; rename it onto `path` on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix or ".tmp")
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_csv(frame, path: str | os.PathLike, **kwargs) -> Path:
    """`DataFrame.to_csv` to `path`, atomically."""
    with atomic_path(path, ".csv") as tmp:
        frame.to_csv(tmp, index=False, **kwargs)
    return Path(path)


def write_text(text: str, path: str | os.PathLike) -> Path:
    """Text to `path`, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)
