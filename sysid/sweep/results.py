"""A sweep's results: one row per trial (``results.csv``), one per configuration over its
seeds (``points.csv``: mean, std, min, max of the validation loss), the chosen
configuration (lowest mean validation loss over all its seeds) in ``sweep.json``.

Only complete run directories count; a trial without one is "stopped early" (by the
sweep's scheduler), "failed" (its error from Ray) or "missing" (never trained, interrupted).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from sysid.runs.rundir import RunDir
from sysid.store.files import write_csv, write_text
from sysid.store.target import RECORD_FILES, OutputKind
from sysid.sweep.inbox import complete_summary
from sysid.sweep.plan import TRIALS_DIR
from sysid.sweep.points import format_value
from sysid.sweep.runner import Outcomes
from sysid.sweep.spec import SweepSpec
from sysid.sweep.summary import ChosenPoint, SweepSummary
from sysid.sweep.trial import TrialSpec, result_row

STOPPED = "stopped early"


@dataclass
class SweepResults:
    """Trials and configurations of a sweep, and the chosen one."""

    trials: pd.DataFrame
    points: pd.DataFrame
    best: ChosenPoint | None

    @property
    def counts(self) -> dict[str, int]:
        status = self.trials["status"] if len(self.trials) else pd.Series([], dtype=str)
        return {"trials": len(self.trials), "complete": int((status == "complete").sum()),
                "failed": int(status.str.startswith("failed").sum()), "missing": int((status == "missing").sum()),
                "stopped_early": int(status.str.startswith(STOPPED).sum())}


def _value(config: dict, key: str):
    section, option = key.split(".", 1)
    value = config.get(section, {}).get(option)
    return tuple(value) if isinstance(value, list) else value


def scanned_trials(spec: SweepSpec, out: Path) -> list[TrialSpec]:
    """Trials whose run directories are complete in `out` (for Optuna, which proposes its
    points while it runs)."""
    found = []
    for run_dir in sorted((out / TRIALS_DIR).glob("*/seed*")):
        if not RunDir(run_dir).config.is_file() or complete_summary(run_dir) is None:
            continue
        config = RunDir(run_dir).read_config()
        values = {key: _value(config, key) for key in spec.keys}
        found.append(TrialSpec(str(run_dir.relative_to(out)), run_dir.parent.name,
                               int(config["experiment"]["seed"]), "", values))
    return found


def collect_results(spec: SweepSpec, out: Path, trials: list[TrialSpec], outcomes: Outcomes) -> SweepResults:
    """Read every trial's run directory into the results tables."""
    rows = []
    for trial in trials:
        row = result_row(trial, complete_summary(out / trial.path))
        error = outcomes.errors.get(trial.path) or outcomes.errors.get(trial.point)
        stopped = outcomes.stopped.get(trial.path, outcomes.stopped.get(trial.point))
        if row["status"] == "missing" and error:
            row["status"] = f"failed: {error}"
        elif row["status"] == "missing" and stopped is not None:
            row["status"], row["epochs"] = STOPPED, stopped
        rows.append(row)
    table = pd.DataFrame(rows)
    if table.empty:
        return SweepResults(table, pd.DataFrame(), None)
    for key in spec.keys:  # tuples (layer widths) as text in the tables
        table[key] = table[key].map(lambda v: format_value(v) if isinstance(v, tuple) else v)
    done = table[table.status == "complete"]
    points = []
    for point, group in table.groupby("point", sort=False):
        ok = done[done.point == point]["val_loss_multistep"]
        points.append({"point": point, **{k: group[k].iloc[0] for k in spec.keys},
                       "seeds": int(len(group)), "complete": int(len(ok)),
                       "val_loss_multistep_mean": float(ok.mean()) if len(ok) else math.nan,
                       "val_loss_multistep_std": float(ok.std(ddof=1)) if len(ok) > 1 else math.nan,
                       "val_loss_multistep_min": float(ok.min()) if len(ok) else math.nan,
                       "val_loss_multistep_max": float(ok.max()) if len(ok) else math.nan})
    points_frame = pd.DataFrame(points).sort_values("val_loss_multistep_mean", kind="stable", na_position="last")
    whole = points_frame[(points_frame.complete == points_frame.seeds) & points_frame.val_loss_multistep_mean.notna()]
    best = None
    if len(whole):
        top = whole.iloc[0]
        best = ChosenPoint(top.point, {k: _plain(top[k]) for k in spec.keys}, float(top.val_loss_multistep_mean),
                           None if math.isnan(top.val_loss_multistep_std) else float(top.val_loss_multistep_std),
                           tuple(done[done.point == top.point]["run"]))
    return SweepResults(table, points_frame.reset_index(drop=True), best)


def _plain(value):
    return value.item() if hasattr(value, "item") else value


def write_results(spec: SweepSpec, out: Path, results: SweepResults, seconds: float,
                  tune: str | None = None, mlflow: str | None = None) -> SweepSummary:
    """results.csv, points.csv and sweep.json (each written atomically), with where
    Tune's experiment (`tune`) and the MLflow store (`mlflow`) are."""
    write_csv(results.trials, out / "results.csv", float_format="%.6g")
    write_csv(results.points, out / "points.csv", float_format="%.6g")
    summary = SweepSummary(spec.name, str(spec.base_path), spec.search, tuple(spec.seeds), spec.objective,
                           tuple(spec.keys), **results.counts, best=results.best, seconds=seconds,  # type: ignore[arg-type]
                           scheduler=str(spec.scheduler.kind), tune=tune, mlflow=mlflow)
    write_text(summary.to_text(), out / RECORD_FILES[OutputKind.SWEEP])
    return summary
