"""The installed console script, run as a user runs it (a subprocess of this environment).

CI runs the suite inside a fresh virtual environment built by `.ci/run`, so this also
proves the error path needs no package the project does not declare (typer >= 0.29
vendors click and no longer installs it).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest


def _console_script() -> str:
    here = Path(sys.executable).parent / "sysid"
    found = str(here) if here.is_file() else shutil.which("sysid")
    if not found:
        pytest.skip("the sysid console script is not installed in this environment (pip install -e .)")
    return found


def _sysid(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": "100"}
    return subprocess.run([_console_script(), *args], capture_output=True, text=True, timeout=timeout, env=env)


@pytest.mark.parametrize("args, says", [
    ((), "Usage: sysid"),
    (("nosuchcmd",), "No such command 'nosuchcmd'"),
    (("evaluate", "--bogus"), "No such option: --bogus"),
    (("train",), "Missing argument"),
    (("forces",), "Missing argument"),
    (("simulate", "--horizon", "abc"), "--horizon"),
])
def test_usage_errors_exit_2_without_traceback(args, says):
    out = _sysid(*args)
    text = out.stdout + out.stderr
    assert out.returncode == 2, text
    assert says in text
    assert "Traceback" not in text and "ModuleNotFoundError" not in text


def test_help_answers_and_exits_0():
    out = _sysid("--help")
    assert out.returncode == 0, out.stderr
    for command in ("train", "evaluate", "preprocess", "report", "reproduce", "simulate", "forces"):
        assert command in out.stdout


def test_bad_input_is_one_line_exit_2(tmp_path):
    out = _sysid("train", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "run"))
    assert out.returncode == 2
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "missing.toml" in lines[0] and "Traceback" not in out.stderr
