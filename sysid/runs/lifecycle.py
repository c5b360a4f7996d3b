"""One experiment end to end: train if it needs training, evaluate, write the run directory.

`run_experiment` is the one library call behind `sysid train`, `sysid reproduce` and any
sweep; the training data come from ``[data] train`` or the data set D1/D2, the test logs
from ``[data] test`` or, for a paper data set, the paper's six (`sysid.data.splits`).
"""
from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd
import torch

from sysid.config.choices import TestLogs
from sysid.identify.checkpoint import TrainingCheckpoint
from sysid.data.recordings import Run, read_runs
from sysid.data.datasets import test_files
from sysid.data.splits import TEST, TRAINING, VALIDATION, check_disjoint_runs, data_split, provenance
from sysid.device import compute_threads
from sysid.dynamics.integrators import Integrator
from sysid.errors import ConfigError, TrainingError
from sysid.evaluation.divergence import PhysicalRange
from sysid.evaluation.evaluate import Evaluation, evaluate_model, short_runs
from sysid.evaluation.verdict import (IDENTIFIED_MMG, SHIP_FILE_MMG, BaselineVerdict, baseline_verdict,
                                      window_score)
from sysid.config.experiment import Experiment
from sysid.hybrid.force_models import CorrectedModel, build_mmg, build_model
from sysid.mmg.coverage import outside_force_models
from sysid.runs.layout import read_ship_definition, write_run
from sysid.identify.trainer import EpochReport, Trainer, TrainingSummary, held_out_validation
from sysid.identify.windowing import astern_of
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
    verdict: BaselineVerdict | None = None

    @property
    def failure(self) -> str | None:
        """Why the run failed (a hit wall-clock limit), else None."""
        return self.training.failure if self.training is not None else None


def training_runs(exp: Experiment, data: str | os.PathLike | None = None) -> list[Run]:
    """The experiment's training logs (``[data] train`` or its data set), read and checked."""
    return read_runs(data_split(exp, data).train, exp.data.rate, exp.data.columns,
                     rudder_sign_checked=exp.data.rudder_sign_checked)


def validation_runs(exp: Experiment) -> list[Run]:
    """The experiment's ``[data] validation`` logs, read (empty: validation blocks of the training logs)."""
    if not exp.data.validation:
        return []
    return read_runs(data_split(exp).validation, exp.data.rate, exp.data.columns,
                     rudder_sign_checked=exp.data.rudder_sign_checked)


def evaluation_runs(exp: Experiment, data: str | os.PathLike | None = None) -> list[Run]:
    """The experiment's test logs: ``[data] test``, else the paper's six when it names a
    paper data set, else none. Read only to evaluate."""
    split = data_split(exp, data)
    columns = exp.data.columns if split.test_source is TestLogs.FILES else None
    return read_runs(split.test, exp.data.rate, columns, rudder_sign_checked=exp.data.rudder_sign_checked)


def warn_outside_force_models(exp: Experiment, runs: Sequence[Run]) -> list[str]:
    """Warn (and return) the shares of training samples outside what the ship file's force
    models cover (`sysid.mmg.coverage`): astern revolutions under a one-quadrant propeller,
    rudder angles beyond the standard rudder's range."""
    if not runs:
        return []
    states = np.concatenate([r.states for r in runs])
    inputs = np.concatenate([r.inputs for r in runs])
    ship = build_mmg(exp).ship
    found = outside_force_models(ship.models, states[:, 1], inputs[:, 0], inputs[:, 1])
    for line in found:
        logging.getLogger(__name__).warning(f"training logs: {line} ({ship.source or ship.name})")
    return found


def physics_baselines(exp: Experiment, model: torch.nn.Module, dtype: torch.dtype,
                      device: str | torch.device = "cpu") -> dict[str, torch.nn.Module]:
    """The physics a learned model is judged against: the ship file's MMG (with ``[mmg]
    overrides``) and, when the model carries identified coefficients under an FNN, its
    identified MMG. Empty for a model without training."""
    if not exp.needs_training:
        return {}
    out = {SHIP_FILE_MMG: build_mmg(exp, dtype).to(device)}
    if exp.identify.parameters and isinstance(model, CorrectedModel):
        out[IDENTIFIED_MMG] = model.mmg
    return out


