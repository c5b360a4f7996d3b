"""Files and directories sysid writes get the user's umask, not the temporary file's 0600."""
from __future__ import annotations

import os
import stat

import pandas as pd
import pytest

from sysid.store.files import write_csv, write_text
from sysid.store.staging import staged_directory


@pytest.fixture
def umask():
    def set_mask(mask: int) -> None:
        os.umask(mask)
    old = os.umask(0o022)
    yield set_mask
    os.umask(old)


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("mask, expected_file, expected_dir", [
    (0o022, 0o644, 0o755), (0o002, 0o664, 0o775), (0o077, 0o600, 0o700)])
def test_modes_follow_the_umask(tmp_path, umask, mask, expected_file, expected_dir):
    umask(mask)
    assert mode(write_text("hello", tmp_path / "a.txt")) == expected_file
    assert mode(write_csv(pd.DataFrame({"a": [1.0]}), tmp_path / "b.csv")) == expected_file
    with staged_directory(tmp_path / "out", "run") as staging:
        write_text("x", staging / "inner" / "c.txt")
    assert mode(tmp_path / "out") == expected_dir
    assert mode(tmp_path / "out" / "inner" / "c.txt") == expected_file
    assert mode(tmp_path / "out" / "manifest.json") == expected_file
