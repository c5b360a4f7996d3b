"""The installed console script, run as a user runs it (a subprocess of this environment).

CI runs the suite inside a fresh virtual environment built by `.ci/run`, so this also
proves the error path needs no package the project does not declare (typer >= 0.29
vendors click and no longer installs it).
"""
from __future__ import annotations

import pytest

from cli_harness import subprocess_run


@pytest.mark.parametrize("args, says", [
    ((), "Usage: sysid"),
    (("nosuchcmd",), "No such command 'nosuchcmd'"),
    (("evaluate", "--bogus"), "No such option: --bogus"),
    (("train",), "Missing argument"),
    (("forces",), "Missing argument"),
    (("simulate", "--horizon", "abc"), "--horizon"),
])
def test_usage_errors_exit_2_without_traceback(args, says):
    out = subprocess_run(*args)
    text = out.out + out.err
    assert out.code == 2, text
    assert says in text
    assert "Traceback" not in text and "ModuleNotFoundError" not in text


def test_help_answers_and_exits_0():
    out = subprocess_run("--help")
    assert out.code == 0, out.err
    for command in ("train", "evaluate", "preprocess", "report", "reproduce", "simulate", "forces"):
        assert command in out.out


def test_bad_input_is_one_line_exit_2(tmp_path):
    out = subprocess_run("train", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "run"))
    assert out.code == 2
    lines = [line for line in out.err.splitlines() if line.strip()]
    assert len(lines) == 1 and "missing.toml" in lines[0] and "Traceback" not in out.err