def scores_on_tests(exp: Experiment, model: torch.nn.Module, evaluation: Evaluation,
                    tests: Sequence[Run], limits: PhysicalRange | None = None) -> dict[str, Evaluation] | None:
    """Evaluations of the model (its `evaluation`) and of each physics baseline on the test
    logs with their traces, divergence checked against `limits` (None without test logs)."""
    if not tests:
        return None
    scores = {"model": evaluation}
    for label, baseline in physics_baselines(exp, model, torch.float64).items():
        scores[label] = evaluate_model(baseline, tests, exp.evaluation.horizons, Integrator(exp.evaluation.integrator),
                                       limits=limits)
    return scores


_READ: dict[tuple, list[Run]] = {}  # recordings read once per process (protocol runs and sweep trials share them)


def cached_test_runs(data: str | os.PathLike | None = None) -> list[Run]:
    """The protocol's six test recordings (`sysid.data.datasets.test_files`), read once per
    process and data directory."""
    key = ("tests", None if data is None else str(data))
    if key not in _READ:
        _READ[key] = read_runs(test_files(data).values())
    return _READ[key]


def cached_training_runs(exp: Experiment, data: str | os.PathLike | None = None) -> list[Run]:
    """`training_runs`, read once per process for each training set (files or data set, rate)."""
    key = ("training", None if data is None else str(data), exp.experiment.dataset, exp.data.train,
           exp.data.columns, exp.data.rate, exp.data.rudder_sign_checked)
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
                   progress: bool = True, log: Callable[[str], None] | None = None,
                   resume: bool = False, overwrite: bool = False,
                   validation: Sequence[Run] | None = None,
                   on_epoch: Callable[[EpochReport], None] | None = None,
                   home: str | os.PathLike | None = None) -> RunResult:
    """Train `exp` (unless it is an MMG used as defined) on `train_runs` (default: its own
    training logs) with `validation` logs (default: its ``[data] validation``, else
    validation blocks of the training logs), evaluate it on `tests` at its horizons beside
    its physics baselines (`sysid.evaluation.verdict`), write the run directory.

    A log in two of training, validation and test (the same samples) is a `DataError`
    naming both. Runs with ``[training] threads`` torch threads. Training writes a
    checkpoint every epoch (`checkpoint_path`); `resume` continues from it to the same
    model an uninterrupted run gives. A run whose wall-clock safety limit was hit is
    written with its failure in summary.json (``result.failure``). The run directory is
    written complete or not at all; an existing one is replaced only with `overwrite`.
    Threads beyond this machine's cores, or horizons that are not whole samples or longer
    than a test file, are a `ConfigError` before any training.
    `on_epoch` receives every epoch's `EpochReport` (sweeps report it to Ray Tune,
    tracking to MLflow). `log` takes the stage lines (default: this module's logger, INFO).
    `home`: where the run directory will live when `out_dir` is a scratch place it is moved
    from (a sweep trial's); its logs are recorded relative to it (`sysid.runs.log_paths`).
    """
    log = log if log is not None else logging.getLogger(__name__).info
    check_experiment_fits(exp, tests)
    started = time.perf_counter()
    ship_definition = read_ship_definition(exp)   # the run keeps the ship file it was made with
    checked: list[Run] = list(validation) if validation is not None else []
    with compute_threads(exp.training.threads):
        runs: list[Run] = []
        held_out, trainer = None, None
        if exp.needs_training:
            runs, checked, held_out = _training_logs(exp, train_runs, data, checked, tests, log)
            trainer = _fitted(exp, runs, checked, out_dir, progress, log, resume, on_epoch)
        return _written(exp, out_dir, tests, runs, checked, held_out, trainer, started, overwrite, log,
                        ship_definition, home)


