"""Tracking runs and sweeps in MLflow (the optional ``tracking`` extra:
``pip install "sysid[tracking]"``).

A run (``sysid train --mlflow URI``) is one MLflow run: every option of its resolved config
as a parameter, the training and validation loss of every epoch (step = the epoch's number
over all stages), the final metrics (validation loss, epochs, test RMSE per scenario and
horizon) and the run directory as artifact ``run/``. A sweep (``sysid sweep --mlflow URI``
or ``[tracking] mlflow``) is one MLflow experiment named after the sweep: a parent run for
the sweep and a child run per trial, logged by the driver (trials on other nodes need no
access to the tracking store).

``URI`` is any MLflow tracking URI (``http://host:5000``, ``sqlite:///mlflow.db``,
``databricks``); a plain path is a file store in that folder.
"""
from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sysid.errors import ConfigError

if TYPE_CHECKING:
    from sysid.config.experiment import Experiment

INSTALL_HINT = "MLflow tracking needs the tracking extra: pip install \"sysid[tracking]\" (mlflow)"
PARAM_BATCH = 100   # MLflow takes at most 100 parameters per call


def tracking_uri(where: str | os.PathLike) -> str:
    """An MLflow tracking URI from `where`: URIs as they are, a path as a file store."""
    text = str(where)
    if "://" in text or text.startswith("file:") or text == "databricks":
        if text.startswith("file:"):
            os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
        return text
    path = Path(text).expanduser().resolve()
    if path.exists() and not path.is_dir():
        raise ConfigError(f"--mlflow {where}: a file; give a folder for a file store, or a tracking URI")
    os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")  # MLflow's file store is opt-in since 3.x
    return path.as_uri()


def config_params(exp: Experiment) -> dict[str, str]:
    """Every option of a resolved experiment config as ``section.option`` -> text."""
    doc = exp.to_table()
    return {f"{section}.{key}": str(value)[:500] for section, table in doc.items() if isinstance(table, dict)
            for key, value in table.items()}


def metric_key(part) -> str:
    """A scenario or log name as part of an MLflow metric key (letters, digits, ``_ - . /``
    and spaces; anything else becomes ``_``; an unnamed scenario is ``-``)."""
    text = "" if part is None or (isinstance(part, float) and math.isnan(part)) else str(part)
    return re.sub(r"[^A-Za-z0-9_\-. /]", "_", text) or "-"


def run_metrics(run_dir: Path) -> dict[str, float]:
    """The final metrics of a run directory: its summary's numbers (the objective as
    ``final_val_loss``, `RunSummary.objective`; ``val_loss`` is the per-epoch history) and the test RMSE of every
    test log and horizon, keyed by the log's scenario and name
    (``rmse_u/Berthing/berthing_12-Nov-2020_11_49_21/30s``: no two logs share a key)."""
    from sysid.runs.directory import RunDir

    run = RunDir(run_dir)
    summary = run.read_summary()
    numbers = {"final_val_loss": summary.objective, "epochs": summary.epochs, "best_epoch": summary.best_epoch,
               "train_seconds": summary.train_seconds, "seconds": summary.seconds,
               "mmg_val_loss": summary.training.mmg_val_loss, "warm_val_loss": summary.training.warm_val_loss}
    metrics = {key: float(value) for key, value in numbers.items()
               if isinstance(value, (int, float)) and math.isfinite(value)}
    table = run.read_metrics()
    for row in table.itertuples():
        for c in ("u", "v", "r"):
            value = getattr(row, f"rmse_{c}")
            if math.isfinite(value):
                metrics[f"rmse_{c}/{metric_key(row.scenario)}/{metric_key(row.file)}/{row.horizon_s:g}s"] = float(value)
    return metrics


class Tracker:
    """One MLflow experiment and the runs logged into it (through `MlflowClient`, with
    explicit run ids: no global MLflow state)."""

    def __init__(self, where: str | os.PathLike, experiment: str):
        try:
            from mlflow.tracking import MlflowClient
        except ImportError:
            raise ConfigError(INSTALL_HINT) from None
        self.uri = tracking_uri(where)
        try:
            self.client = MlflowClient(self.uri)
            found = self.client.get_experiment_by_name(experiment)
            self.experiment_id = found.experiment_id if found else self.client.create_experiment(experiment)
        except Exception as exc:  # MLflow's MlflowException, requests' errors
            reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
            raise ConfigError(f"--mlflow {where}: cannot use this MLflow tracking store ({reason})") from None

    def start(self, name: str, params: dict[str, Any], parent: str | None = None, tags: dict | None = None) -> str:
        """A new run; its id."""
        from mlflow.entities import Param

        all_tags = {**(tags or {}), **({"mlflow.parentRunId": parent} if parent else {})}
        run = self.client.create_run(self.experiment_id, run_name=name, tags=all_tags)
        items = [Param(str(k), str(v)[:500]) for k, v in params.items()]
        for lo in range(0, len(items), PARAM_BATCH):
            self.client.log_batch(run.info.run_id, params=items[lo:lo + PARAM_BATCH])
        return run.info.run_id

    def metrics(self, run_id: str, values: dict[str, float], step: int = 0) -> None:
        from mlflow.entities import Metric
        import time

        now = int(time.time() * 1000)
        items = [Metric(k, float(v), now, step) for k, v in values.items()
                 if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)]
        if items:
            self.client.log_batch(run_id, metrics=items)

    def finish(self, run_id: str, run_dirs: dict[str, Path] | None = None, status: str = "FINISHED") -> None:
        """Final metrics and the run directories as artifacts (``run/`` for one, else
        ``run/{key}/``), then end the run with `status` (FINISHED, FAILED, KILLED)."""
        run_dirs = run_dirs or {}
        for key, run_dir in run_dirs.items():
            if (run_dir / "summary.json").is_file():
                prefix = "" if len(run_dirs) == 1 else f"{key}/"
                self.metrics(run_id, {prefix + k: v for k, v in run_metrics(run_dir).items()})
                self.client.log_artifacts(run_id, str(run_dir), "run" if len(run_dirs) == 1 else f"run/{key}")
        self.client.set_terminated(run_id, status)


class EpochLogger:
    """``Trainer(on_epoch=...)`` for one tracked run: each epoch's losses at step = its
    number over all stages."""

    def __init__(self, tracker: Tracker, run_id: str):
        self.tracker, self.run_id, self.step = tracker, run_id, 0

    def __call__(self, epoch) -> None:
        self.step += 1
        self.tracker.metrics(self.run_id, {"val_loss": epoch.val_loss, "train_loss": epoch.train_loss}, self.step)
