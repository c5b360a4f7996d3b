"""The log of a command: stage lines time-stamped when stdout is not a terminal (the warm start
included), ``-q`` keeps warnings and errors only, ``-v`` adds every epoch; ``sysid --version``."""
from __future__ import annotations

import re
import time

import pytest
from cli_harness import in_process
from tiny_experiment import tiny_experiment, tiny_test_file

import sysid

STAMP = re.compile(r"^(\d{4}-\d{2}-\d{2} \d{2}:\d{2}:\d{2}) (.*)$")


def _train(capsys, tmp_path, dataset_dir, *flags):
    config = tiny_experiment(tmp_path / "tiny.toml", dataset_dir, seed=1, epochs=2, warm_start_epochs=3, patience=None)
    out = in_process(capsys, "train", config, "-o", tmp_path / f"run{len(flags)}{''.join(flags)}", "--test",
                     tiny_test_file(dataset_dir), *flags)
    assert out.code == 0, out.err
    return out


@pytest.mark.slow
def test_stage_lines_are_time_stamped_and_verbosity_follows_v_and_q(tmp_path, dataset_dir, capsys):
    before = time.strftime("%Y-%m-%d %H:%M:%S")
    verbose = _train(capsys, tmp_path, dataset_dir, "-v")                 # -v after the command's name
    stamped = [STAMP.match(line) for line in verbose.out.splitlines() if STAMP.match(line)]
    stages = [m.group(2).strip() for m in stamped]
    assert any(s.startswith("train: hybrid model on 2 training log(s)") for s in stages)
    assert any(s.startswith("warm start: 3 epochs") for s in stages)       # the warm start says so
    assert any(s.startswith("warm start epoch 3/3: loss") for s in stages)
    assert any(s.startswith("kNN gate:") for s in stages)
    assert all(before <= m.group(1) <= time.strftime("%Y-%m-%d %H:%M:%S") for m in stamped)  # now, in order
    assert [m.group(1) for m in stamped] == sorted(m.group(1) for m in stamped)
    assert any(s.startswith("epoch 1/2: training") for s in stages)        # every epoch with -v
    assert any(s.startswith("warm start epoch 1/3: loss") for s in stages)

    quiet = _train(capsys, tmp_path, dataset_dir, "-q")
    assert not STAMP.search(quiet.out) and "warm start" not in quiet.out + quiet.err
    assert "rmse_u" in quiet.out and "train: wrote" in quiet.out             # the results stay


def test_version(capsys):
    out = in_process(capsys, "--version")
    assert out.code == 0 and out.out.startswith(f"sysid {sysid.__version__} (Python 3.")