def run_seeds(experiments: Sequence[Experiment], out_dirs: Sequence[str | os.PathLike], tests: Sequence[Run],
              train_runs: Sequence[Run] | None = None, data: str | os.PathLike | None = None,
              progress: bool = True, logs: Sequence[Callable[[str], None]] | None = None,
              group_log: Callable[[str], None] = print, resume: bool = False, overwrite: bool = False,
              validation: Sequence[Run] | None = None,
              on_epochs: Sequence[Callable[[EpochReport], None] | None] | None = None,
              homes: Sequence[str | os.PathLike | None] | None = None) -> list[RunResult]:
    """`run_experiment` of the seeds of one configuration (`experiments`, equal but for
    ``[experiment] seed`` and name), each into its own run directory (`out_dirs`) with its
    own log, checkpoint and ``on_epoch``, their training stages side by side in this process
    (`sysid.identify.side_by_side`; one progress line per epoch group through `group_log`).
    Each run directory holds what `run_experiment` writes for its seed alone, its model
    equal to round-off. `resume` continues every seed from its checkpoint (a seed without
    one starts afresh), the unfinished ones side by side. Seeds that cannot share
    (`side_by_side.refusal`) are a `ConfigError`: train them with `run_experiment`.
    `homes`: each run's `home` (`run_experiment`)."""
    from sysid.identify.side_by_side import fit_side_by_side

    exp0 = experiments[0]
    logs = list(logs) if logs is not None else [group_log] * len(experiments)
    on_epochs = list(on_epochs) if on_epochs is not None else [None] * len(experiments)
    homes = list(homes) if homes is not None else [None] * len(experiments)
    check_experiment_fits(exp0, tests)
    started = time.perf_counter()
    ship_definitions = [read_ship_definition(exp) for exp in experiments]
    with compute_threads(exp0.training.threads):
        runs, shared, held_out = _training_logs(exp0, train_runs, data, list(validation or []), tests, logs[0])
        trainers = [Trainer(exp, progress=progress, log=log, checkpoint=checkpoint_path(out), resume=resume,
                            on_epoch=on_epoch)
                    for exp, out, log, on_epoch in zip(experiments, out_dirs, logs, on_epochs)]
        try:
            fit_side_by_side(trainers, runs, shared, log=group_log)
        except TrainingError:  # a diverged training resumes to the same divergence: keep nothing
            for exp, out in zip(experiments, out_dirs):
                TrainingCheckpoint(checkpoint_path(out), exp.to_toml()).remove()
            raise
        share = (time.perf_counter() - started) / len(trainers)   # each seed's share of the group's time
        return [_written(exp, out, tests, runs, shared, held_out, trainer, time.perf_counter() - share, overwrite,
                         log, ship, home)
                for exp, out, trainer, log, ship, home in zip(experiments, out_dirs, trainers, logs, ship_definitions,
                                                              homes)]


def _written(exp: Experiment, out_dir: str | os.PathLike, tests: Sequence[Run], runs: list[Run],
             validation: list[Run], held_out, trainer: Trainer | None, started: float, overwrite: bool,
             log: Callable[[str], None], ship_definition: bytes | None = None,
             home: str | os.PathLike | None = None) -> RunResult:
    """A run after its training (`trainer` fitted; None: an MMG used as defined): validation
    scores beside the physics baselines, evaluation on `tests` with its verdict, the run
    directory written (its seconds counted from `started`; with `ship_definition`, the ship
    file's bytes read when the run started; its logs recorded relative to `home`, else
    `out_dir`) and the checkpoint removed."""
    history, training, validation_scores = None, None, None
    limits = PhysicalRange.of_runs(runs)   # the training logs' range: beyond it a prediction diverged
    if trainer is not None:
        history, training = trainer.history_, trainer.summary_
        if training.failure is None:  # in the training dtype, as val_loss_multistep, at its horizons
            validation_scores = _validation_scores(exp, trainer, limits)
        model = trainer.model_.cpu().double()
    else:
        model = build_model(exp)
    evaluation, verdict, baseline_metrics, baseline_traces = _evaluated(exp, model, tests, limits, validation_scores,
                                                                        log)
    source = "files" if exp.data.train else (exp.experiment.dataset if exp.needs_training else "-")
    astern = astern_of(exp, build_mmg(exp).ship.models)
    data_used = provenance(source, runs, validation, tests, exp.training.val_fraction, exp.training.block_s,
                           held_out, exp.training.split_seed, astern.of if astern is not None else None,
                           exp.evaluation.horizons)
    _warn_astern_tests(data_used["test"], log)
    seconds = time.perf_counter() - started
    path = write_run(out_dir, exp, model, evaluation, history, training, seconds, overwrite,
                     verdict=verdict, data=data_used, baseline_metrics=baseline_metrics, limits=limits,
                     ship_definition=ship_definition, baseline_traces=baseline_traces, home=home)
    if training is not None:
        TrainingCheckpoint(checkpoint_path(out_dir), exp.to_toml()).remove()
    return RunResult(path, exp, model, evaluation, history, training, seconds, verdict)


