"""One trial of a sweep: one configuration and seed trained into an ordinary run directory
(`sysid.runs.rundir`; ``sysid evaluate`` and ``sysid report`` read it).

A trial whose run directory is already complete is not trained again; one interrupted
mid-training continues from its checkpoint (`sysid.runs.lifecycle.checkpoint_path`). Every
training that finishes is written to the sweep's journal (``trials.log``, one JSON line
per event), which is how a resumed sweep shows that no trial ran twice.
"""
from __future__ import annotations

import json
import math
import os
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from sysid.errors import CheckpointError
from sysid.config.experiment import parse_experiment
from sysid.runs.lifecycle import cached_test_runs, cached_training_runs, checkpoint_path, run_experiment
from sysid.runs.directory import RunDir
from sysid.runs.summary import RunSummary
from sysid.sweep.trial_lock import trial_lock

JOURNAL = "trials.log"


@dataclass(frozen=True)
class TrialSpec:
    """What one trial trains: its run directory (relative to the sweep's output), the
    configuration's name and varied values, the seed, and the resolved experiment TOML."""

    path: str
    point: str
    seed: int
    config: str
    values: dict = field(default_factory=dict)
    label: str = ""          # reproduce: the protocol run's name


@dataclass(frozen=True)
class TrialContext:
    """Where trials write and read: the output directory and the data root."""

    out: str
    data: str | None = None
    source: str = "<sweep>"


def journal(out: str | os.PathLike, event: str, trial: TrialSpec, **extra: Any) -> None:
    """Append one event line to the sweep's journal (one write on an O_APPEND file)."""
    line = json.dumps({"event": event, "trial": trial.path, "time": time.time(), "pid": os.getpid(), **extra})
    Path(out).mkdir(parents=True, exist_ok=True)
    fd = os.open(Path(out) / JOURNAL, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        os.write(fd, (line + "\n").encode())
    finally:
        os.close(fd)


def read_journal(out: str | os.PathLike) -> list[dict]:
    """Every event of the journal (a torn last line, from a kill mid-write, is skipped)."""
    path = Path(out) / JOURNAL
    events = []
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                events.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return events


def complete_summary(run_dir: Path) -> RunSummary | None:
    """summary.json of a complete run directory, else None."""
    run = RunDir.complete(run_dir)
    try:
        return run.read_summary() if run is not None else None
    except (CheckpointError, OSError):
        return None


def result_row(trial: TrialSpec, summary: RunSummary | None, run_dir: Path) -> dict:
    """The results-table row of a trial (status "missing" when it has no complete run)."""
    row = {"point": trial.point, "seed": trial.seed, "run": trial.path, **trial.values}
    if trial.label:
        row["name"] = trial.label
    if summary is None:
        return {**row, "status": "missing", "val_loss_multistep": math.nan}
    return {**row, "status": summary.status, "val_loss_multistep": summary.objective,
            "epochs": summary.epochs, "best_epoch": summary.best_epoch, "stopped": summary.stopped_text,
            "train_seconds": summary.train_seconds}


def run_trial(trial: TrialSpec, context: TrialContext, log: Callable[[str], None] = lambda m: None) -> dict:
    """Train `trial` into its run directory unless it is complete; its results-table row.
    One process at a time per trial (`sysid.sweep.trial_lock`)."""
    with trial_lock(context.out, trial.path):
        return _run_locked(trial, context, log)


def _run_locked(trial: TrialSpec, context: TrialContext, log: Callable[[str], None]) -> dict:
    run_dir = Path(context.out) / trial.path
    summary = complete_summary(run_dir)
    if summary is not None:
        journal(context.out, "reused", trial)
        return result_row(trial, summary, run_dir)
    exp = parse_experiment(tomllib.loads(trial.config), f"{context.source} (trial {trial.path})")
    resume = checkpoint_path(run_dir).is_file()
    journal(context.out, "resumed" if resume else "started", trial)
    train = cached_training_runs(exp, context.data) if exp.needs_training else None
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    result = run_experiment(exp, run_dir, cached_test_runs(context.data), train, context.data,
                            progress=False, log=log, resume=resume, overwrite=run_dir.exists())
    summary = RunDir(result.path).read_summary()
    journal(context.out, "trained", trial, val_loss_multistep=summary.val_loss_multistep)
    return result_row(trial, summary, run_dir)


def tune_trainable(config: dict, trials: list[TrialSpec], context: TrialContext) -> None:
    """Ray Tune's function trainable: the trial at index ``config["trial"]``."""
    from ray import tune

    row = run_trial(trials[int(config["trial"])], context)
    value = row["val_loss_multistep"]
    tune.report({"val_loss_multistep": value if math.isfinite(value) else math.inf,
                 "epochs": int(row.get("epochs") or 0), "failed": row["status"] != "complete"})
