"""sweep.json (summary.json before) of a sweep directory as a typed record (`SweepSummary`): written by
`sysid.sweep.results.write_results`, read by the CLI and the report."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sysid.runs.records import JsonRecord


@dataclass(frozen=True)
class ChosenPoint(JsonRecord):
    """The chosen configuration: lowest mean validation loss over all its seeds (each of
    them complete); its varied values, the loss's mean and std over the seeds (None for one
    seed) and its run directories (relative to the sweep directory)."""

    point: str
    values: dict[str, Any]
    val_loss_multistep_mean: float
    val_loss_multistep_std: float | None
    runs: tuple[str, ...]
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SweepSummary(JsonRecord):
    """A sweep: its name, base config, search ("grid" | "random" | "optuna"), seeds,
    objective, varied keys ("section.option"), trial counts (``stopped_early``: ended by the
    scheduler, "none" | "asha" | "median"), the chosen configuration (None: no configuration
    completed all its seeds), the wall time [s], where Tune's experiment is (``tune``: relative
    to the sweep directory when inside it, else an absolute path or URI; `tune_at`) and the
    MLflow tracking URI (None: not tracked)."""

    name: str
    base: str | None = None
    search: str | None = None
    seeds: tuple[int, ...] = ()
    objective: str | None = None
    keys: tuple[str, ...] = ()
    trials: int = 0
    complete: int = 0
    failed: int = 0
    missing: int = 0
    stopped_early: int = 0
    best: ChosenPoint | None = None
    seconds: float | None = None
    scheduler: str | None = None
    tune: str | None = None
    mlflow: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def tune_at(self, folder: str | os.PathLike) -> str | None:
        """Where Tune's experiment is, for the sweep directory now at `folder`."""
        if self.tune is None or "://" in self.tune or os.path.isabs(self.tune):
            return self.tune
        return str(Path(folder) / self.tune)