def _warn_astern_tests(recorded: list[dict], log: Callable[[str], None]) -> None:
    """A WARNING line naming the test logs (`provenance`'s records) whose windows hold samples
    outside a one-quadrant propeller model: scored as they are, outside that model's validity."""
    named = [f"{Path(r['file']).stem} " + ", ".join(f"{n} of the {h}-s windows" for h, n in r["astern_windows"].items())
             for r in recorded if any(r.get("astern_windows", {}).values())]
    if named:
        log("WARNING: test windows with astern revolutions or going astern, outside the ship file's one-quadrant "
            "propeller model, are scored as they are (summary.json data.test astern_windows): " + "; ".join(named))


def _training_logs(exp: Experiment, train_runs: Sequence[Run] | None, data: str | os.PathLike | None,
                   validation: list[Run], tests: Sequence[Run], log: Callable[[str], None]):
    """(training logs, validation logs, the held-out draw or None): `train_runs` or the
    config's, the validation logs given or ``[data] validation`` or held out of the training
    logs; `DataError` for a log in two of them, a warning for states beyond the force models."""
    runs = list(train_runs) if train_runs is not None else training_runs(exp, data)
    held_out = None
    if not validation and exp.data.validation:
        validation = list(validation_runs(exp))
    if not validation and (held_out := held_out_validation(exp, runs)) is not None:
        runs, validation = list(held_out.train), list(held_out.validation)
        log("validation: the held-out training logs " + "; ".join(
            f"{group}: {', '.join(names)}" for group, names in held_out.groups.items()))
    check_disjoint_runs({TRAINING: runs, VALIDATION: validation, TEST: tests}, exp.source)
    warn_outside_force_models(exp, runs)
    return runs, validation, held_out


def _fitted(exp: Experiment, runs: Sequence[Run], validation: Sequence[Run], out_dir: str | os.PathLike, progress: bool,
            log: Callable[[str], None], resume: bool, on_epoch: Callable[[EpochReport], None] | None) -> Trainer:
    """The `Trainer` fitted on `runs`; a diverged training removes its checkpoint (it would
    resume to the same divergence) and raises."""
    try:
        return Trainer(exp, progress=progress, log=log, checkpoint=checkpoint_path(out_dir),
                       resume=resume, on_epoch=on_epoch).fit(runs, validation)
    except TrainingError:
        TrainingCheckpoint(checkpoint_path(out_dir), exp.to_toml()).remove()
        raise


def _validation_scores(exp: Experiment, trainer: Trainer, limits: PhysicalRange | None = None) -> dict:
    """horizon [s] -> "model" or baseline label -> `WindowScore` on the trainer's validation
    windows, each window named by its log (the verdict's cells per validation log), a
    prediction beyond the training range `limits` diverged."""
    validation_scores = {}
    for horizon, windows in trainer.validation_sets_.items():
        scored = {"model": trainer.model_, **physics_baselines(exp, trainer.model_, windows.states.dtype,
                                                                windows.states.device)}
        # the model's rollouts are the ones of its val_loss_multistep (`Trainer.objective`)
        errors = {"model": trainer.validation_errors_.get(horizon)}
        origins = trainer.validation_origins_.get(horizon)
        validation_scores[horizon] = {k: window_score(m, windows, trainer.velocity_weights_, errors.get(k), origins,
                                                      limits)
                                      for k, m in scored.items()}
    return validation_scores


def _evaluated(exp: Experiment, model, tests: Sequence[Run], limits: PhysicalRange, validation_scores: dict | None,
               log: Callable[[str], None]):
    """(the model's `Evaluation` on the test logs, its verdict or None, the baselines'
    metrics on the same logs or None, their traces: label -> trace name -> frame); a WARNING
    line per diverged prediction."""
    evaluation = evaluate_model(model, tests, exp.evaluation.horizons, Integrator(exp.evaluation.integrator),
                                limits=limits)
    for divergence in evaluation.divergences:
        log(f"WARNING: the prediction diverged on {divergence.text()}")
    verdict, baseline_metrics, baseline_traces = None, None, {}
    if validation_scores is not None:
        scores = scores_on_tests(exp, model, evaluation, tests, limits)
        verdict = baseline_verdict(str(exp.experiment.model), validation_scores, scores)
        if scores:
            baseline_metrics = pd.concat([e.metrics.assign(baseline=label) for label, e in scores.items()
                                          if label != "model"], ignore_index=True)
            baseline_traces = {label: e.traces for label, e in scores.items() if label != "model"}
    return evaluation, verdict, baseline_metrics, baseline_traces
