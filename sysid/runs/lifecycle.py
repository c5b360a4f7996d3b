"""One experiment end to end: train if it needs training, evaluate, write the run directory.

`run_experiment` is the one library call behind `sysid train`, `sysid reproduce` and any
sweep; the training data come from ``[data] files`` or the data set D1/D2.
"""
from __future__ import annotations

import glob
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import pandas as pd
import torch

from sysid.identify.checkpoint import TrainingCheckpoint
from sysid.data.recordings import Run, expand_paths, read_run
from sysid.data.datasets import test_files, training_files
from sysid.device import compute_threads
from sysid.errors import ConfigError, TrainingError
from sysid.evaluation.evaluate import Evaluation, evaluate_model, short_runs
from sysid.config.experiment import Experiment
from sysid.hybrid.force_models import build_model
from sysid.runs.rundir import write_run
from sysid.identify.trainer import Trainer, TrainingSummary
from sysid.config.checks import threads


@dataclass
class RunResult:
    """A finished run: where it was written, the model (CPU, float64) and what it scored."""

    path: Path
    experiment: Experiment
    model: torch.nn.Module
    evaluation: Evaluation
    history: pd.DataFrame | None
    training: TrainingSummary | None
    seconds: float

    @property
    def failure(self) -> str | None:
        """Why the run failed (a hit wall-clock limit), else None."""
        return self.training.failure if self.training is not None else None


def training_runs(exp: Experiment, data: str | os.PathLike | None = None) -> list[Run]:
    """The experiment's training files (``[data] files`` or its data set), read and checked."""
    if not exp.data.files:
        files = training_files(exp.experiment.dataset, data)
    else:  # folders and patterns expanded; a plain file is read as named ("file not found" if missing)
        files = [f for item in exp.data.files for f in (
            expand_paths([item]) if glob.has_magic(item) or Path(item).is_dir() else [Path(item)])]
    return [read_run(f, exp.data.rate) for f in files]


_READ: dict[tuple, list[Run]] = {}  # recordings read once per process (protocol runs and sweep trials share them)


def cached_test_runs(data: str | os.PathLike | None = None) -> list[Run]:
    """The protocol's six test recordings (`sysid.data.datasets.test_files`), read once per
    process and data directory."""
    key = ("tests", None if data is None else str(data))
    if key not in _READ:
        _READ[key] = [read_run(p) for p in test_files(data).values()]
    return _READ[key]


def cached_training_runs(exp: Experiment, data: str | os.PathLike | None = None) -> list[Run]:
    """`training_runs`, read once per process for each training set (files or data set, rate)."""
    key = ("training", None if data is None else str(data), exp.experiment.dataset, exp.data.files, exp.data.rate)
    if key not in _READ:
        _READ[key] = training_runs(exp, data)
    return _READ[key]


def checkpoint_path(out_dir: str | os.PathLike) -> Path:
    """Where the training checkpoint of the run to be written at `out_dir` lives while it
    trains (beside it, hidden; removed once the run directory is complete)."""
    out_dir = Path(out_dir)
    return out_dir.parent / f".{out_dir.name}.checkpoint.pt"


def check_experiment_fits(exp: Experiment, tests: Sequence[Run]) -> None:
    """The config's resources and horizons against this machine and these test runs."""
    source = exp.source or "config"
    threads(f"{source}: [training] threads =", exp.training.threads, ConfigError)
    name = f"{source}: [evaluation] horizons"
    short = short_runs(tests, exp.evaluation.horizons, name, ConfigError)
    if short:
        run, h = short[0]
        raise ConfigError(f"{name}: the test file {run.path} holds {len(run)} samples ({run.duration:.0f} s), "
                          f"fewer than one {h:g}-s window, so its metrics would be empty; choose shorter "
                          "horizons or other test files (nothing trained)")


def run_experiment(exp: Experiment, out_dir: str | os.PathLike, tests: Sequence[Run],
                   train_runs: Sequence[Run] | None = None, data: str | os.PathLike | None = None,
                   progress: bool = True, log: Callable[[str], None] = print,
                   resume: bool = False, overwrite: bool = False) -> RunResult:
    """Train `exp` (unless it is an MMG used as defined) on `train_runs` (default: its own
    training files), evaluate it on `tests` at its horizons, write the run directory.

    Runs with ``[training] threads`` torch threads. Training writes a checkpoint every epoch
    (`checkpoint_path`); `resume` continues from it to the same model an uninterrupted run
    gives. A run whose wall-clock safety limit was hit is written with its failure in
    summary.json (``result.failure``). The run directory is written complete or not at all;
    an existing one is replaced only with `overwrite`. Threads beyond this machine's cores,
    or horizons that are not whole samples or longer than a test file, are a `ConfigError`
    before any training.
    """
    check_experiment_fits(exp, tests)
    started = time.perf_counter()
    history, training = None, None
    with compute_threads(exp.training.threads):
        if exp.needs_training:
            runs = list(train_runs) if train_runs is not None else training_runs(exp, data)
            try:
                trainer = Trainer(exp, progress=progress, log=log, checkpoint=checkpoint_path(out_dir),
                                  resume=resume).fit(runs)
            except TrainingError:  # a diverged training resumes to the same divergence: keep nothing
                TrainingCheckpoint(checkpoint_path(out_dir), exp.to_toml()).remove()
                raise
            model, history, training = trainer.model_.cpu().double(), trainer.history_, trainer.summary_
        else:
            model = build_model(exp)
        evaluation = evaluate_model(model, tests, exp.evaluation.horizons, exp.evaluation.integrator)
    seconds = time.perf_counter() - started
    path = write_run(out_dir, exp, model, evaluation, history, training, seconds, overwrite)
    if training is not None:
        TrainingCheckpoint(checkpoint_path(out_dir), exp.to_toml()).remove()
    return RunResult(path, exp, model, evaluation, history, training, seconds)
