"""Run directories written by the trainer's writer (`sysid.runs.lifecycle.run_experiment`)
from the real data: a tiny hybrid whose MMG is first identified by gradient (gate,
identification, uncertainty, training details), and an MMG identified by
Levenberg-Marquardt (its start-state check). About 5 s each; each fixture is the
`RunResult` (``.path``: the run directory, ``.training``: the trainer's `TrainingSummary`)."""
from __future__ import annotations

from pathlib import Path

import pytest

from sysid.config.experiment import load_experiment, parse_experiment
from sysid.data.recordings import read_run
from sysid.runs.lifecycle import RunResult, run_experiment
from tiny_experiment import TRAIN_FILES, tiny_experiment, tiny_test_file


def _write(exp, out: Path, dataset_dir: Path) -> RunResult:
    return run_experiment(exp, out, [read_run(tiny_test_file(dataset_dir))], progress=False, log=lambda m: None)


@pytest.fixture(scope="session")
def hybrid_run(dataset_dir, tmp_path_factory) -> RunResult:
    """A tiny hybrid, N_r identified by gradient before the network, gate on the inputs (k = 5)."""
    tmp = tmp_path_factory.mktemp("hybrid")
    exp = load_experiment(tiny_experiment(tmp / "tiny.toml", dataset_dir, seed=3, epochs=2, warm_start_epochs=2))
    exp = exp.replace(identify={"parameters": ("N_r",), "epochs": 2})
    return _write(exp, tmp / "run", dataset_dir)


@pytest.fixture(scope="session")
def levenberg_marquardt_run(dataset_dir, tmp_path_factory) -> RunResult:
    """An MMG whose N_r is identified by Levenberg-Marquardt (2 iterations)."""
    tmp = tmp_path_factory.mktemp("lm")
    files = [str(dataset_dir / "berthing" / name) for name in TRAIN_FILES]
    exp = parse_experiment({"experiment": {"name": "lm", "model": "mmg"}, "data": {"files": files},
                            "identify": {"parameters": ["N_r"], "solver": "levenberg_marquardt", "iterations": 2},
                            "evaluation": {"horizons": [30.0]}}, "lm.toml")
    return _write(exp, tmp / "run", dataset_dir)
