"""A sweep's trials in MLflow: a Tune callback on the driver logging each Tune trial as a
child run of the sweep's run (`sysid.experiment_tracking`): its varied values, every epoch's losses,
its final metrics and run directories (once they are in the sweep's output)."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from sysid.sweep.connect import import_ray
from sysid.sweep.inbox import complete_summary
from sysid.experiment_tracking import Tracker


def tracking_callback(tracker: Tracker, parent: str, out: Path, names: Callable[[dict], str],
                      params: Callable[[dict], dict], run_dirs: Callable[[dict], dict[str, str]],
                      log: Callable[[str], None] = print):
    """The Tune callback. `names`, `params` and `run_dirs` map a Tune config to the trial's
    name, its parameters and its run directories ({key: path relative to `out`})."""
    _, tune = import_ray()

    class TrackTrials(tune.Callback):  # type: ignore[name-defined]
        def __init__(self):
            self.runs: dict[str, str] = {}
            self.broken = False

        def _safely(self, what: str, action: Callable[[], None]) -> None:
            if self.broken:
                return
            try:
                action()
            except Exception as exc:  # tracking never stops a sweep
                self.broken = True
                log(f"WARNING MLflow: {what} failed ({str(exc).strip().splitlines()[0][:200] if str(exc).strip() else type(exc).__name__}); "
                    "tracking stops, the sweep goes on")

        def on_trial_start(self, iteration, trials, trial, **info):
            if trial.trial_id not in self.runs:  # a retried trial keeps its MLflow run
                def start():
                    self.runs[trial.trial_id] = tracker.start(names(trial.config), params(trial.config), parent)
                self._safely("starting a trial's run", start)

        def on_trial_result(self, iteration, trials, trial, result, **info):
            run = self.runs.get(trial.trial_id)
            if run is not None and not result.get("final"):
                # MLflow's per-epoch names, as `sysid.experiment_tracking.EpochLogger` logs a training
                values = {name: result[k] for name, k in (("val_loss", "early_stopping_loss"), ("train_loss", "train_loss"))
                          if k in result}
                self._safely("logging an epoch", lambda: tracker.metrics(run, values, int(result["training_iteration"])))

        def on_trial_complete(self, iteration, trials, trial, **info):
            run = self.runs.get(trial.trial_id)
            if run is not None:
                done = {key: out / path for key, path in run_dirs(trial.config).items()
                        if complete_summary(out / path) is not None}
                status = "FINISHED" if (trial.last_result or {}).get("final") else "KILLED"
                self._safely("finishing a trial's run", lambda: tracker.finish(run, done, status))

        def on_trial_error(self, iteration, trials, trial, **info):
            run = self.runs.get(trial.trial_id)
            if run is not None:
                self._safely("finishing a failed trial's run", lambda: tracker.finish(run, {}, "FAILED"))

    return TrackTrials()
