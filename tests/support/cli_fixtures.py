"""Fixtures of the CLI fuzz tests, imported by name into a test module: `sysid` (the command
in-process, as the console script calls it) and `run_copy` (a copy of the session's tiny
trained run, `trained` in conftest, to break)."""
from __future__ import annotations

import shutil

import pytest

from cli_harness import in_process


@pytest.fixture
def sysid(capsys):
    return lambda *args: in_process(capsys, *args)


@pytest.fixture
def run_copy(trained, tmp_path):
    copy = tmp_path / "run"
    shutil.copytree(trained, copy)
    return copy
