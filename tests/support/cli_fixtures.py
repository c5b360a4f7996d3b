"""Fixtures of the CLI fuzz tests, imported by name into a test module: `sysid` (the command
in-process), `files` (real berthing and zigzag runs) and `trained` (a tiny hybrid run
directory written by `sysid train`), `run_copy` (a copy of it to break)."""
from __future__ import annotations

import shutil

import pytest

from cli_harness import in_process
from tiny_experiment import tiny_config


@pytest.fixture
def sysid(capsys):
    return lambda *args: in_process(capsys, *args)


@pytest.fixture(scope="module")
def files(dataset_dir):
    berthing = dataset_dir / "berthing"
    return {"train": berthing / "berthing_12-Nov-2020_11_07_23.csv",
            "test": berthing / "berthing_12-Nov-2020_11_49_21.csv",  # 128 s
            "zigzag": dataset_dir / "zigzag" / "zigzag_31-Jul-2020_13_04_24.csv"}


@pytest.fixture(scope="module")
def trained(tmp_path_factory, files):
    """A run directory written by `sysid train` (hybrid, gate on the 9 inputs, k = 3)."""
    from sysid.cli import run
    folder = tmp_path_factory.mktemp("trained")
    config = folder / "tiny.toml"
    config.write_text(tiny_config(files))
    run(["train", str(config), "-o", str(folder / "run"), "--test", str(files["test"])])
    return folder / "run"


@pytest.fixture
def run_copy(trained, tmp_path):
    copy = tmp_path / "run"
    shutil.copytree(trained, copy)
    return copy
