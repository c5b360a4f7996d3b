"""Running `sysid` as a user does and judging how it fails, for the CLI fuzz tests.

`Outcome` is one command's exit code and output; `assert_refused` is the contract every bad
input must meet: its exit code (2 for bad input and refused outputs), exactly one error line that names the file or option at
fault, no traceback, and nothing partial or stale left where the output was asked for.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ERROR_PREFIXES = ("error:", "internal error:", "interrupted:")

# bytes that are no CSV or TOML: NULs, invalid UTF-8, a stray quote
BINARY = bytes(range(256)) * 4 + b'\x00\xff"\n\x89PNG\r\n'


@dataclass
class Outcome:
    code: int
    out: str
    err: str

    @property
    def error_lines(self) -> list[str]:
        return [line for line in self.err.splitlines() if line.startswith(ERROR_PREFIXES)]


def in_process(capsys, *args) -> Outcome:
    """`sysid.cli.main` with these arguments, as the console script calls it."""
    from sysid.cli import main
    capsys.readouterr()
    try:
        main([str(a) for a in args])
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    captured = capsys.readouterr()
    return Outcome(code, captured.out, captured.err)


def console_script() -> str:
    here = Path(sys.executable).parent / "sysid"
    found = str(here) if here.is_file() else shutil.which("sysid")
    if not found:
        pytest.skip("the sysid console script is not installed in this environment (pip install -e .)")
    return found


def environment() -> dict[str, str]:
    """The test's environment for a child `sysid`, on one thread (a shared 2-core machine)."""
    return {**os.environ, "OMP_NUM_THREADS": "1", "COLUMNS": "100"}


def subprocess_run(*args, timeout: float = 300) -> Outcome:
    """The installed console script in a subprocess."""
    done = subprocess.run([console_script(), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=environment())
    return Outcome(done.returncode, done.stdout, done.stderr)


def leftovers(directory: Path) -> list[str]:
    """Hidden entries (staging directories, temporary files) in `directory`."""
    return sorted(p.name for p in directory.iterdir() if p.name.startswith(".")) if directory.is_dir() else []


def assert_refused(outcome: Outcome, code: int, *named: str, absent: tuple[Path, ...] = ()) -> str:
    """The clean-failure contract; returns the error line."""
    text = outcome.out + outcome.err
    assert "Traceback" not in text, text
    assert outcome.code == code, f"exit {outcome.code}, expected {code}:\n{text}"
    assert len(outcome.error_lines) == 1, f"expected one error line:\n{outcome.err}"
    line = outcome.error_lines[0]
    assert not line.startswith("internal error"), line
    for name in named:
        assert str(name) in line, f"{name!r} not named in: {line}"
    for path in absent:
        assert not path.exists(), f"{path} was left behind"
        assert leftovers(path.parent) == [], f"hidden leftovers beside {path}: {leftovers(path.parent)}"
    return line
